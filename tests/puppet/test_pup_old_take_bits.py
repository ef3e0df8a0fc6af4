"""A take recorded before the implicit step added the muscles as precomputed responses (its header
has no "muscles") replays with the muscles summed into the frame's forces, as it was recorded:
bit for bit. `data/take_muscles_summed.jsonl` was recorded by that earlier code (the procedural
face at resolution 1, on the implicit step, a smile and a brow turned up over one second)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from puppet.replay import Replayer, build_performance
from puppet.session import read_session

OLD = Path(__file__).parent / "data" / "take_muscles_summed.jsonl"
FINAL = "835591b4ea1c2cd3"  # the recording program's last state


def test_a_take_from_before_the_responses_replays_bit_for_bit() -> None:
    perf = build_performance(read_session(OLD), None)
    assert perf.muscles_summed
    rp = Replayer(perf)
    assert rp.sim.method == "implicit"
    rp.seek(perf.ticks)
    assert rp.verified == 2 and not rp.mismatches
    from puppet.replay import state_digest

    assert state_digest(rp.state) == FINAL


def test_the_responses_alone_would_not_replay_it() -> None:
    """What the flag is for: the same values through the responses differ in their last bits."""
    perf = build_performance(read_session(OLD), None)
    perf.muscles_summed = False
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    assert rp.mismatches


def test_puppet_replay_of_the_old_take_says_bit_identical(tmp_path: Path) -> None:
    take = tmp_path / "old.jsonl"
    shutil.copyfile(OLD, take)
    out = subprocess.run([sys.executable, "-m", "puppet", "replay", str(take), "--headless"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "bit-identical to the live session at 2 checkpoints" in out.stdout


#: recorded before the step started from the last step's jaw opening and skin age (its header has
#: "muscles" but no "jaw"), by that code with the scanned head's fitted skin: the ict face at 120 Hz,
#: the SGI box's default map played by the mock box, a smile, the jaw and the age turned up over one second
OLD_JAW = Path(__file__).parent / "data" / "take_jaw_whole.jsonl"
#: the scanned head's rig it was recorded on (hash aceb05fae80282b4, the shipped ict_rig.npz then):
#: the rig has changed since, and a take replays bit for bit on the rig it was recorded with
#: (`puppet replay --rig`), as the replay's warning says
OLD_JAW_RIG = Path(__file__).parent / "data" / "take_jaw_whole_rig.npz"
FINAL_JAW = "9b3cf2430cc91d86"


def test_a_take_with_the_jaw_and_age_taken_whole_replays_bit_for_bit() -> None:
    perf = build_performance(read_session(OLD_JAW), None, rig_path=str(OLD_JAW_RIG))
    assert not perf.muscles_summed and not perf.jaw_responses
    rp = Replayer(perf)
    assert rp.sim.method == "implicit" and not rp.sim.jaw_responses
    rp.seek(perf.ticks)
    assert rp.verified == 2 and not rp.mismatches
    from puppet.replay import state_digest

    assert state_digest(rp.state) == FINAL_JAW


def test_the_jaw_as_responses_would_not_replay_it() -> None:
    """The take moves the jaw and the age, so the step from the last pose gives other bits."""
    perf = build_performance(read_session(OLD_JAW), None, rig_path=str(OLD_JAW_RIG))
    perf.jaw_responses = True
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    assert rp.mismatches


#: recorded before a scanned head's forehead bent as its bound layer (its header has "muscles",
#: "lids" and "jaw" but no "bending"), by that code: the ict face at 120 Hz, the SGI box's default
#: map played by the mock box, the brows raised (frontalis) then drawn down (corrugator, procerus)
#: over one second
OLD_FOREHEAD = Path(__file__).parent / "data" / "take_thin_forehead.jsonl"
FINAL_FOREHEAD = "1fa7a8221aa4c588"
THIN_FOREHEAD_HASH = "0804b9ee47a2e609"  # the default face's hash then
#: the scanned head's rig it was recorded on (the shipped ict_rig.npz then, before the lower lid's
#: tightener was added): a take replays bit for bit on the rig it was recorded with (`--rig`)
OLD_FOREHEAD_RIG = Path(__file__).parent / "data" / "take_thin_forehead_rig.npz"


def test_a_take_from_before_the_bound_forehead_replays_bit_for_bit_on_its_face() -> None:
    perf = build_performance(read_session(OLD_FOREHEAD), None, rig_path=str(OLD_FOREHEAD_RIG))
    assert "bending" not in read_session(OLD_FOREHEAD).header
    assert perf.face.model.params.forehead_bending == 1.0
    assert perf.face.rig["hash"] == THIN_FOREHEAD_HASH
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    assert rp.verified == 2 and not rp.mismatches
    from puppet.replay import state_digest

    assert state_digest(rp.state) == FINAL_FOREHEAD


def test_the_bound_forehead_would_not_replay_it() -> None:
    """What the header's "bending" is for: the take raises and knits the brows, which the bound
    layer's bending changes."""
    from puppet.live import BENDING_AS
    from puppet.replay import Replayer as R

    session = read_session(OLD_FOREHEAD)
    session.header["bending"] = BENDING_AS
    perf = build_performance(session, None, rig_path=str(OLD_FOREHEAD_RIG))
    assert perf.face.model.params.forehead_bending > 1.0
    assert perf.face.rig["hash"] != THIN_FOREHEAD_HASH
    rp = R(perf)
    rp.seek(perf.ticks)
    assert rp.mismatches


