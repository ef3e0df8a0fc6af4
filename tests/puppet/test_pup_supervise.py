"""The show survives: SIGKILL loses at most the tick in progress; `puppet live --supervise` brings a
crashed show back (an injected exception, SIGKILL) and continues the same take as a new segment,
with the face's last channel values, replayable as one take, bit for bit."""

from __future__ import annotations

import json
import mmap
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from puppet import live, resume
from puppet.errors import ConfigError
from puppet.session import SessionWriter, read_session
from puppet_helpers import ENV, ev, mapper
from puppet_helpers import run_puppet as puppet
from fakeclock import FakeClock

CHILD = Path(__file__).with_name("show_child.py")

SCRIPT = """
impersonate = "sgi"
speed = {speed}
duration = {duration}
[[ramp]]
control = "dial1"
start = 0.05
duration = {ramp}
from = 0.0
to = 0.9
rate = 50
[[events]]
t = 0.2
control = "button0"
value = 1
"""


def script(tmp_path: Path, speed: float = 0, duration: float = 3.0) -> str:
    p = tmp_path / "script.toml"
    p.write_text(SCRIPT.format(speed=speed, duration=duration, ramp=duration - 0.5))
    return f"mock://{p}"


@pytest.fixture(scope="module")
def face() -> live.Face:
    return live.load_face()


# --- SIGKILL: at most the tick in progress ------------------------------------------------------

