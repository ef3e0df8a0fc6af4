"""Takes say that their lids follow the gaze (the header's "lids", `sim.gaze_lids`): a take with
it replays bit for bit with the lids carried by the eyes; the same take without it (as one recorded
before the lids followed the gaze) is replayed with the lids still, and the lids' pull is what
makes the difference."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from puppet.capture.take import write_take
from puppet.live import load_face
from puppet.replay import Replayer, build_performance
from puppet.session import read_session

OLD = Path(__file__).parent / "data" / "take_muscles_summed.jsonl"


def _look_around(tmp_path: Path) -> Path:
    face = load_face()
    names = [c.name for c in face.vocab.channels]
    values = np.tile(np.array(face.vocab.defaults(), float), (120, 1))
    values[:, names.index("eyes_yaw")] = np.linspace(0.0, 1.0, 120)
    values[60:, names.index("eyes_pitch")] = -0.5
    take = tmp_path / "look.jsonl"
    write_take(take, face, values, 60.0, {"test": True})
    return take


def _replay(take: Path) -> Replayer:
    perf = build_performance(read_session(take), None)
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    return rp


def test_a_take_of_a_moving_gaze_replays_bit_for_bit(tmp_path: Path) -> None:
    take = _look_around(tmp_path)
    assert read_session(take).header["lids"] == "gaze"
    rp = _replay(take)
    assert rp.perf.lids_follow_gaze
    assert rp.verified == 2 and not rp.mismatches


def test_without_the_header_the_lids_stay_as_they_were_recorded_then(tmp_path: Path) -> None:
    take = _look_around(tmp_path)
    lines = take.read_text().splitlines()
    header = json.loads(lines[0])
    assert header["t"] == "header"
    del header["lids"]
    take.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    rp = _replay(take)
    assert not rp.perf.lids_follow_gaze
    assert rp.mismatches  # recorded with the lids following: replayed still, the bits differ


def test_an_old_take_is_replayed_with_the_lids_still() -> None:
    assert not build_performance(read_session(OLD), None).lids_follow_gaze


def test_one_eyes_look_turns_that_eye_only(tmp_path: Path) -> None:
    """An ARKit CSV of the left eye looking out alone reads as that eye turned fully and the right
    one not at all (the shared gaze half, the vergence half the other way), and is written back so."""
    import csv

    from puppet.capture.arkit_in import read_arkit_csv
    from puppet.export.arkit import ARKIT_SHAPES, ArkitCsvWriter, timecode
    from sim.channels import CHANNEL_NAMES

    src = tmp_path / "look.csv"
    rows = ["Timecode,BlendShapeCount," + ",".join(ARKIT_SHAPES)]
    rows += [f"{timecode(f, 30)},{len(ARKIT_SHAPES)}," + ",".join("1" if s == "EyeLookOutLeft" else "0"
                                                                   for s in ARKIT_SHAPES) for f in range(3)]
    src.write_text("\n".join(rows) + "\n")
    cap = read_arkit_csv(src)
    yaw, verge = (cap.values[:, CHANNEL_NAMES.index(c)] for c in ("eyes_yaw", "eyes_vergence"))
    assert np.allclose(yaw, 0.5) and np.allclose(verge, -0.5)
    out = tmp_path / "back.csv"
    w = ArkitCsvWriter(out, list(CHANNEL_NAMES), 30.0)
    for k, v in enumerate(cap.values):
        w.add(k, v)
    w.close()
    with open(out, newline="") as fh:
        row = next(csv.DictReader(fh))
    assert float(row["EyeLookOutLeft"]) == 1.0
    assert all(float(row[s]) == 0.0 for s in ("EyeLookInLeft", "EyeLookInRight", "EyeLookOutRight"))
    assert float(row["LeftEyeYaw"]) > 0.3 and float(row["RightEyeYaw"]) == 0.0  # quarter turns: 30 degrees, none
