"""File exporters on their own: PC2 header and data, OBJ order, ARKit and channel CSVs."""

from __future__ import annotations

import csv
import struct
from pathlib import Path

import numpy as np
import pytest

from puppet.export.arkit import ARKIT_SHAPES, UNSUPPORTED, ArkitCsvWriter, timecode
from puppet.export.channels_csv import ChannelCsvWriter
from puppet.export.pc2 import PC2Writer, read_pc2, write_obj


def test_pc2_header_and_samples_read_back(tmp_path: Path) -> None:
    frames = [np.random.default_rng(k).normal(size=(5, 3)) for k in range(4)]
    w = PC2Writer(tmp_path / "a.pc2", 5, start_frame=1.0, sampling=1.0)
    for f in frames:
        w.add(f)
    w.close()
    raw = (tmp_path / "a.pc2").read_bytes()
    assert raw[:12] == b"POINTCACHE2\0"
    assert struct.unpack_from("<iiffi", raw, 12) == (1, 5, 1.0, 1.0, 4)
    assert len(raw) == 32 + 4 * 5 * 3 * 4
    head, data = read_pc2(tmp_path / "a.pc2")
    assert head["num_samples"] == 4 and data.dtype == np.float32
    assert np.array_equal(data, np.array(frames, dtype=np.float32))


def test_obj_keeps_vertex_order(tmp_path: Path) -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]], dtype=float)
    write_obj(tmp_path / "m.obj", v, np.array([[0, 1, 2]]), "rest pose")
    lines = (tmp_path / "m.obj").read_text().splitlines()
    vs = [list(map(float, x.split()[1:])) for x in lines if x.startswith("v ")]
    assert vs == v.tolist() and "f 1 2 3" in lines and lines[0] == "# rest pose"


def test_arkit_csv_header_timecode_and_mapping(tmp_path: Path) -> None:
    names = ["zygomaticus_major_l", "zygomaticus_major_r", "jaw", "eyes_yaw", "eyes_pitch"]
    w = ArkitCsvWriter(tmp_path / "a.csv", names, 30)
    w.add(0, np.array([0.0, 0.0, 0.0, 0.0, 0.0]))
    w.add(31, np.array([0.385, 0.11, 0.5, 0.4, -0.3]))
    w.close()
    rows = list(csv.reader(open(tmp_path / "a.csv")))
    head = rows[0]
    assert head[:3] == ["Timecode", "BlendShapeCount", "EyeBlinkLeft"] and len(head) == 2 + 52 + 9
    assert len(ARKIT_SHAPES) == 52 and UNSUPPORTED == ()  # every shape has a channel
    r = dict(zip(head, rows[2]))
    assert r["Timecode"] == "00:00:01:01.000" and r["BlendShapeCount"] == "61"
    # mouthSmile at 1 drives the zygomaticus 0.55 (the scan's smile): the export divides by it
    assert float(r["MouthSmileLeft"]) == pytest.approx(0.7) and float(r["MouthSmileRight"]) == pytest.approx(0.2)
    assert float(r["JawOpen"]) == pytest.approx(0.5 / 0.8)  # jawOpen at 1 opens the jaw 0.8 (the scan's opening)
    assert float(r["EyeLookOutLeft"]) == pytest.approx(0.4) and float(r["EyeLookInRight"]) == pytest.approx(0.4)
    assert float(r["EyeLookDownLeft"]) == pytest.approx(0.3) and float(r["EyeLookUpLeft"]) == 0.0
    # the eyes' rotations in quarter turns (the gaze's full range is 30 degrees sideways, 20 up/down)
    assert float(r["LeftEyeYaw"]) == pytest.approx(0.4 / 3) and float(r["RightEyePitch"]) == pytest.approx(-0.3 * 2 / 9)


def test_timecode_rolls_over() -> None:
    assert timecode(60 * 3600 + 59, 60) == "01:00:00:59.000"
    assert timecode(61 * 60, 60) == "00:01:01:00.000"


def test_channel_csv_is_exact(tmp_path: Path) -> None:
    w = ChannelCsvWriter(tmp_path / "c.csv", ["a", "b"])
    vals = np.array([1 / 3, 2 / 7])
    w.add(0, 0.0, 0, vals)
    w.close()
    rows = list(csv.reader(open(tmp_path / "c.csv")))
    assert rows[0] == ["frame", "time", "tick", "a", "b"]
    assert [float(x) for x in rows[1][3:]] == vals.tolist()


def test_a_folder_in_the_way_of_a_file_export_is_named_not_filled(tmp_path: Path) -> None:
    """`replay --out d.csv` where d.csv is a folder wrote PNG frames into it (a user asking for a
    CSV got pictures in a folder called .csv). Every file export now names the folder, exit 2,
    the folder as it was; a folder without an export suffix (shot.01) still gets the frames."""
    import subprocess
    import sys

    take = Path(__file__).parent / "data" / "take_jaw_whole.jsonl"
    rig = ["--rig", str(take.with_name("take_jaw_whole_rig.npz"))]
    for name in ("d.csv", "d.mp4", "d.png", "d.pc2", "d.curves", "d.arkit.csv"):
        folder = tmp_path / name
        folder.mkdir()
        done = subprocess.run([sys.executable, "-m", "puppet", "replay", str(take), "--out", str(folder),
                               "--to", "0.05", "--size", "64x48", *rig], capture_output=True, text=True, timeout=300)
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and f"{name}: is a folder" in done.stderr, \
            done.stderr
        assert list(folder.iterdir()) == []
    shot = tmp_path / "shot.01"
    shot.mkdir()
    done = subprocess.run([sys.executable, "-m", "puppet", "replay", str(take), "--out", str(shot),
                           "--to", "0.05", "--size", "64x48", *rig], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and sorted(p.name for p in shot.iterdir())[0] == "frame_000000.png", done.stderr
