"""Takes say that the upper and lower lids are carried sideways apart by the turning eyes (the
header's "lid coupling", `sim.gaze_lids.lid_couplings`): a take recorded before, with the lids held
alike, replays bit for bit the old way; a new take replays bit for bit the new way; and the two ways
part on a moving gaze, which is what the header is for."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from header_takes import replay_to_end, with_header

from puppet.capture.take import write_take
from puppet.errors import ConfigError
from puppet.live import LIDS_APART_AS, load_face
from puppet.session import read_session

DATA = Path(__file__).parent / "data"
#: recorded by main at 37b0100 on the scanned head (rig hash b1e3de12b4e812a7, the shipped rig
#: then; it replays to the same bits on the rig shipped at 095760e, hash 3eae69a52ccd3d38, which
#: differs from it only in channels the take leaves at 0: `RIG`, passed as `puppet replay --rig`
#: would pass it; the smile's, the lids' and the jaw's fields were refitted since): 120 ticks at 120 Hz, the
#: gaze turning aside to 0.8, then down to -0.6 from tick 30, the eyes converging 0.3 from tick 60,
#: the left smile rising to 0.4 (`_look_around` below, on that code)
OLD = DATA / "take_lids_alike.jsonl"
RIG = str(DATA / "take_responses_f64_rig.npz")


def _look_around(tmp_path: Path) -> Path:
    face = load_face(face="ict")
    names = [c.name for c in face.vocab.channels]
    values = np.tile(np.array(face.vocab.defaults(), float), (120, 1))
    values[:, names.index("eyes_yaw")] = np.linspace(0.0, 0.8, 120)
    values[30:, names.index("eyes_pitch")] = np.linspace(0.0, -0.6, 90)
    values[60:, names.index("eyes_vergence")] = 0.3
    values[:, names.index("zygomaticus_major_l")] = np.linspace(0.0, 0.4, 120)
    take = tmp_path / "look.jsonl"
    write_take(take, face, values, 120.0, {"test": True})
    return take


@pytest.fixture(scope="module")
def new_take(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _look_around(tmp_path_factory.mktemp("new"))


def test_a_take_from_before_replays_bit_for_bit() -> None:
    header = read_session(OLD).header
    assert "lid coupling" not in header and header["lids"] == "gaze"
    assert header["rig"]["hash"] == "b1e3de12b4e812a7"
    rp = replay_to_end(OLD, rig=RIG)
    assert rp.sim.method == "implicit"
    assert not rp.perf.lids_apart and not rp.sim.lids_apart
    assert rp.verified == 2 and not rp.mismatches


def test_the_new_way_would_not_replay_it() -> None:
    assert replay_to_end(OLD, rig=RIG, lids_apart=True).mismatches


def test_a_new_take_says_so_and_replays_bit_for_bit(new_take: Path) -> None:
    assert read_session(new_take).header["lid coupling"] == LIDS_APART_AS
    rp = replay_to_end(new_take)
    assert rp.perf.lids_apart and rp.sim.lids_apart
    assert rp.verified == 2 and not rp.mismatches


def test_without_its_key_a_new_take_is_replayed_the_old_way(new_take: Path, tmp_path: Path) -> None:
    take = with_header(new_take, tmp_path / "without.jsonl", lambda h: h.pop("lid coupling"))
    rp = replay_to_end(take)
    assert not rp.perf.lids_apart
    assert rp.mismatches


def test_a_damaged_entry_is_named(tmp_path: Path) -> None:
    take = with_header(OLD, tmp_path / "bad.jsonl", lambda h: h.update({"lid coupling": [LIDS_APART_AS]}))
    with pytest.raises(ConfigError, match="lid coupling"):
        read_session(take)
