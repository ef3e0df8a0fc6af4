"""Session files: exact floats, changes only, markers, and crash-cut files reading back."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from devices.events import ControlEvent, StatusEvent
from puppet.errors import ConfigError
from puppet.session import SessionWriter, read_session

NAMES = ["a", "b", "c"]


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def header() -> dict:
    return {"channels": NAMES, "tick_rate": 60.0, "rig": {"name": "test", "hash": "x"}, "mapping": ""}


def test_round_trip_is_bit_exact_and_sparse(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    rows = [np.array([0.1, 0.2, 30.0])]
    for _ in range(20):
        r = rows[-1].copy()
        r[rng.integers(0, 3)] = rng.random() / 3.0  # awkward doubles
        rows.append(r)
    p = tmp_path / "s.jsonl"
    with SessionWriter(p, header()) as w:
        w.event(0, ControlEvent("mock://", "dial0", "dial", 0.005, 1.0, 1, 12.5), t0=10.0)
        w.event(1, StatusEvent("mock://", "lost", 12.6))
        for k, r in enumerate(rows):
            w.values(k, r)
            w.tick(k + 1)
        w.marker(5, "here")
        w.close(len(rows))
    s = read_session(p)
    assert s.complete and not s.warnings and s.ticks == len(rows)
    back = s.value_array(np.zeros(3))
    assert np.array_equal(back, np.array(rows))  # bit for bit
    assert s.markers == [(5, "here")] and s.events[0]["time"] == 2.5 and s.events[1]["status"] == "lost"
    # changes only: no line lists a value equal to the previous tick's
    lines = [json.loads(x) for x in p.read_text().splitlines() if '"t":"v"' in x]
    assert all(len(rec["v"]) <= 1 for rec in lines[1:])


def test_every_tick_reaches_the_os_without_close(tmp_path: Path) -> None:
    """A process killed after tick k leaves ticks 0..k in the file: each tick is written at once
    (with a sync record when no value changed), no clock, no close."""
    p = tmp_path / "s.jsonl"
    w = SessionWriter(p, header(), fsync_seconds=None)
    rows = [[1.0, 2.0, 3.0], [1.0, 2.5, 3.0], [1.0, 2.5, 3.0], [1.0, 2.5, 3.0], [0.5, 2.5, 3.0]]
    for k, row in enumerate(rows):
        w.values(k, np.array(row))
        w.tick(k + 1)
        s = read_session(p)                  # readable while still open, up to this tick
        assert s.ticks == k + 1 and not s.complete and s.warnings
        assert np.array_equal(s.value_array(np.zeros(3))[-1], row)
    text = p.read_text()
    assert text.count('"t":"sync"') == 2     # the two ticks that changed nothing
    w.close()


def test_fsync_thread_makes_the_file_durable_while_recording(tmp_path: Path) -> None:
    """The writer's thread fsyncs the open file and logs what each fsync covered: the bytes then
    on disk read back as at least the logged ticks."""
    p = tmp_path / "s.jsonl"
    w = SessionWriter(p, header(), fsync_seconds=0.01)
    assert w.syncer is not None
    for k in range(40):
        w.values(k, np.array([k, 0.0, 0.0], dtype=float))
        w.tick(k + 1)
        w.syncer.sync_now()
    log = list(w.syncer.log)
    w.close()
    assert len(log) >= 40
    data = p.read_bytes()
    for _, size, ticks in log:
        cut = tmp_path / "cut.jsonl"
        cut.write_bytes(data[:size])
        assert read_session(cut).ticks >= ticks
    assert max(t for _, _, t in log) == 40


def test_cut_file_reads_to_last_complete_record(tmp_path: Path) -> None:
    p = tmp_path / "s.jsonl"
    with SessionWriter(p, header()) as w:
        for k in range(10):
            w.values(k, np.array([k, 0.0, 0.0], dtype=float))
            w.tick(k + 1)
    text = p.read_text()
    cut = text[: text.index('"tick":7') + 5]  # mid-record, like a SIGKILL during write
    p.write_text(cut)
    s = read_session(p)
    assert not s.complete and s.ticks == 7 and "cut off" in s.warnings[0]
    assert s.value_array(np.zeros(3))[-1][0] == 6.0


@pytest.mark.parametrize("content", ["", "not json\n", '{"format": "other"}\n', "\x00\xff"])
def test_not_a_recording_is_one_line_error(tmp_path: Path, content: str) -> None:
    p = tmp_path / "bad.jsonl"
    p.write_text(content)
    with pytest.raises(ConfigError, match="bad.jsonl:1: not a facepuppet recording"):
        read_session(p)


def test_values_placed_by_name_on_another_channel_order(tmp_path: Path) -> None:
    p = tmp_path / "s.jsonl"
    with SessionWriter(p, header()) as w:
        w.values(0, np.array([1.0, 2.0, 3.0]))
        w.tick(1)
    s = read_session(p)
    assert s.value_array(np.zeros(4), ["c", "x", "a", "b"])[0].tolist() == [3.0, 0.0, 1.0, 2.0]


@pytest.mark.parametrize("bad", ['{"t":"v","tick":3,"v":{"a":"x"}}', '{"t":"v","tick":"3"x}', '[1,2]',
                                 '{"t":"v","tick":3,"v":[1]}', '{"t":"v","tick":3,"v":{"a":1e999}}'])
def test_damaged_record_stops_reading_with_a_warning(tmp_path: Path, bad: str) -> None:
    p = tmp_path / "s.jsonl"
    with SessionWriter(p, header()) as w:
        for k in range(3):
            w.values(k, np.array([k, 0.0, 0.0], dtype=float))
            w.tick(k + 1)
    lines = p.read_text().splitlines()
    lines.insert(-1, bad)
    p.write_text("\n".join(lines) + "\n")
    s = read_session(p)
    assert s.ticks == 3 and s.warnings and "damaged record" in s.warnings[0]


def test_disk_full_stops_recording_but_not_the_show(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = tmp_path / "s.jsonl"
    w = SessionWriter(p, header())
    w.values(0, np.array([1.0, 2.0, 3.0]))
    w.tick(1)
    w.flush()

    class Full:
        def write(self, s: str) -> int:
            raise OSError(28, "No space left on device")

        def flush(self) -> None:
            pass

        def close(self) -> None:
            pass

    w._file.close()  # type: ignore[union-attr]
    w._file = Full()  # type: ignore[assignment]
    w.values(1, np.array([1.5, 2.0, 3.0]))  # must not raise
    w.tick(2)
    w.close(2)
    assert w.error is not None and "No space left" in capsys.readouterr().err
    assert read_session(p).ticks == 1


class _Watched:
    """A file that notes which thread writes to it and hands each write on."""

    def __init__(self, f) -> None:  # type: ignore[no-untyped-def]
        self.f, self.writers = f, set()

    def write(self, text: str) -> int:
        import threading

        self.writers.add(threading.get_ident())
        return self.f.write(text)

    def flush(self) -> None:
        import threading

        self.writers.add(threading.get_ident())
        self.f.flush()

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self.f, name)


def _deferred_take(path: Path, behind: bool) -> set:
    w = SessionWriter(path, header(), fsync_seconds=None)
    w.defer = True
    w._file = watched = _Watched(w._file)  # type: ignore[assignment]
    if behind:
        w.write_behind()
    rows = [[1.0, 2.0, 3.0], [1.0, 2.5, 3.0], [1.0, 2.5, 3.0], [0.5, 2.5, 3.0]] * 10
    for k, row in enumerate(rows):
        w.event(k, ControlEvent("mock://", "dial0", "dial", 0.005, 1.0, 1, 12.5 + k))
        w.values(k, np.array(row))
        if k % 7 == 3:
            w.marker(k, f"m{k}")
            w.check(k + 1, lambda k=k: f"digest{k}")
        w.tick(k + 1)
        w.service()
        if k == 20:
            w.flush()  # waits for the writer's thread: the file then holds 21 ticks
            assert read_session(path).ticks == 21
    during = set(watched.writers)  # who wrote while the take ran (close writes the end record itself)
    w.close(len(rows))
    return during


def test_a_writer_writing_behind_makes_the_same_file_from_its_own_thread(tmp_path: Path) -> None:
    """The live loop hands its records to the writer's thread (`write_behind`), so it does not wait
    on the file system (an append waits for the journal an fsync holds): the file is the same, byte
    for byte, and the loop's thread made no write of its own."""
    import threading

    mine = _deferred_take(tmp_path / "a.jsonl", behind=False)
    others = _deferred_take(tmp_path / "b.jsonl", behind=True)
    strip = [x for x in (tmp_path / "a.jsonl").read_text().splitlines() if '"t":"header"' not in x]
    assert strip == [x for x in (tmp_path / "b.jsonl").read_text().splitlines() if '"t":"header"' not in x]
    assert mine == {threading.get_ident()}
    assert others and threading.get_ident() not in others  # only the writer's thread wrote
    assert read_session(tmp_path / "b.jsonl").complete


