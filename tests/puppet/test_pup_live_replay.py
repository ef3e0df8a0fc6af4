"""End to end: mock device -> mapping -> live loop with recording -> replay, bit for bit; crash
safety under SIGKILL; the command line, including the no-display fallback."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import devices
from devices.events import ControlEvent
from puppet import live
from puppet.mapping import Mapper
from puppet.replay import Replayer, build_performance
from puppet.session import SessionWriter, read_session
from puppet_helpers import ENV
from puppet_helpers import run_puppet as puppet

SCRIPT = """
impersonate = "sgi"
speed = {speed}
duration = {duration}
[[ramp]]
control = "dial1"
start = 0.05
duration = 0.5
from = 0.0
to = 0.9
rate = 50
[[ramp]]
control = "dial7"
start = 0.3
duration = 0.4
from = 0.0
to = 0.5
rate = 40
[[events]]
t = 0.2
control = "button0"
value = 1
[[events]]
t = 0.25
control = "button0"
value = 0
[[events]]
t = 0.6
control = "button7"
value = 1
[[events]]
t = 0.62
control = "button7"
value = 0
[[events]]
t = 0.7
control = "button30"
value = 1
"""



def script(tmp_path: Path, speed: float = 0, duration: float = 1.0) -> str:
    p = tmp_path / "script.toml"
    p.write_text(SCRIPT.format(speed=speed, duration=duration))
    return f"mock://{p}"


@pytest.fixture(scope="module")
def face() -> live.Face:
    return live.load_face()


def test_live_run_and_replay_are_bit_identical_at_every_tick(tmp_path: Path, face: live.Face) -> None:
    dev = devices.open_device(script(tmp_path))
    spec = live.build_mapping(face.vocab, None, [dev.spec])
    mapper = Mapper(spec, face.vocab)
    rec = tmp_path / "take.jsonl"
    writer = SessionWriter(rec, live.session_header(face, spec, live.TICK_RATE, [dev.spec]))
    core = live.LiveCore(face, mapper, writer=writer)
    live_positions: list[bytes] = []
    live.run_virtual(core, live.scripted_events([dev]), 1.0,
                     on_frame=lambda c: live_positions.append(c.state.positions.tobytes()))
    writer.close(core.tick_count)
    dev.close()
    assert core.tick_count == 60 and core.markers == [(42, "sgi marker")]
    # the performance moved the face: smile and jaw are on, so the check below is not vacuous
    assert live_positions[-1] != face.model.rest.tobytes()
    session = read_session(rec)
    assert session.complete and session.ticks == 60 and session.markers == [(42, "sgi marker")]
    assert any(e["ctl"] == "dial1" for e in session.events)
    for _ in range(2):  # two independent replays
        rp = Replayer(build_performance(session, None))
        for k in range(60):
            rp.step()
            assert rp.state.positions.tobytes() == live_positions[k], f"tick {k} differs"
        assert rp.verified == 1 and not rp.mismatches


def test_cli_record_then_replay_verifies(tmp_path: Path) -> None:
    rec = tmp_path / "s.jsonl"
    out = puppet("live", "--device", script(tmp_path), "--headless", "--record", str(rec), "--duration", "1.5")
    assert out.returncode == 0, out.stderr
    assert "performed 90 ticks" in out.stdout
    out = puppet("replay", str(rec), "--headless")
    assert out.returncode == 0, out.stderr
    assert "bit-identical to the live session at 1 checkpoints" in out.stdout


def test_a_missing_rig_given_to_replay_is_named_as_the_users(tmp_path: Path) -> None:
    """`puppet replay take.jsonl --rig typo.npz` said 'take.jsonl: recorded with rig typo.npz, which
    is missing; pass --rig PATH': the take blamed for a rig it never named, and told to do what was done."""
    rec = tmp_path / "s.jsonl"
    assert puppet("live", "--device", script(tmp_path), "--headless", "--record", str(rec), "--duration", "0.2",
                  "--no-panel").returncode == 0
    out = puppet("replay", str(rec), "--rig", str(tmp_path / "typo.npz"), "--out", str(tmp_path / "o.csv"))
    assert out.returncode == 2
    assert out.stderr.strip() == f"puppet: error: {tmp_path / 'typo.npz'}: no such rig file", out.stderr