def test_an_export_says_when_the_simulation_left_the_recording(tmp_path: Path) -> None:
    """An export of a take this program does not simulate as the show did (here its first checksum
    altered) is written, with one warning line naming the tick; the take as recorded exports
    without one."""
    import json

    lines = OLD.read_text(encoding="utf-8").splitlines()
    first = next(i for i, line in enumerate(lines) if json.loads(line).get("t") == "chk")
    rec = json.loads(lines[first])
    changed = dict(rec, sha="0" * len(rec["sha"]))
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join(lines[:first] + [json.dumps(changed)] + lines[first + 1:]) + "\n", encoding="utf-8")
    good = tmp_path / "good.jsonl"
    shutil.copyfile(OLD, good)
    for take, warned in ((bad, True), (good, False)):
        out = subprocess.run([sys.executable, "-m", "puppet", "replay", str(take), "--out",
                              str(take.with_suffix(".pc2")), "--fps", "30"], capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        assert take.with_suffix(".pc2").stat().st_size > 0
        said = f"diverged from the recording at tick {rec['tick']}" in out.stderr
        assert said == warned, out.stderr


#: recorded on main 2ed57ef, before the lips' sphincter and the mentalis had sided halves (its
#: header lists 55 channels, no orbicularis_oris_l/_r or mentalis_l/_r), by that code: the ict
#: face at 120 Hz, the SGI box's default map played by the mock box, the lips' sphincter toggled
#: on (button14) and the chin raised (button25 held) over one second
OLD_LIPS = Path(__file__).parent / "data" / "take_whole_lips.jsonl"
#: the scanned head's rig it was recorded on (the shipped ict_rig.npz then, hash 1f962233d96cb540)
OLD_LIPS_RIG = Path(__file__).parent / "data" / "take_whole_lips_rig.npz"
FINAL_LIPS = "2fbe1f4bf9593e42"


def test_a_take_from_before_the_sided_halves_replays_bit_for_bit() -> None:
    import numpy as np

    session = read_session(OLD_LIPS)
    assert "orbicularis_oris" in session.channels and "mentalis_l" not in session.channels
    values = np.asarray(session.value_array([0.0] * len(session.channels)))
    for whole in ("orbicularis_oris", "mentalis"):  # it drives the whole channels the halves now sit beside
        assert values[:, session.channels.index(whole)].max() > 0.9
    perf = build_performance(session, None, rig_path=str(OLD_LIPS_RIG))
    assert perf.face.rig["hash"] == "1f962233d96cb540"
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    assert rp.verified == 2 and not rp.mismatches
    from puppet.replay import state_digest

    assert state_digest(rp.state) == FINAL_LIPS
