"""Scheduling of the live loop: a tick that takes events is drawn at once (its frame does not wait
for the display's schedule) without frames ever coming closer than half a frame period, and the
tick rate a show on the wall clock uses is chosen from the face's measured step cost."""

from __future__ import annotations

import pytest

from devices.events import ControlEvent
from puppet import live
from puppet.mapping import Mapper
from puppet.tick_rate import choose_tick_rate
from fakeclock import FakeClock


@pytest.fixture(scope="module")
def face() -> live.Face:
    return live.load_face()


def test_a_tick_that_takes_an_event_is_drawn_at_once(face: live.Face) -> None:
    clk = FakeClock()
    spec = live.build_mapping(face.vocab, None, ["mock://"])
    core = live.LiveCore(face, Mapper(spec, face.vocab), rate=240.0)
    ev = ControlEvent("mock://", "dial7", "dial", 0.25, 50.0, 50, 100.0)
    # tick 0 is drawn by the schedule; events in ticks 1 (too soon after it), 6 and 13 (half a frame
    # and more after the last frame) and 14 (right after 13's frame)
    arrivals = {1: [ev], 6: [ev], 13: [ev], 14: [ev]}
    ticks: list[int] = []
    drawn: list[int] = []

    def drain() -> list:
        ticks.append(len(ticks))
        return arrivals.get(ticks[-1], [])

    live.run_realtime(core, drain, 30 / 240, clock=clk, sleep=clk.sleep, frame_rate=60.0,
                      on_frame=lambda c: drawn.append(c.tick_count - 1))
    assert core.tick_count == 30
    assert 6 in drawn and 13 in drawn  # drawn right after the tick that took the event
    assert 1 not in drawn and 14 not in drawn  # too soon after the last frame: on the schedule
    assert all(b - a >= 2 for a, b in zip(drawn, drawn[1:]))  # never closer than half a frame (4 ticks)
    assert all(b - a <= 4 for a, b in zip(drawn, drawn[1:]))  # and never further apart than a frame
    assert len(drawn) >= 30 // 4  # at least the display's rate


def test_a_loop_that_falls_behind_drops_wall_time_and_says_where_its_clock_went(face: live.Face) -> None:
    """The schedule's origin (where a take's sound is placed) moves on by exactly the wall time
    dropped when a tick comes more than 4 ticks late, and not when a tick is a little late."""
    clk = FakeClock()
    core = live.LiveCore(face, Mapper(live.build_mapping(face.vocab, None, ["mock://"]), face.vocab), rate=240.0)
    origins: list[float | None] = []

    def drain() -> list:
        origins.append(core.clock_origin)
        if len(origins) == 5:
            clk.t += 3 / 240  # late, not behind: the schedule holds
        if len(origins) == 10:
            clk.t += 0.25  # a stall: the next tick is 0.25 s late
        return []

    live.run_realtime(core, drain, 20 / 240, clock=clk, sleep=clk.sleep)
    assert core.tick_count == 20
    assert origins[0] == 100.0 and len(set(origins[:10])) == 1
    # tick 10, due 1/240 s after tick 9 began, came 0.25 s after it: the clock moved by its lateness
    assert abs(origins[10] - origins[9] - (0.25 - 1 / 240)) < 1e-9
    assert len(set(origins[10:])) == 1


def test_the_tick_rate_follows_the_faces_step_cost(face: live.Face) -> None:
    rate, cost = choose_tick_rate(face.model, budget=1e-9)  # nothing fits: the lowest rate
    assert rate == min(live.TICK_RATES) and set(cost) == set(live.TICK_RATES)
    assert all(c > 0 for c in cost.values())
    rate, cost = choose_tick_rate(face.model, budget=10.0)  # anything fits: the highest, tried alone
    assert rate == max(live.TICK_RATES) and list(cost) == [max(live.TICK_RATES)]


def test_input_arriving_just_before_a_boundary_starts_its_tick_at_once(face: live.Face) -> None:
    """The loop spins the last moment before a tick boundary (live.SPIN_S); an event arriving then
    is taken at once, not at the boundary, and no tick ever starts more than a tick early."""
    clk = FakeClock()
    core = live.LiveCore(face, Mapper(live.build_mapping(face.vocab, None, ["mock://"]), face.vocab), rate=120.0)
    dt = core.dt
    arrival = clk.t + 5 * dt - live.SPIN_S / 2  # inside the spin before tick 5's boundary
    pending = [arrival]
    drains: list[tuple[float, int, bool]] = []  # (clock, tick, took the event)

    def sleep(s: float) -> None:  # time moves in 0.1 ms steps, as a spin would see it
        clk.t += min(max(s, 0.0), 1e-4)

    def wake(timeout: float) -> bool:  # EventQueue.wait_arrival on the fake clock
        if pending and pending[0] <= clk.t + max(timeout, 0.0):
            clk.t = max(clk.t, pending[0])
            return True
        clk.t += max(timeout, 0.0)
        return False

    def drain() -> list:
        took = bool(pending) and pending[0] <= clk.t
        drains.append((clk.t, core.tick_count, took))
        if took:
            pending.pop()
            return [ControlEvent("mock://", "dial7", "dial", 0.25, 50.0, 50, arrival)]
        return []

    start = clk.t
    live.run_realtime(core, drain, 8 * dt, clock=clk, sleep=sleep, wake=wake)
    [(t, k, _)] = [d for d in drains if d[2]]
    assert k == 5
    assert t - arrival < 2e-4  # taken as it arrived, not SPIN_S / 2 later at the boundary
    assert all(t >= start + (k - 1) * dt - 1e-9 for t, k, _ in drains)  # never more than a tick early
    assert core.state_latency.percentile(100) is not None
