"""Takes say how the implicit step made the margin bending's rest side at an open jaw (the header's
"jaw bending", `sim.Simulator.bending_turned`): from the jaw's turn, three values a row, in takes
that say so; as the product of the bending matrix with the turned rest shape in takes recorded
before, which replay that way, bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from puppet.capture.take import write_take
from puppet.live import JAW_BENDING_AS, load_face
from puppet.replay import Replayer, build_performance, state_digest
from puppet.session import read_session

#: recorded before the bending's rest side was made from the jaw's turn (its header has "muscles",
#: "lids", "jaw" and "bending" but no "jaw bending"), by that code: the ict face at 120 Hz, the SGI
#: box's default map played by the mock box, the jaw opened (dial 7), the age (dial 0) and the smile
#: (dial 1) turned up over one second
OLD = Path(__file__).parent / "data" / "take_bending_product.jsonl"
FINAL = "9bca7fba6a16346e"  # the recording program's last state


def _replay(path: Path, turned: bool | None = None) -> Replayer:
    perf = build_performance(read_session(path), None)
    if turned is not None:
        perf.bending_turned = turned
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    return rp


def test_a_take_from_before_the_turned_bending_replays_bit_for_bit() -> None:
    assert "jaw bending" not in read_session(OLD).header
    rp = _replay(OLD)
    assert not rp.perf.bending_turned and not rp.sim.bending_turned
    assert rp.verified == 2 and not rp.mismatches
    assert state_digest(rp.state) == FINAL


def test_the_turned_bending_would_not_replay_it() -> None:
    """What the header is for: the take opens the jaw, where the two ways part in the last bits."""
    rp = _replay(OLD, turned=True)
    assert rp.mismatches


def _open_and_age(tmp_path: Path) -> Path:
    face = load_face(face="ict")  # the scanned head: the live step is the implicit one there
    names = [c.name for c in face.vocab.channels]
    values = np.tile(np.array(face.vocab.defaults(), float), (120, 1))
    values[:, names.index("jaw")] = np.linspace(0.0, 0.8, 120)
    values[:, names.index("age")] = np.linspace(30.0, 70.0, 120)
    values[40:, names.index("zygomaticus_major_l")] = 0.5
    take = tmp_path / "open.jsonl"
    write_take(take, face, values, 120.0, {"test": True})
    return take


def test_a_new_take_opening_the_jaw_says_so_and_replays_bit_for_bit(tmp_path: Path) -> None:
    take = _open_and_age(tmp_path)
    assert read_session(take).header["jaw bending"] == JAW_BENDING_AS
    rp = _replay(take)
    assert rp.perf.bending_turned and rp.sim.bending_turned and rp.sim.method == "implicit"
    assert rp.verified == 2 and not rp.mismatches


def test_without_the_header_a_new_take_is_replayed_with_the_product(tmp_path: Path) -> None:
    take = _open_and_age(tmp_path)
    lines = take.read_text().splitlines()
    header = json.loads(lines[0])
    del header["jaw bending"]
    take.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    rp = _replay(take)
    assert not rp.perf.bending_turned
    assert rp.mismatches  # recorded with the turn: the product gives other bits
