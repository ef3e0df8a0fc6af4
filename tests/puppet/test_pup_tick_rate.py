"""The tick rate is the take's: a show on the wall clock ticks at 240 Hz (frames still at the
display's rate), records it, and replays bit-identically; a take written before the rate was a
choice (no tick_rate in its header) replays as the 60 Hz take it is."""

from __future__ import annotations

import json
from pathlib import Path

from puppet.session import read_session
from puppet_helpers import ENV
from puppet_helpers import run_puppet as puppet

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"


def test_a_240_hz_show_records_its_rate_and_replays_bit_identically(tmp_path: Path) -> None:
    rec = tmp_path / "fast.jsonl"
    out = puppet("live", "--headless", "--no-panel", "--device", f"mock://{SCRIPT}?speed=1", "--duration", "1.5",
                 "--record", str(rec), env=ENV)
    assert out.returncode == 0, out.stderr[-2000:]
    s = read_session(rec)
    assert s.tick_rate == 240.0 and s.ticks == 360 and s.complete  # the default on the wall clock
    assert any(e.get("t") == "ev" for e in s.events)
    replay = puppet("replay", str(rec), "--headless", env=ENV)
    assert replay.returncode == 0, replay.stderr
    assert "bit-identical to the live session at 6 checkpoints" in replay.stdout  # one every 60 ticks


def test_a_take_without_a_tick_rate_replays_at_60_hz(tmp_path: Path) -> None:
    rec = tmp_path / "slow.jsonl"
    out = puppet("live", "--headless", "--no-panel", "--device", f"mock://{SCRIPT}?speed=1", "--duration", "1.2",
                 "--tick-rate", "60", "--record", str(rec), env=ENV)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = rec.read_text().splitlines()
    head = json.loads(lines[0])
    assert head["tick_rate"] == 60.0
    del head["tick_rate"]  # as the takes of earlier versions were written
    rec.write_text("\n".join([json.dumps(head), *lines[1:]]) + "\n")
    s = read_session(rec)
    assert s.tick_rate == 60.0 and s.ticks == 72
    replay = puppet("replay", str(rec), "--headless", env=ENV)
    assert replay.returncode == 0, replay.stderr
    assert "bit-identical" in replay.stdout and "(1.20 s)" in replay.stdout


def test_a_damaged_or_unwritable_tick_rate_cache_only_means_measuring_again(tmp_path: Path, monkeypatch) -> None:
    """The measured rate kept in the face cache: a file nested thousands deep is measured again
    (it was a RecursionError before the show started), and a cache that cannot be written (a full
    disk or a read-only folder: safefile's one-line BadFile) leaves the show its measured rate."""
    import safefile
    from puppet import face_cache
    from puppet.live import load_face
    from puppet.tick_rate import TICK_RATES, live_tick_rate

    monkeypatch.setenv(face_cache.ENV, str(tmp_path))
    face = load_face(None, 0, face="procedural")
    rate = live_tick_rate(face)
    assert rate in TICK_RATES
    (kept,) = tmp_path.glob("tick-rate-*.json")
    kept.write_text("[" * 5000 + "]" * 5000)
    assert live_tick_rate(face) in TICK_RATES
    kept.unlink()

    def full(path, *a, **k):
        raise safefile.BadFile(f"{path}: cannot write: No space left on device")

    monkeypatch.setattr(safefile, "atomic_write", full)
    assert live_tick_rate(face) in TICK_RATES
    assert not list(tmp_path.glob("tick-rate-*.json"))
