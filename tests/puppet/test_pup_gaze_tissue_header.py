"""Takes say that the tissue round the globe is carried by the turning eyes (the header's "gaze
tissue", the rig's `gaze`, `sim.gaze_lids.tissue_fields`): a take recorded before replays bit for
bit without it, on the rig shipped with it; a new take replays bit for bit with it; and the two
ways part on a turning gaze, which is what the header is for."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from header_takes import replay_to_end, with_header

from puppet.capture.take import write_take
from puppet.errors import ConfigError
from puppet.live import GAZE_TISSUE_AS, load_face
from puppet.session import read_session

DATA = Path(__file__).parent / "data"
#: recorded by main at 3af3024 on the scanned head as shipped then (rig hash babc28fc2073568e: the
#: shipped rig without its `gaze` fields): 120 ticks at 120 Hz, the gaze turning to the face's right
#: to -0.9, up to 0.7 from tick 30, the eyes converging 0.2 from tick 60, the left smile rising to 0.4
#: (`_look_around` below, on that code)
OLD = DATA / "take_before_gaze_tissue.jsonl"
#: the rig shipped with the tissue (hash 5d11ba0fe38578c5: the take's rig and its `gaze` fields, nothing
#: else changed); later rigs refit fields the take drives (the smile's), so the take replays on this
#: one, passed as `puppet replay --rig` would pass it
RIG = str(DATA / "rig_gaze_tissue.npz")


def _look_around(tmp_path: Path) -> Path:
    face = load_face(face="ict")
    names = [c.name for c in face.vocab.channels]
    values = np.tile(np.array(face.vocab.defaults(), float), (120, 1))
    values[:, names.index("eyes_yaw")] = np.linspace(0.0, -0.9, 120)
    values[30:, names.index("eyes_pitch")] = np.linspace(0.0, 0.7, 90)
    values[60:, names.index("eyes_vergence")] = 0.2
    values[:, names.index("zygomaticus_major_l")] = np.linspace(0.0, 0.4, 120)
    take = tmp_path / "look.jsonl"
    write_take(take, face, values, 120.0, {"test": True})
    return take


@pytest.fixture(scope="module")
def new_take(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _look_around(tmp_path_factory.mktemp("new"))


def test_a_take_from_before_replays_bit_for_bit() -> None:
    header = read_session(OLD).header
    assert "gaze tissue" not in header and header["rig"]["hash"] == "babc28fc2073568e"
    assert load_face(face="ict").model.rig.gaze  # the shipped rig carries the tissue now
    rp = replay_to_end(OLD, rig=RIG)
    assert rp.sim.method == "implicit"
    assert not rp.perf.gaze_tissue and not rp.sim.gaze_tissue
    assert rp.verified == 2 and not rp.mismatches


def test_the_new_way_would_not_replay_it() -> None:
    assert replay_to_end(OLD, rig=RIG, gaze_tissue=True).mismatches


def test_a_new_take_says_so_and_replays_bit_for_bit(new_take: Path) -> None:
    assert read_session(new_take).header["gaze tissue"] == GAZE_TISSUE_AS
    rp = replay_to_end(new_take)
    assert rp.perf.gaze_tissue and rp.sim.gaze_tissue
    assert rp.verified == 2 and not rp.mismatches


def test_without_its_key_a_new_take_is_replayed_the_old_way(new_take: Path, tmp_path: Path) -> None:
    take = with_header(new_take, tmp_path / "without.jsonl", lambda h: h.pop("gaze tissue"))
    rp = replay_to_end(take)
    assert not rp.perf.gaze_tissue
    assert rp.mismatches


def test_a_damaged_entry_is_named(tmp_path: Path) -> None:
    take = with_header(OLD, tmp_path / "bad.jsonl", lambda h: h.update({"gaze tissue": [GAZE_TISSUE_AS]}))
    with pytest.raises(ConfigError, match="gaze tissue"):
        read_session(take)