def test_a_writer_writing_behind_holds_at_most_one_tick_unwritten(tmp_path: Path) -> None:
    """A file that holds the writer's thread back (a disk busy with an fsync) makes the loop wait at
    its next hand-over instead of piling ticks up in memory: a crash then loses at most a tick."""
    import time

    w = SessionWriter(tmp_path / "t.jsonl", header(), fsync_seconds=None)
    w.defer = True
    slow = _Watched(w._file)
    w._file = slow  # type: ignore[assignment]
    write = slow.write
    slow.write = lambda text: (time.sleep(0.02), write(text))[1]  # type: ignore[method-assign]
    w.write_behind()
    unwritten = []
    for k in range(8):
        w.values(k, np.array([1.0, 2.0, float(k)]))
        w.tick(k + 1)
        w.service()
        unwritten.append(w._handed - w._written)
    w.close(8)
    assert max(unwritten) <= 1, unwritten
    assert read_session(tmp_path / "t.jsonl").ticks == 8


def test_the_records_put_together_are_the_json_encoders_text(tmp_path: Path) -> None:
    """Events and values written from their fields' kept text (the live loop writes a record per
    event and per tick) are the very lines `json` writes for the same records, for odd names,
    raw values of every kind, signed zeros and awkward doubles; what json refuses it still refuses."""
    from puppet.session import _json

    names = ['a"b', "é\\n", "ch\n2", "-0"]
    events = [ControlEvent("mock://x?y=\"1\"", "dial0", "dial", 0.005, 1.0, 1, 12.5),
              ControlEvent("mock://x?y=\"1\"", "dial0", "dial", -0.0, -3, 1e-300, 12.5 + 1e-9),
              ControlEvent("mock://x?y=\"1\"", "dial0", "dial", 1 / 3, None, "raw \"é\"\n", 13.0),
              ControlEvent("sgi://tty", "button3", "button", 1.0, None, None, 14.0),
              ControlEvent("sgi://tty", "button3", "button", 0.0, None, True, 14.0),
              ControlEvent("sgi://tty", "button3", "button", 0.0, None, b"\x01", 14.5),
              ControlEvent("sgi://tty", "key:ü", "key", 1.0, 2.5, 7, 1e20)]
    rows = [np.array([0.1, -0.0, 1e-310, 2.0 / 3.0]), np.array([0.1, 5e-324, 1e-310, 1e300])]
    p = tmp_path / "s.jsonl"
    want = []
    with SessionWriter(p, {**header(), "channels": names}, fsync_seconds=None) as w:
        for k, ev in enumerate(events + events):
            w.event(k, ev, t0=10.0)
            raw = ev.raw if isinstance(ev.raw, (int, float, str)) or ev.raw is None else repr(ev.raw)
            want.append(_json({"t": "ev", "tick": k, "dev": ev.device, "ctl": ev.control, "kind": ev.kind,
                               "value": float(ev.value), "delta": ev.delta, "raw": raw, "time": ev.t - 10.0}))
        for k, r in enumerate(rows):
            w.values(k, r)
            w.tick(k + 1)
        w.close(len(rows))
    want.append(_json({"t": "v", "tick": 0, "v": dict(zip(names, map(float, rows[0])))}))
    want.append(_json({"t": "v", "tick": 1, "v": {names[1]: 5e-324, names[3]: 1e300}}))
    lines = p.read_text().splitlines()
    assert lines[1:1 + len(want)] == want
    with SessionWriter(tmp_path / "nan.jsonl", header(), fsync_seconds=None) as w, pytest.raises(ValueError):
        w.event(0, ControlEvent("mock://", "dial0", "dial", float("nan"), 1.0, 1, 12.5))