def test_recording_into_a_missing_folder_is_one_line_before_the_show(tmp_path: Path) -> None:
    rec = tmp_path / "no-such-folder" / "s.jsonl"
    out = puppet("live", "--device", script(tmp_path), "--headless", "--record", str(rec), "--duration", "0.2")
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "does not exist" in lines[0] and "create it" in lines[0]
    assert not rec.parent.exists()


def test_recording_over_an_earlier_take_keeps_it_aside(tmp_path: Path) -> None:
    rec = tmp_path / "show.jsonl"
    assert puppet("live", "--device", script(tmp_path), "--headless", "--record", str(rec),
                  "--duration", "0.2").returncode == 0
    first = rec.read_bytes()
    out = puppet("live", "--device", script(tmp_path), "--headless", "--record", str(rec), "--duration", "0.3")
    assert out.returncode == 0, out.stderr
    kept = tmp_path / "show.1.jsonl"
    assert kept.read_bytes() == first  # the earlier take, byte for byte
    assert "kept as" in out.stderr and str(kept) in out.stderr
    assert read_session(rec).ticks == 18 and read_session(kept).ticks == 12


def test_sigkill_during_recording_leaves_a_replayable_file(tmp_path: Path) -> None:
    rec = tmp_path / "killed.jsonl"
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--device", script(tmp_path, speed=1, duration=60),
                             "--headless", "--record", str(rec), "--duration", "60", "--tick-rate", "60"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # wait until a good part is on disk (sync records)
            if rec.exists() and rec.read_text().count('"t":"sync"') >= 8:
                break
            time.sleep(0.05)
        else:
            pytest.fail("the recording never got flushed")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    text = rec.read_text()
    assert '"t":"end"' not in text
    s = read_session(rec)
    assert not s.complete and s.warnings and s.ticks >= 40
    out = puppet("replay", str(rec), "--headless")
    assert out.returncode == 0, out.stderr
    assert "warning" in out.stderr and f"replayed {s.ticks} ticks" in out.stdout


def test_sigterm_stops_cleanly_and_closes_the_recording(tmp_path: Path) -> None:
    rec = tmp_path / "term.jsonl"
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--device", script(tmp_path, speed=1, duration=60),
                             "--headless", "--record", str(rec)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=ENV)
    deadline = time.monotonic() + 60
    while not (rec.exists() and '"t":"sync"' in rec.read_text()) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert read_session(rec).complete and "performed" in out


