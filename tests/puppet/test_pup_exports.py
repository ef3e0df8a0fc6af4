"""Exports from a replay: frame counts and rates, PC2 equal to the simulation, curves round trip."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import devices
from puppet import live
from puppet.curves import load_curves
from puppet.export.pc2 import read_pc2
from puppet.export.runner import ExportOptions, export
from puppet.mapping import Mapper
from puppet.replay import Replayer, build_performance
from puppet.session import SessionWriter, read_session

SCRIPT = """
impersonate = "sgi"
speed = 0
duration = 1.0
[[ramp]]
control = "dial1"
start = 0.0
duration = 0.6
from = 0.0
to = 1.0
rate = 50
[[ramp]]
control = "dial7"
start = 0.2
duration = 0.5
from = 0.0
to = 0.6
rate = 50
"""


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("rec")
    (d / "s.toml").write_text(SCRIPT)
    face = live.load_face()
    dev = devices.open_device(f"mock://{d / 's.toml'}")
    spec = live.build_mapping(face.vocab, None, [dev.spec])
    rec = d / "take.jsonl"
    w = SessionWriter(rec, live.session_header(face, spec, 60.0, [dev.spec]))
    core = live.LiveCore(face, Mapper(spec, face.vocab), writer=w)
    live.run_virtual(core, live.scripted_events([dev]), 1.0)
    w.close(core.tick_count)
    dev.close()
    return rec


def test_mp4_frame_count_and_rate(recording: Path, tmp_path: Path) -> None:
    import imageio.v2 as imageio

    perf = build_performance(read_session(recording), None)
    out = tmp_path / "v.mp4"
    export(perf, out, ExportOptions(fps=24, size=(160, 96), start=0.25, end=0.75))
    reader = imageio.get_reader(str(out))
    frames = [f for f in reader]
    assert reader.get_meta_data()["fps"] == pytest.approx(24)
    assert len(frames) == 12 and frames[0].shape == (96, 160, 3)
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 0.05  # the face moved
    # speed 2 halves the frame count; PNG frames land in a folder
    export(perf, tmp_path / "pngs", ExportOptions(fps=10, size=(64, 48), speed=2.0))
    assert len(list((tmp_path / "pngs").glob("frame_*.png"))) == 5


def test_pc2_matches_the_simulation_and_obj_order(recording: Path, tmp_path: Path) -> None:
    perf = build_performance(read_session(recording), None)
    out = tmp_path / "face.pc2"
    export(perf, out, ExportOptions(fps=30))
    head, data = read_pc2(out)
    n = len(perf.face.model.rest)
    assert head == {"version": 1, "num_points": n, "start_frame": 1.0, "sampling": 1.0, "num_samples": 30}
    rp = Replayer(perf)
    for j in (0, 7, 29):
        rp.seek(2 * j)  # 30 fps from 60 Hz ticks: every other tick
        assert np.array_equal(data[j], rp.state.surface.astype(np.float32))
    obj = [list(map(float, ln.split()[1:])) for ln in (tmp_path / "face.obj").read_text().splitlines()
           if ln.startswith("v ")]
    assert np.allclose(obj, perf.face.model.rest, atol=1e-5)


def test_obj_is_the_posed_mesh_at_from_as_the_pc2_holds_it(recording: Path, tmp_path: Path) -> None:
    """`replay --out X.obj` was refused (an OBJ came only as the rest mesh beside a PC2): it is the
    posed mesh at --from, like .png's still, vertex for vertex the PC2's sample of that tick."""
    perf = build_performance(read_session(recording), None)
    export(perf, tmp_path / "all.pc2", ExportOptions(fps=60))
    _, data = read_pc2(tmp_path / "all.pc2")
    summary = export(perf, tmp_path / "at.obj", ExportOptions(fps=60, start=0.5))
    assert "at.obj" in summary
    obj = np.array([list(map(float, ln.split()[1:4])) for ln in (tmp_path / "at.obj").read_text().splitlines()
                    if ln.startswith("v ")])
    assert obj.shape == data[30].shape
    assert np.allclose(obj, data[30], atol=1e-4)
    assert not np.allclose(obj, data[0], atol=1e-3)  # the dials moved the face by then


def test_csv_and_arkit_rows(recording: Path, tmp_path: Path) -> None:
    perf = build_performance(read_session(recording), None)
    export(perf, tmp_path / "c.csv", ExportOptions(fps=60))
    export(perf, tmp_path / "a.arkit.csv", ExportOptions(fps=60))
    rows = list(csv.DictReader(open(tmp_path / "c.csv")))
    assert len(rows) == 60 and float(rows[-1]["zygomaticus_major_l"]) > 0.5
    ark = list(csv.DictReader(open(tmp_path / "a.arkit.csv")))
    assert len(ark) == 60 and ark[59]["Timecode"] == "00:00:00:59.000"
    assert float(ark[-1]["MouthSmileLeft"]) > 0.5 and float(ark[-1]["JawOpen"]) > 0.2


def test_curves_export_edit_and_replay_alone_or_layered(recording: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    from puppet.cli import main

    run = lambda *a: main(["replay", *a])  # noqa: E731  (in-process: the same code path as the CLI)
    cur = tmp_path / "take.curves"
    assert run(str(recording), "--out", str(cur)) == 0
    cs = load_curves(cur)
    assert {c.target for c in cs.curves} >= {"zygomaticus_major", "jaw"}
    # edit: add a brow raise; play the curves alone and layered over the recording
    cur.write_text(cur.read_text() + "curve frontalis_inner smooth\n  0.1 0\n  0.5 1\n  0.9 1\nend\n")
    alone, layered = tmp_path / "alone.csv", tmp_path / "layered.csv"
    assert run("--curves", str(cur), "--out", str(alone)) == 0
    assert run(str(recording), "--curves", str(cur), "--out", str(layered)) == 0
    a = list(csv.DictReader(open(alone)))
    b = list(csv.DictReader(open(layered)))
    assert float(a[40]["frontalis_inner_l"]) == 1.0 and float(b[40]["frontalis_inner_r"]) == 1.0
    rec = read_session(recording).value_array(np.zeros(len(read_session(recording).channels)))
    j = read_session(recording).channels.index("zygomaticus_major_l")
    assert abs(float(a[40]["zygomaticus_major_l"]) - rec[40, j]) < 0.01  # curves reproduce the take
    # a broken curves file: one line, file:line
    bad = tmp_path / "bad.curves"
    bad.write_text("facepuppet-curves 1\ncurve jaw\n 0 zero\nend\n")
    capsys.readouterr()
    assert run("--curves", str(bad), "--headless") == 2
    assert capsys.readouterr().err.strip().startswith(f"puppet: error: {bad}:3:")


def test_long_export_renders_in_a_second_process(recording: Path, tmp_path: Path) -> None:
    import imageio.v2 as imageio

    from puppet.errors import PuppetError
    from puppet.export.video import PARALLEL_MIN_FRAMES

    perf = build_performance(read_session(recording), None)
    fps = 120.0  # 1 s of performance at 120 fps: enough frames for the parallel path
    assert fps * perf.duration >= PARALLEL_MIN_FRAMES
    out = tmp_path / "long.mp4"
    export(perf, out, ExportOptions(fps=fps, size=(64, 48)))
    reader = imageio.get_reader(str(out))
    assert reader.count_frames() == 120 and reader.get_meta_data()["fps"] == pytest.approx(120)
    with pytest.raises(PuppetError, match="unknown view 'xray'"):
        export(perf, tmp_path / "bad.mp4", ExportOptions(fps=fps, size=(64, 48), view="xray"))


@pytest.mark.parametrize("view", ["shaded", "trails"])
def test_render_pool_gives_the_serial_frames_in_order(recording: Path, tmp_path: Path, view: str) -> None:
    import imageio.v2 as imageio

    perf = build_performance(read_session(recording), None)
    opts = dict(fps=120.0, size=(96, 64), view=view)
    export(perf, tmp_path / "serial.mp4", ExportOptions(parallel=False, **opts))
    export(perf, tmp_path / "pool.mp4", ExportOptions(workers=2, **opts))
    a = [f for f in imageio.get_reader(str(tmp_path / "serial.mp4"))]
    b = [f for f in imageio.get_reader(str(tmp_path / "pool.mp4"))]
    assert len(a) == len(b) == 120
    assert all(np.array_equal(x, y) for x, y in zip(a, b))  # same frames, same order, same encoder
    assert np.abs(a[0].astype(int) - a[-1].astype(int)).mean() > 0.05
    if view == "shaded":  # PNG frames written by the pool's processes themselves
        export(perf, tmp_path / "pngs", ExportOptions(workers=2, fps=120.0, size=(64, 48)))
        assert len(list((tmp_path / "pngs").glob("frame_*.png"))) == 120


def test_odd_size_and_options_are_checked(recording: Path, tmp_path: Path) -> None:
    import imageio.v2 as imageio

    from puppet.errors import PuppetError

    perf = build_performance(read_session(recording), None)
    export(perf, tmp_path / "odd.mp4", ExportOptions(fps=10, size=(65, 47), supersample=2, crf=30))
    frames = [f for f in imageio.get_reader(str(tmp_path / "odd.mp4"))]
    assert len(frames) == 10 and frames[0].shape == (48, 66, 3)  # padded to even for H.264
    with pytest.raises(PuppetError, match="--crf"):
        export(perf, tmp_path / "x.mp4", ExportOptions(crf=99))
    with pytest.raises(PuppetError, match="--supersample"):
        export(perf, tmp_path / "x.mp4", ExportOptions(supersample=0))


def test_a_pc2_export_keeps_a_users_own_obj_beside_it(recording: Path, tmp_path: Path) -> None:
    """`--out face.pc2` writes its rest mesh to face.obj: where face.obj is the user's own mesh (the
    one `puppet import-face face.obj` read, a Blender export) the export is refused in one line and
    the mesh kept; a rest mesh an earlier export wrote is replaced as before."""
    from puppet.errors import PuppetError

    perf = build_performance(read_session(recording), None)
    mine = tmp_path / "face.obj"
    mine.write_text("# Blender 4.1\nmtllib face.mtl\nv 0 0 0\nvt 0 0\n")
    before = mine.read_bytes()
    with pytest.raises(PuppetError, match="face.obj") as err:
        export(perf, tmp_path / "face.pc2", ExportOptions(fps=30))
    assert "\n" not in str(err.value)
    assert mine.read_bytes() == before and not (tmp_path / "face.pc2").exists()
    mine.unlink()
    export(perf, tmp_path / "face.pc2", ExportOptions(fps=30, end=0.2))
    export(perf, tmp_path / "face.pc2", ExportOptions(fps=30, end=0.1))  # its own rest mesh: replaced
    assert read_pc2(tmp_path / "face.pc2")[0]["num_samples"] == 3


def test_an_export_into_a_log_has_no_progress_bar(recording: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    """Exporting with stderr in a file or a pipe (a log, a farm's output) writes no bar of carriage
    returns."""
    perf = build_performance(read_session(recording), None)
    export(perf, tmp_path / "c.csv", ExportOptions(fps=60))
    assert "\r" not in capsys.readouterr().err


def test_drawing_options_on_a_data_export_are_said_not_to_apply(recording: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture) -> None:
    """`--view wireframe --size 640x480` on a .csv export were dropped without a word; now one line
    names them, the export is the one written without them, and options that apply stay silent."""
    from puppet.cli import main

    plain, drawn = tmp_path / "plain.csv", tmp_path / "drawn.csv"
    assert main(["replay", str(recording), "--out", str(plain)]) == 0
    assert "note" not in capsys.readouterr().err
    assert main(["replay", str(recording), "--out", str(drawn), "--view", "wireframe", "--size", "640x480"]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "note" in line]
    assert err == ["puppet: note: --view and --size do not apply to a .csv of channels; ignored"], err
    assert drawn.read_bytes() == plain.read_bytes()
    assert main(["replay", str(recording), "--out", str(tmp_path / "x.pc2"), "--crf", "18"]) == 0
    assert "--crf does not apply to a .pc2 point cache" in capsys.readouterr().err
    assert main(["replay", str(recording), "--out", str(tmp_path / "s.png"), "--view", "heat", "--size", "64x48",
                 "--to", "0.1"]) == 0
    assert "note" not in capsys.readouterr().err


def test_replay_out_obj_on_the_scanned_head_says_it_holds_the_whole_scan(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """`puppet replay take.jsonl --out take.obj` on the default face wrote the scan's 26,719
    vertices but said "(6020 simulated vertices)": a user checking the README's promise read that
    the OBJ had lost the scan's topology. It says what the file holds, as `puppet pose` does."""
    from puppet.cli import main
    from puppet.mapping.config import MappingSpec

    face = live.load_face(face="ict")
    names = [c.name for c in face.vocab.channels]
    take = tmp_path / "jaw.jsonl"
    header = live.session_header(face, MappingSpec(name="t", bindings=[], combine={}, source="t", text=""), 60.0, [])
    values = np.array(face.vocab.defaults())
    with SessionWriter(take, header, fsync_seconds=None) as w:
        for k in range(6):
            values[names.index("jaw")] = 0.1 * k
            w.values(k, values)
            w.tick(k + 1)
        w.close(6)
    obj = tmp_path / "at.obj"
    capsys.readouterr()
    assert main(["replay", str(take), "--out", str(obj), "--from", "0.05"]) == 0
    said = capsys.readouterr().out
    n = sum(1 for ln in obj.read_text().splitlines() if ln.startswith("v "))
    assert n == 26719 != face.model.n_vertices
    assert "the scan's 26719 vertices" in said and f"{face.model.n_vertices} simulated vertices" not in said, said
