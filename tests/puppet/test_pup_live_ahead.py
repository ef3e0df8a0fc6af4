"""The live loop solves the next step's all-but-the-inputs between ticks (`Simulator.prepare`) on
the implicit integrator; replay never does. A take recorded that way replays bit for bit."""

from __future__ import annotations

from pathlib import Path

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