def test_the_show_ends_after_its_background_builds(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A thread still loading compiled code (the wrinkle layer's build, started after the first
    frame) when the interpreter tears down aborts the whole process ("terminate called without an
    active exception", exit 134) after the show: a short show, or one stopped by SIGTERM right after
    its first frame, must wait for the build before it returns."""
    import threading

    from puppet.cli import main

    built = threading.Event()
    build = live.LiveCore._build_wrinkles

    def slow_build(self: live.LiveCore) -> None:
        time.sleep(1.5)  # a loaded machine loading the layer's kernels
        build(self)
        built.set()

    monkeypatch.setattr(live.LiveCore, "_build_wrinkles", slow_build)
    rec = tmp_path / "short.jsonl"
    code = main(["live", "--device", script(tmp_path, speed=1, duration=0.2), "--headless", "--record", str(rec),
                 "--duration", "0.2"])
    assert code == 0 and read_session(rec).complete
    assert built.is_set(), "the show returned while its wrinkle layer was still being built"


def test_background_wait_is_bounded() -> None:
    """A build that never ends does not hold the show's end: the wait gives up (and `puppet live`
    then ends the process without the interpreter's teardown)."""
    import threading

    release = threading.Event()
    live.start_background(threading.Thread(target=release.wait, daemon=True))
    t = time.monotonic()
    assert not live.join_background(0.2)
    assert time.monotonic() - t < 5
    release.set()
    assert live.join_background(5)


def test_no_display_falls_back_to_headless_and_says_where(tmp_path: Path) -> None:
    env = {k: v for k, v in ENV.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    out = subprocess.run([sys.executable, "-m", "puppet", "live", "--device", script(tmp_path), "--duration", "0.5"],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=90)
    assert out.returncode == 0, out.stderr
    first = out.stderr.strip().splitlines()[0]
    assert "no display" in first and "recording to" in first
    recs = list(tmp_path.glob("puppet-*.jsonl"))
    assert len(recs) == 1 and read_session(recs[0]).ticks == 30
    assert recs[0].with_suffix(".png").exists()


@pytest.mark.parametrize("args,msg", [
    (["live", "--device", "nosuch://x", "--headless", "--duration", "1"], "nosuch"),
    (["live", "--device", "mock://", "--headless", "--duration", "-1"], "--duration"),
    (["replay", "/nonexistent.jsonl", "--headless"], "nonexistent.jsonl"),
    (["replay", "--headless"], "recording FILE"),
    # '.' was a ValueError traceback ('has an empty name'), a folder 'cannot be kept aside'
    (["live", "--device", "mock://", "--headless", "--duration", "1", "--record", "."], "names a folder"),
    (["live", "--device", "mock://", "--headless", "--duration", "1", "--record", "/tmp"], "names a folder"),
    # nan or -1 ended the monitor, or the learn, at once and silently (exit 0)
    (["monitor", "mock://", "--duration", "nan"], "--duration"),
    (["monitor", "mock://", "--duration", "-1"], "--duration"),
    (["learn", "--device", "mock://", "--map", "/tmp/x.toml", "--timeout", "nan"], "--timeout"),
])
def test_user_errors_are_one_line(args: list[str], msg: str) -> None:
    out = puppet(*args)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("puppet: error:") and msg in lines[0]


def test_bad_mapping_file_is_one_line_with_location(tmp_path: Path) -> None:
    m = tmp_path / "bad.toml"
    m.write_text('[[binding]]\ncontrol = "dial0"\ntarget = "jaw"\nfilters = [{type = "smoth"}]\n')
    out = puppet("live", "--device", script(tmp_path), "--map", str(m), "--headless", "--duration", "0.1")
    assert out.returncode == 2
    assert out.stderr.strip() == (f"puppet: error: {m}:4:13: expected one of range, invert, curve, deadzone, "
                                  "smooth, one_euro, slew for type, got 'smoth'")


def test_a_bad_mapping_file_is_said_before_the_face_loads(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture) -> None:
    """The map's own error came after the face had loaded: seconds on a busy machine, and the
    "preparing the face" notice (due after 3 s) then came first, which the test above met once."""
    from puppet.cli import main

    m = tmp_path / "bad.toml"
    m.write_text('[[binding]]\ncontrol = "dial0"\ntarget = "jaw"\nfilters = [{type = "smoth"}]\n')

    def no_face(*args: object, **kwargs: object) -> None:
        raise AssertionError("the face was loaded before the map was read")

    monkeypatch.setattr(live, "load_face", no_face)
    monkeypatch.setenv("PUPPET_LIBRARY", "off")
    assert main(["live", "--device", script(tmp_path), "--map", str(m), "--headless", "--duration", "0.1"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"puppet: error: {m}:4:13: expected one of range, invert, curve, deadzone, smooth, one_euro, slew for type, "
        "got 'smoth'"]


def test_recording_header(tmp_path: Path) -> None:
    rec = tmp_path / "h.jsonl"
    assert puppet("live", "--device", script(tmp_path), "--headless", "--record", str(rec)).returncode == 0
    head = json.loads(rec.read_text().splitlines()[0])
    assert head["format"] == "facepuppet-session" and head["version"] == 1 and head["tick_rate"] == 60.0
    assert head["rig"]["hash"] and "jaw" in head["channels"] and head["program"].startswith("facepuppet")
    assert "dial0" in head["mapping"]["text"] and head["start_time"].endswith("+00:00")
    assert np.isfinite(read_session(rec).value_array(np.zeros(len(head["channels"])))).all()


def test_box_plugged_in_mid_show_is_adopted_with_its_map(tmp_path: Path, face: live.Face,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from devices.discovery import DeviceInfo
    from devices.events import ControlEvent
    from puppet.cmd_live import DeviceWatcher

    new_spec = script(tmp_path)
    monkeypatch.setattr(devices, "discover", lambda probe=False: [DeviceInfo(new_spec, "rehearsal box", "mock", True)])
    core = live.LiveCore(face, Mapper(live.build_mapping(face.vocab, None, []), face.vocab))
    queue = devices.EventQueue()
    devs: list = []
    w = DeviceWatcher(devs, queue, interval=0.05)
    core.before_tick.append(w.adopt)
    w.start()
    try:
        deadline = time.monotonic() + 10
        while not devs and time.monotonic() < deadline:
            core.tick([])
            time.sleep(0.02)
    finally:
        w.close()
        for d in devs:
            d.close()
    assert [d.spec for d in devs] == [new_spec] and core.markers[-1][1] == f"plugged in: {new_spec}"
    core.tick([ControlEvent(new_spec, "dial7", "dial", 0.5)])  # its default (SGI) map is live
    for _ in range(30):
        core.tick([])
    assert core.values[[c.name for c in face.vocab.channels].index("jaw")] > 0.4


def test_hud_shows_key_map_latency_and_lost_devices(face: live.Face) -> None:
    from devices.events import StatusEvent

    kb = devices.open_device("keyboard://")
    core = live.LiveCore(face, Mapper(live.build_mapping(face.vocab, None, [kb.spec], system_keys=True), face.vocab))
    core.tick([ControlEvent(kb.spec, "key:A", "key", 1.0, None, "A", 0.0)])
    core.presented(0.012)
    hud = live.live_hud(core, [kb], keymap=True)
    text = "\n".join(hud.lines)
    assert "Q brow up" in text and "A smile" in text and "ESC panic" in text and len(hud.lines) <= 24
    assert hud.latency_ms == pytest.approx(12.0)
    assert any(name.startswith("zygomaticus_major") for name, *_ in hud.channels)
    assert hud.devices == [(kb.spec, True)]
    core.tick([StatusEvent(kb.spec, "lost")])
    hud = live.live_hud(core, [kb], keymap=False)
    assert hud.devices == [(kb.spec, False)] and any(line.startswith("LOST key:A") for line in hud.lines)
    assert "A smile" not in "\n".join(hud.lines)
    kb.close()


class FakeClock:
    """A clock that only moves when slept on (records every sleep)."""

    def __init__(self) -> None:
        self.t = 100.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.t += max(s, 0.0)


def test_wait_until_reaches_the_absolute_deadline_without_spinning_on_a_fake_clock() -> None:
    clk = FakeClock()
    woke = live.wait_until(100.2, clk, clk.sleep)
    assert woke >= 100.2 and clk.t == woke
    assert all(s <= 0.05 + 1e-12 for s in clk.sleeps)  # chunks, so a stop flag is noticed
    stop = live.StopFlag(stopped=True)
    assert live.wait_until(200.0, clk, clk.sleep, stop=stop) == clk.t  # a stop ends the wait at once
    assert live.wait_until(50.0, clk, clk.sleep) == clk.t  # a past deadline does not wait


def test_realtime_ticks_drain_input_at_each_boundary(face: live.Face) -> None:
    clk = FakeClock()
    spec = live.build_mapping(face.vocab, None, ["mock://"])
    core = live.LiveCore(face, Mapper(spec, face.vocab))
    arrivals = {3: [ControlEvent("mock://", "dial7", "dial", 0.25, 50.0, 50, 100.04)]}
    drained_at: list[float] = []

    def drain() -> list:
        k = len(drained_at)
        drained_at.append(clk.t)
        return arrivals.get(k, [])

    live.run_realtime(core, drain, 0.1, clock=clk, sleep=clk.sleep)
    assert core.tick_count == 6 and len(drained_at) == 6
    assert drained_at == pytest.approx([100.0 + k / 60 for k in range(6)])  # on the boundaries
    assert core.latency.samples and core.latency.samples[0] == pytest.approx(100.05 - 100.04)
    assert core.values[[c.name for c in face.vocab.channels].index("jaw")] > 0


def test_no_garbage_collection_runs_inside_a_tick_and_the_collector_is_restored(face: live.Face) -> None:
    # a full collection of what numba, numpy and the face leave takes tens of ms: during the show
    # the collector is off (and the old objects frozen out of it); garbage is collected after frames
    import gc

    clk = FakeClock()
    spec = live.build_mapping(face.vocab, None, ["mock://"])
    core = live.LiveCore(face, Mapper(spec, face.vocab))
    seen: list[tuple[bool, int]] = []
    collections: list[int] = []
    def record(phase: str, info: dict) -> None:
        if phase == "start" and seen:  # from the first tick on (setup may collect, as any code does)
            collections.append(info["generation"])

    gc.callbacks.append(record)
    try:
        def drain() -> list:
            seen.append((gc.isenabled(), gc.get_freeze_count()))
            return []

        live.run_realtime(core, drain, live.GC_FRAMES * 2 / 60.0 + 0.05, clock=clk, sleep=clk.sleep)
    finally:
        gc.callbacks.pop()
    assert seen and all(not enabled and frozen > 10_000 for enabled, frozen in seen)
    assert gc.isenabled() and gc.get_freeze_count() == 0
    # inside the loop only its own collections: the young generations every GC_FRAMES frames
    assert collections.count(1) >= 2 and set(collections) == {1}
