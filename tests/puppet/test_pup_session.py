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


def test_flushes_every_100ms_without_close(tmp_path: Path) -> None:
    clock = FakeClock()
    p = tmp_path / "s.jsonl"
    w = SessionWriter(p, header(), clock=clock)
    w.values(0, np.array([1.0, 2.0, 3.0]))
    w.tick(1)
    assert '"t":"v"' not in p.read_text()   # buffered
    clock.t = 0.1
    w.values(1, np.array([1.0, 2.5, 3.0]))
    w.tick(2)
    s = read_session(p)                      # readable while still open
    assert s.ticks == 2 and not s.complete and s.warnings
    w.close()


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
