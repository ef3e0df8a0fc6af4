"""Takes say how the implicit step's substeps solve (the header's "solve",
`sim.Simulator.symmetric_solve`): from the symmetric factor alone (L and D) in takes that say so;
from L and U in takes recorded before, which replay that way, bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from puppet.capture.take import write_take
from puppet.live import SOLVE_AS, load_face
from puppet.replay import Replayer, build_performance, state_digest
from puppet.session import read_session

#: recorded before the substeps solved from the symmetric factor (its header has "jaw bending" but
#: no "solve"), by that code: the ict face at 120 Hz, one second of the jaw opening to 0.8, the age
#: 30 -> 70 and the left smile at 0.5 from tick 40 (`_open_and_age` below, written by `write_take`)
OLD = Path(__file__).parent / "data" / "take_solve_lu.jsonl"
FINAL = "5ae0ccadeaf904ba"  # the recording program's last state


def _replay(path: Path, symmetric: bool | None = None) -> Replayer:
    perf = build_performance(read_session(path), None)
    if symmetric is not None:
        perf.symmetric_solve = symmetric
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    return rp


def test_a_take_from_before_the_symmetric_solve_replays_bit_for_bit() -> None:
    assert "solve" not in read_session(OLD).header
    rp = _replay(OLD)
    assert not rp.perf.symmetric_solve and not rp.sim.symmetric_solve
    assert rp.verified == 2 and not rp.mismatches
    assert state_digest(rp.state) == FINAL


def test_the_symmetric_solve_would_not_replay_it() -> None:
    """What the header is for: the two solves part in the last bits."""
    rp = _replay(OLD, symmetric=True)
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


def test_a_new_take_says_so_and_replays_bit_for_bit(tmp_path: Path) -> None:
    take = _open_and_age(tmp_path)
    assert read_session(take).header["solve"] == SOLVE_AS
    rp = _replay(take)
    assert rp.perf.symmetric_solve and rp.sim.symmetric_solve and rp.sim.method == "implicit"
    assert rp.verified == 2 and not rp.mismatches


def test_without_the_header_a_new_take_is_replayed_with_l_and_u(tmp_path: Path) -> None:
    take = _open_and_age(tmp_path)
    lines = take.read_text().splitlines()
    header = json.loads(lines[0])
    del header["solve"]
    take.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    rp = _replay(take)
    assert not rp.perf.symmetric_solve
    assert rp.mismatches  # recorded with the symmetric solve: L and U give other bits


def test_a_damaged_solve_entry_is_named(tmp_path: Path) -> None:
    import pytest

    from puppet.errors import ConfigError

    lines = OLD.read_text().splitlines()
    header = json.loads(lines[0])
    header["solve"] = ["symmetric factor"]
    take = tmp_path / "bad.jsonl"
    take.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    with pytest.raises(ConfigError, match="solve"):
        read_session(take)
