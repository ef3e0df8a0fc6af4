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
FINAL_JAW = "9b3cf2430cc91d86"


def test_a_take_with_the_jaw_and_age_taken_whole_replays_bit_for_bit() -> None:
    perf = build_performance(read_session(OLD_JAW), None)
    assert not perf.muscles_summed and not perf.jaw_responses
    rp = Replayer(perf)
    assert rp.sim.method == "implicit" and not rp.sim.jaw_responses
    rp.seek(perf.ticks)
    assert rp.verified == 2 and not rp.mismatches
    from puppet.replay import state_digest

    assert state_digest(rp.state) == FINAL_JAW


def test_the_jaw_as_responses_would_not_replay_it() -> None:
    """The take moves the jaw and the age, so the step from the last pose gives other bits."""
    perf = build_performance(read_session(OLD_JAW), None)
    perf.jaw_responses = True
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    assert rp.mismatches
