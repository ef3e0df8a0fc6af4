"""The live loop's critical path: recording kept during the tick and written after the frame (same
file, same crash safety); the spans that time a tick."""

from __future__ import annotations

from pathlib import Path

import pytest

from devices.events import ControlEvent, StatusEvent
from puppet import live
from puppet.mapping import Mapper
from puppet.replay import state_digest
from puppet.session import SessionWriter, read_session

SGI = "sgi:///dev/ttyTEST"


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture(scope="module")
def face() -> live.Face:
    return live.load_face()


def _events(k: int) -> list:
    if k == 3:
        return [StatusEvent(SGI, "connected", 0.01)]
    if k % 7 == 1:
        return [ControlEvent(SGI, f"dial{1 + k % 8}", "dial", 0.01 * (1 + k % 5), None, 3, k / 60.0),
                ControlEvent(SGI, "button3", "button", float(k % 2), None, 1, k / 60.0 + 1e-4)]
    return []


def _core(face: live.Face, writer: SessionWriter | None = None) -> live.LiveCore:
    spec = live.build_mapping(face.vocab, None, [SGI])
    return live.LiveCore(face, Mapper(spec, face.vocab), writer=writer)


def test_deferred_recording_is_the_same_file(face: live.Face, tmp_path: Path) -> None:
    """The live core keeps the records and writes them after the frame; a writer used directly
    writes them at once: the files are identical, line for line."""
    spec = live.build_mapping(face.vocab, None, [SGI])
    head = live.session_header(face, spec, 60.0, [SGI])
    a, b = tmp_path / "deferred.jsonl", tmp_path / "direct.jsonl"
    clock = FakeClock()
    wa = SessionWriter(a, head, clock=clock)
    core = _core(face, wa)
    assert wa.defer
    for k in range(130):
        core.tick(_events(k))
        core.after_frame()
        clock.t += 1 / 60
    core.mark("end of take")
    wa.close(core.tick_count)

    # the same calls, made by hand on a writer that is not deferred
    clock2 = FakeClock()
    wb = SessionWriter(b, head, clock=clock2)
    ref = _core(face)
    for k in range(130):
        evs = _events(k)
        for ev in evs:
            wb.event(k, ev)
        ref.tick(evs)
        wb.values(k, ref.values)
        if ref.tick_count % live.CHECK_TICKS == 0:
            wb.check(ref.tick_count, state_digest(ref.state))
        wb.tick(ref.tick_count)
        clock2.t += 1 / 60
    wb.marker(ref.tick_count, "end of take")
    wb.close(ref.tick_count)
    assert a.read_text().splitlines()[1:] == b.read_text().splitlines()[1:]
    s = read_session(a)
    assert s.complete and s.ticks == 130 and sorted(s.checks) == [60, 120] and not s.warnings


def test_deferred_records_reach_the_disk_within_100_ms(face: live.Face, tmp_path: Path) -> None:
    """Kept records are on disk (with a sync) once a frame is published after 100 ms: a process
    killed then leaves a readable file with those ticks."""
    spec = live.build_mapping(face.vocab, None, [SGI])
    p = tmp_path / "s.jsonl"
    clock = FakeClock()
    w = SessionWriter(p, live.session_header(face, spec, 60.0, [SGI]), clock=clock)
    core = _core(face, w)
    for k in range(8):
        core.tick(_events(k))
        core.after_frame()
        clock.t += 1 / 60
    # 8 frames = 133 ms: flushed at least once, without close
    s = read_session(p)
    assert not s.complete and s.ticks >= 6
    assert any(e.get("t") == "ev" and e["tick"] == 1 for e in s.events)
    w.close(core.tick_count)


def test_spans_time_the_parts_of_a_tick(face: live.Face) -> None:
    core = _core(face)
    core.spans = live.Spans()
    for k in range(5):
        core.tick(_events(k))
    assert set(core.spans.data) == {"events", "mapping", "sim step", "tick tail"}
    assert all(len(v) == 5 for v in core.spans.data.values())
