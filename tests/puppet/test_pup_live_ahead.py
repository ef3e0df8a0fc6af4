"""The live loop solves the next step's all-but-the-inputs between ticks (`Simulator.prepare`) on
the implicit integrator; replay never does. A take recorded that way replays bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from devices.events import ControlEvent
from fakeclock import FakeClock
from puppet import live
from puppet.mapping import Mapper
from puppet.replay import Replayer, build_performance
from puppet.session import SessionWriter, read_session


def test_a_take_recorded_with_steps_prepared_ahead_replays_bit_for_bit(tmp_path: Path) -> None:
    face = live.load_face(resolution=1)  # the procedural face fine enough for the implicit integrator
    rate = 120.0
    spec = live.build_mapping(face.vocab, None, ["mock://"])
    mapper = Mapper(spec, face.vocab)
    rec = tmp_path / "take.jsonl"
    writer = SessionWriter(rec, live.session_header(face, spec, rate, ["mock://"]))
    core = live.LiveCore(face, mapper, writer=writer, rate=rate)
    assert core.sim.method == "implicit"
    clk = FakeClock()
    prepared = []
    prepare = core.sim.prepare

    def counted(state: object) -> None:
        prepared.append(core.tick_count)
        prepare(state)  # type: ignore[arg-type]

    core.sim.prepare = counted  # type: ignore[method-assign]
    positions: list[bytes] = []
    ticks = 0

    def drain() -> list[ControlEvent]:
        nonlocal ticks
        k, ticks = ticks, ticks + 1
        out = []
        if 2 <= k < 24:  # a smile turned up over 22 ticks, then the jaw opened a little at two ticks
            out.append(ControlEvent("mock://", "dial1", "dial", k / 24, 0.0, 0, clk.t))
        if k in (10, 11):
            out.append(ControlEvent("mock://", "dial7", "dial", 0.2 * (k - 9), 0.0, 0, clk.t))
        return out

    live.run_realtime(core, drain, 0.25, clock=clk, sleep=clk.sleep,
                      on_frame=lambda c: positions.append(c.state.positions.tobytes()))
    writer.close(core.tick_count)
    assert core.tick_count == 30 and len(prepared) >= 25
    assert positions[-1] != face.model.rest.tobytes()
    rp = Replayer(build_performance(read_session(rec), None))
    for k in range(30):
        rp.step()
        assert rp.state.positions.tobytes() == positions[k], f"tick {k} differs"


def _steps_with_input_waiting(ahead_when_idle: bool) -> list[bool]:
    """A show whose every tick finds an input already waiting (a dense stream): for each tick that
    took one, whether its step found the input-free solve made ahead."""
    face = live.load_face(resolution=1)
    spec = live.build_mapping(face.vocab, None, ["mock://"])
    core = live.LiveCore(face, Mapper(spec, face.vocab), rate=120.0)
    clk = FakeClock()
    used: list[bool] = []
    step = core.sim.step

    def stepped(state: object, control: object, **kw: object) -> object:
        out = step(state, control, **kw)  # type: ignore[arg-type]
        used.append(core.sim._implicit.last_predicted)  # type: ignore[union-attr]
        return out

    core.sim.step = stepped  # type: ignore[method-assign]
    k = 0

    def drain() -> list[ControlEvent]:
        nonlocal k
        k += 1
        return [ControlEvent("mock://", "dial1", "dial", 0.02 * (k % 5 + 1), 0.0, 0, clk.t)]

    def wake(timeout: float) -> bool:
        return True  # something is always waiting

    live.run_realtime(core, drain, 0.1, clock=clk, sleep=clk.sleep, wake=wake, ahead_when_idle=ahead_when_idle)
    return used


def test_a_tick_that_finds_input_waiting_still_starts_from_the_solve_made_ahead() -> None:
    # the loop makes the next step's input-free solve before it drains, whatever is queued, so an
    # input arriving during that solve joins the tick and the tick only adds what the input changes
    used = _steps_with_input_waiting(ahead_when_idle=False)
    assert len(used) == 12 and all(used)
    # as before: the loop skipped the solve when input waited and each such tick did the whole step
    assert not any(_steps_with_input_waiting(ahead_when_idle=True))


def test_a_headless_show_makes_the_wrinkle_surface_for_the_ticks_it_draws() -> None:
    # 120 Hz ticks, 60 Hz frames: the surface (drawn only) is made once a frame, for the tick drawn,
    # so every frame shows its own tick's skin and the ticks between frames do not pay for it
    face = live.load_face(face="procedural")
    spec = live.build_mapping(face.vocab, None, ["mock://"])
    core = live.LiveCore(face, Mapper(spec, face.vocab), rate=120.0)
    assert core.sim.wrinkles and face.model.rig.wrinkles
    clk = FakeClock()
    made = []
    surface = core.sim.surface

    def counted(state: object) -> None:
        made.append(core.tick_count)
        surface(state)  # type: ignore[arg-type]

    core.sim.surface = counted  # type: ignore[method-assign]
    k = 0

    def drain() -> list[ControlEvent]:
        nonlocal k
        k += 1
        return [ControlEvent("mock://", "dial1", "dial", k / 30, 0.0, 0, clk.t)] if k in (3, 9, 15) else []

    stale = []

    def on_frame(c: live.LiveCore) -> None:
        expected = c.state.copy()
        surface(expected)
        stale.append(not np.array_equal(expected.surface, c.state.surface))

    live.run_realtime(core, drain, 0.25, clock=clk, sleep=clk.sleep, on_frame=on_frame, frame_rate=60.0)
    assert core.tick_count == 30 and len(stale) >= 15 and not any(stale)
    assert len(made) <= len(stale) + 1 < core.tick_count  # (the last tick's made after the loop if not drawn)
    after = core.state.copy()
    surface(after)
    assert np.array_equal(after.surface, core.state.surface)  # the loop leaves the last tick's surface made