def test_sigkill_at_random_ticks_loses_at_most_the_tick_in_progress(tmp_path: Path) -> None:
    """The child writes the number of the tick it starts to shared memory; after SIGKILL at a
    random moment the file holds every tick before that one."""
    rng = np.random.default_rng(1414)
    for trial in range(2):
        rec, counter = tmp_path / f"k{trial}.jsonl", tmp_path / f"c{trial}"
        counter.write_bytes(struct.pack("q", -1))
        proc = subprocess.Popen([sys.executable, str(CHILD), str(rec), str(counter)], env=ENV,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        with open(counter, "r+b") as fh:
            shared = mmap.mmap(fh.fileno(), 8)
        target = int(rng.integers(20, 90))
        deadline = time.monotonic() + 120
        while struct.unpack_from("q", shared, 0)[0] < target:
            assert proc.poll() is None, proc.stderr.read().decode()[-800:] if proc.stderr else ""
            assert time.monotonic() < deadline, "the show never got going"
            time.sleep(float(rng.uniform(0, 0.004)))  # anywhere inside a tick
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        started = struct.unpack_from("q", shared, 0)[0]  # the tick in progress (or just done)
        s = read_session(rec)
        assert not s.complete
        assert started <= s.ticks <= started + 1, (started, s.ticks)
        assert len(s.values) >= started - 1  # the dial moved the face at every tick: each one is there


# --- resuming a take ------------------------------------------------------------------------------

def _take(tmp_path: Path, face: live.Face, ticks: int, end: bool) -> Path:
    spec = live.build_mapping(face.vocab, None, ["sgi:///dev/x"])
    p = tmp_path / "take.jsonl"
    w = SessionWriter(p, live.session_header(face, spec, 60.0, ["sgi:///dev/x"]), fsync_seconds=None)
    vals = np.array(face.vocab.defaults(), dtype=float)
    for k in range(ticks):
        vals[k % 5] = (k % 7) / 10
        w.event(k, ev(f"dial{k % 5}", 0.01, "dial", "sgi:///dev/x"))
        w.values(k, vals)
        w.tick(k + 1)
    if end:
        w.close(ticks)
    return p


def test_resume_point_of_a_file_cut_anywhere(tmp_path: Path, face: live.Face) -> None:
    """A take cut at every byte of its last records (a crash mid-write) continues from the last
    complete tick, with that tick's values; the appended segment reads back as one take."""
    full = _take(tmp_path, face, 40, end=True).read_bytes()
    start = len(full) - 1500
    for cut in range(start, len(full) + 1, 7):
        p = tmp_path / "cut.jsonl"
        p.write_bytes(full[:cut // 2])
        follower = resume.TakeFollower(p, face)  # a standby following the file as it grows
        follower.poll()
        p.write_bytes(full[:cut])
        s = read_session(p)
        point = resume.resume_point(p, face)
        assert point is not None and point.ticks == s.ticks
        assert np.array_equal(point.values, s.value_array(np.array(face.vocab.defaults()))[-1])
        followed = follower.point()
        if cut < len(full):  # (a take that ended cleanly is left to the full reader)
            assert followed is not None and (followed.ticks, followed.offset) == (point.ticks, point.offset)
            assert np.array_equal(followed.values, point.values)
        w = resume.open_resumed(point, SessionWriter, {"channels": s.channels})
        w.segment(point.ticks, resume.RESTART_LABEL)
        w.values(point.ticks, point.values + 0.0)
        w.tick(point.ticks + 1)
        w.close(point.ticks + 1)
        back = read_session(p)
        assert back.complete and not back.warnings and back.ticks == point.ticks + 1, cut
        assert back.segments == ([point.ticks] if point.ticks else [])


def test_resume_after_a_damaged_last_line_nested_thousands_deep(tmp_path: Path, face: live.Face) -> None:
    """The crash left a damaged last line (nested thousands deep): the take continues after the
    last complete tick and the damaged line is cut off; it was a RecursionError traceback."""
    full = _take(tmp_path, face, 40, end=True).read_bytes()
    body = full[:full.rindex(b'{"t":"end"')]
    p = tmp_path / "deep.jsonl"
    p.write_bytes(body + b"[" * 5000 + b"]" * 5000 + b"\n")
    point = resume.resume_point(p, face)
    assert point is not None and point.offset == len(body)
    assert point.ticks == read_session(p).ticks


def test_resume_refuses_another_faces_recording(tmp_path: Path, face: live.Face) -> None:
    p = _take(tmp_path, face, 5, end=False)
    lines = p.read_text().splitlines()
    head = json.loads(lines[0])
    head["rig"]["hash"] = "another"
    p.write_text("\n".join([json.dumps(head), *lines[1:]]) + "\n")
    with pytest.raises(ConfigError, match="another face"):
        resume.resume_point(p, face)
    assert resume.resume_point(tmp_path / "none.jsonl", face) is None


MAP = """
version = 1
device = "mock"
[[binding]]
control = "dial1"
target = "jaw"
[[binding]]
control = "fader"
target = "zygomaticus_major_l"
[[binding]]
control = "panic"
action = "panic"
"""


def test_held_values_stay_until_each_control_takes_over() -> None:
    m = mapper(MAP)
    names = [c.name for c in m.vocab.channels]
    restored = m.defaults.copy()
    restored[names.index("jaw")] = 0.6
    restored[names.index("zygomaticus_major_l")] = 0.8
    restored[names.index("frontalis_inner_l")] = 0.3  # nothing here drives it
    hold = resume.HeldValues(m, restored)
    for _ in range(3):
        out = hold.apply(m.step(1 / 60))
        assert np.array_equal(out, restored)  # not neutral
    m.feed(ev("dial1", 0.05, "dial"))  # a dial nudges on from the restored value
    out = hold.apply(m.step(1 / 60))
    assert out[names.index("jaw")] == pytest.approx(0.65, abs=0.02)
    assert out[names.index("zygomaticus_major_l")] == 0.8
    m.feed(ev("fader", 0.1))  # a fader far from 0.8 does not snap it (pickup)
    assert hold.apply(m.step(1 / 60))[names.index("zygomaticus_major_l")] == 0.8
    m.feed(ev("panic", 1.0, "button"))
    for _ in range(120):
        out = hold.apply(m.step(1 / 60))
    assert np.array_equal(out, m.defaults)  # a panic still eases everything to neutral


# --- the supervisor ------------------------------------------------------------------------------

def test_supervise_restarts_after_an_injected_exception(tmp_path: Path) -> None:
    rec = tmp_path / "take.jsonl"
    out = puppet("live", "--supervise", "--headless", "--device", script(tmp_path), "--record", str(rec),
                 env={**ENV, live.CRASH_ENV: "50"})
    assert out.returncode == 0, out.stderr[-2000:]
    assert "RuntimeError" in out.stderr and "restarted" in out.stderr and "continuing" in out.stderr
    s = read_session(rec)
    assert s.complete and s.ticks == 180 and s.segments == [50]
    assert (50, resume.RESTART_LABEL) in s.markers
    face = live.load_face()
    defaults = np.array(face.vocab.defaults(), dtype=float)
    vals = s.value_array(defaults)
    moved = np.flatnonzero(vals[49] != defaults)
    assert len(moved) >= 2  # the dial and the button had moved the face before the crash
    assert np.all(np.abs(vals[50, moved] - vals[49, moved]) < 0.05)  # and it did not snap back
    rp = puppet("replay", str(rec), "--headless")
    assert rp.returncode == 0, rp.stderr
    assert "replayed 180 ticks" in rp.stdout and "bit-identical to the live session at 3 checkpoints" in rp.stdout


def _children(pid: int) -> list[tuple[int, str]]:
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            out.append((int(d.name), cmd))
    return out


def _wait(cond, timeout: float = 120.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


def test_supervise_restarts_after_sigkill_and_stops_on_sigterm(tmp_path: Path) -> None:
    rec = tmp_path / "take.jsonl"
    sup = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--supervise", "--headless", "--device",
                            script(tmp_path, speed=1, duration=120), "--record", str(rec)],
                           env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        def standby_ready() -> bool:
            return any("--standby" in c for _, c in _children(sup.pid)) and rec.exists() \
                and read_session(rec).ticks > 30
        _wait(standby_ready)
        show = [p for p, c in _children(sup.pid) if "--standby" not in c]
        assert len(show) == 1
        os.kill(show[0], signal.SIGKILL)
        _wait(lambda: rec.exists() and read_session(rec).segments != [])
        k = read_session(rec).segments[0]
        _wait(lambda: read_session(rec).ticks > k + 30)  # the take goes on
        sup.send_signal(signal.SIGTERM)
        out, err = sup.communicate(timeout=60)
    finally:
        if sup.poll() is None:
            sup.kill()
            sup.wait()
    assert sup.returncode == 0, err[-2000:]
    assert "SIGKILL" in err and "from standby" in err
    assert not [p for p, _ in _children(sup.pid)]  # no process left behind
    s = read_session(rec)
    assert s.complete and s.segments == [k] and (k, resume.RESTART_LABEL) in s.markers
    rp = puppet("replay", str(rec), "--headless")
    assert rp.returncode == 0 and "mismatch" not in rp.stdout + rp.stderr, rp.stdout + rp.stderr


def test_supervise_does_not_restart_a_users_mistake(tmp_path: Path) -> None:
    out = puppet("live", "--supervise", "--headless", "--device", "nosuch://x", "--record",
                 str(tmp_path / "t.jsonl"))
    assert out.returncode == 2 and "restarted" not in out.stderr
    assert [x for x in out.stderr.splitlines() if "error" in x][0].count("nosuch") == 1
    out = puppet("live", "--resume", "--headless", "--device", script(tmp_path))
    assert out.returncode == 2 and "--record" in out.stderr


def test_resume_continues_a_crashed_take_as_a_restart_would(tmp_path: Path) -> None:
    """What the systemd unit does: the crashed command run again with --resume continues the take."""
    rec = tmp_path / "take.jsonl"
    args = ["live", "--headless", "--device", script(tmp_path, duration=2.0), "--record", str(rec), "--resume"]
    out = puppet(*args, env={**ENV, live.CRASH_ENV: "40"})
    assert out.returncode == 1 and "RuntimeError" in out.stderr
    assert read_session(rec).ticks == 40
    out = puppet(*args, env={**ENV, live.CRASH_ENV: "40"})  # the hook does not fire again: tick 40 is done
    assert out.returncode == 0, out.stderr[-2000:]
    assert "continuing" in out.stderr
    s = read_session(rec)
    assert s.complete and s.ticks == 120 and s.segments == [40]


def test_a_resumed_take_ticks_at_once_on_the_wall_clock(face: live.Face) -> None:
    """A core that starts at tick 600 (a resumed take) ticks from its own start, on the boundaries
    from there: it does not wait the 10 s the ticks before it took."""
    spec = live.build_mapping(face.vocab, None, ["mock://"])
    from puppet.mapping import Mapper

    core = live.LiveCore(face, Mapper(spec, face.vocab))
    core.tick_count = 600
    clk = FakeClock()
    drained_at: list[float] = []

    def drain() -> list:
        drained_at.append(clk.t)
        return []

    live.run_realtime(core, drain, 605 / 60, clock=clk, sleep=clk.sleep)
    assert core.tick_count == 605
    assert drained_at == pytest.approx([100.0 + k / 60 for k in range(5)])


def test_a_resumed_virtual_take_plays_only_the_rest_of_the_script(tmp_path: Path, face: live.Face) -> None:
    import devices

    dev = devices.open_device(script(tmp_path, duration=2.0))
    events = live.scripted_events([dev])
    spec = live.build_mapping(face.vocab, None, [dev.spec])
    seen: list[tuple[int, float]] = []

    class Spy(live.LiveCore):
        def tick(self, evs) -> None:  # type: ignore[no-untyped-def, override]
            evs = list(evs)
            seen.extend((self.tick_count, e.t) for e in evs)
            super().tick(evs)

    from puppet.mapping import Mapper

    full = Spy(face, Mapper(spec, face.vocab))
    live.run_virtual(full, events, 2.0)
    first = list(seen)
    seen.clear()
    rest = Spy(face, Mapper(spec, face.vocab))
    rest.tick_count = 50
    live.run_virtual(rest, events, 2.0)
    dev.close()
    assert rest.tick_count == 120 and seen == [x for x in first if x[0] >= 50]
