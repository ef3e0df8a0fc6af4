"""Takes say how the implicit step was made where a newer step gives other bits, and takes
recorded before replay the old way, bit for bit:

- "jaw bending" (`sim.Simulator.bending_turned`): the margin bending's rest side at an open jaw
  from the jaw's turn, three values a row; before, the product of the bending matrix with the
  turned rest shape;
- "solve" (`sim.Simulator.symmetric_solve`): the substeps' solve from the symmetric factor alone
  (L and D); before, from L and U;
- "responses" (`sim.Simulator.single_responses`): the inputs' precomputed responses read in
  float32; before, in float64;
- "jaw constants" (`sim.Simulator.constants_from_grid`): at a jaw opening the target, support
  normals and constant forces read linearly between precomputed openings; before, the turn of
  every vertex at each opening."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from puppet.capture.take import write_take
from puppet.errors import ConfigError
from puppet.live import JAW_BENDING_AS, JAW_CONSTANTS_AS, RESPONSES_AS, SOLVE_AS, load_face
from puppet.replay import Replayer, build_performance, state_digest
from puppet.session import read_session

DATA = Path(__file__).parent / "data"
#: the shipped rig before the jaw was fitted to the scan (hash 3eae69a52ccd3d38)
RESPONSES_RIG = DATA / "take_responses_f64_rig.npz"


@dataclass(frozen=True)
class Way:
    key: str  # the take header's key
    value: str  # what a new take says
    attr: str  # the performance's and the simulator's switch
    old: Path  # a take recorded by the code before, without the key
    final: str  # that recording program's last state
    rig: Path | None = None  # the rig it replays on, as `puppet replay --rig` would pass it (None: OLD_RIG)


WAYS = [
    # the ict face at 120 Hz, the SGI box's default map played by the mock box, the jaw opened
    # (dial 7), the age (dial 0) and the smile (dial 1) turned up over one second
    Way("jaw bending", JAW_BENDING_AS, "bending_turned", DATA / "take_bending_product.jsonl", "9bca7fba6a16346e"),
    # the ict face at 120 Hz, one second of the jaw opening to 0.8, the age 30 -> 70 and the left
    # smile at 0.5 from tick 40 (`_open_and_age` below, written by `write_take`)
    Way("solve", SOLVE_AS, "symmetric_solve", DATA / "take_solve_lu.jsonl", "5ae0ccadeaf904ba"),
    # the same performance recorded by main at 2ed57ef on the shipped rig (float64 responses, the
    # jaw's constants turned at each opening): one take for both keys. It replays on the shipped rig
    # as it was before the jaw's hinge and weights were fitted to the scan (`sim.face.scan.jaw_fit`),
    # the last rig whose jaw, age and smile moved the skin as the one it was recorded on
    Way("responses", RESPONSES_AS, "single_responses", DATA / "take_responses_f64.jsonl", "fafa1c948267615b",
        rig=RESPONSES_RIG),
    Way("jaw constants", JAW_CONSTANTS_AS, "constants_from_grid", DATA / "take_responses_f64.jsonl", "fafa1c948267615b",
        rig=RESPONSES_RIG),
]
IDS = [w.key for w in WAYS]
#: the scanned head's rig both old takes replay bit for bit on (hash 5e71a5b7d3b2b2be, the shipped
#: ict_rig.npz until the skin under the chin was set free; they were recorded on 9beb46811f320c14,
#: which differs from it only by a channel they leave at 0): passed as `puppet replay --rig` would
OLD_RIG = DATA / "take_ict_held_chin_rig.npz"


def _replay(path: Path, way: Way, new: bool | None = None) -> Replayer:
    perf = build_performance(read_session(path), None, rig_path=str(way.rig or OLD_RIG) if path == way.old else None)
    if new is not None:
        setattr(perf, way.attr, new)
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    return rp


@pytest.mark.parametrize("way", WAYS, ids=IDS)
def test_a_take_from_before_replays_bit_for_bit(way: Way) -> None:
    assert way.key not in read_session(way.old).header
    rp = _replay(way.old, way)
    assert not getattr(rp.perf, way.attr) and not getattr(rp.sim, way.attr)
    assert rp.verified == 2 and not rp.mismatches
    assert state_digest(rp.state) == way.final


@pytest.mark.parametrize("way", WAYS, ids=IDS)
def test_the_new_way_would_not_replay_it(way: Way) -> None:
    """What the header is for: the takes open the jaw, where the two ways part in the last bits."""
    assert _replay(way.old, way, new=True).mismatches


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


@pytest.fixture(scope="module")
def new_take(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _open_and_age(tmp_path_factory.mktemp("new"))


def test_a_new_take_says_so_and_replays_bit_for_bit(new_take: Path) -> None:
    header = read_session(new_take).header
    rp = _replay(new_take, WAYS[0])
    assert rp.sim.method == "implicit" and rp.verified == 2 and not rp.mismatches
    for way in WAYS:
        assert header[way.key] == way.value
        assert getattr(rp.perf, way.attr) and getattr(rp.sim, way.attr)


@pytest.mark.parametrize("way", WAYS, ids=IDS)
def test_without_its_key_a_new_take_is_replayed_the_old_way(way: Way, new_take: Path, tmp_path: Path) -> None:
    lines = new_take.read_text().splitlines()
    header = json.loads(lines[0])
    del header[way.key]
    take = tmp_path / "without.jsonl"
    take.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    rp = _replay(take, way)
    assert not getattr(rp.perf, way.attr)
    assert rp.mismatches  # recorded the new way: the old one gives other bits


@pytest.mark.parametrize("way", WAYS, ids=IDS)
def test_a_damaged_entry_is_named(way: Way, tmp_path: Path) -> None:
    lines = way.old.read_text().splitlines()
    header = json.loads(lines[0])
    header[way.key] = [way.value]
    take = tmp_path / "bad.jsonl"
    take.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    with pytest.raises(ConfigError, match=way.key):
        read_session(take)
