"""Huge and endless inputs named as the files a command reads: a 3 GB file of one line (sparse),
/dev/zero or /dev/urandom behind a pipe, a pipe that never stops. Each command reads a bounded
amount, then says in one line what the file is (exit 2): `puppet replay /dev/zero` read 2 GB before
refusing, and `puppet fit big.csv` read a 3 GB file whole (a MemoryError traceback)."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import threading
from pathlib import Path

import pytest

import formats

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "puppet" / "data"
HUGE = 3 << 30  # bytes of every sparse file (no disk is used)
#: bytes a reader may take from an endless pipe before refusing it: its line bounds (4 MB) and the
#: pipe's buffer; the old readers took 2 GB (a recording) or 16-64 MB (a map, curves)
PIPE_BOUND = 24 << 20


def _sparse(path: Path, head: bytes = b"") -> Path:
    path.write_bytes(head)
    os.truncate(path, HUGE)
    return path


def _capped(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """`puppet ARGV` in a child whose address space is capped at 2.5 GB: reading any of the 3 GB
    files whole fails there."""

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (5 << 29, 5 << 29))

    env = {**os.environ, "PUPPET_FACE": "procedural", "JACK_NO_START_SERVER": "1"}
    return subprocess.run([sys.executable, "-m", "puppet", *argv], capture_output=True, text=True, timeout=300,
                          preexec_fn=cap, env=env, cwd=cwd)


def _huge_files(d: Path) -> dict[str, tuple[list[str], str]]:
    """name -> (argv, the file the error line must name), each reading a 3 GB sparse file."""
    header = (DATA / "take_jaw_whole.jsonl").read_bytes().split(b"\n")[0] + b"\n"
    _sparse(d / "one-line.jsonl")
    _sparse(d / "header-then-one-line.jsonl", header + b'{"t":"v","tick":0,"v":{"jaw":0.')
    for suffix in ("csv", "pc2", "wav", "obj", "curves", "toml", "npz", "json"):
        _sparse(d / f"big.{suffix}")
    _sparse(d / "arkit.csv", b"Timecode,BlendShapeCount,EyeBlinkLeft\n")
    lm = d / "lm.json"
    lm.write_bytes(formats.good_landmarks(d))
    take = d / "take.jsonl"
    take.write_bytes((DATA / "take_jaw_whole.jsonl").read_bytes())
    return {
        "replay one line": (["replay", "one-line.jsonl", "--out", "x.csv"], "one-line.jsonl"),
        "replay header then one line": (["replay", "header-then-one-line.jsonl", "--out", "x.csv"],
                                        "header-then-one-line.jsonl"),
        "takes import": (["takes", "--library", "lib.db", "import", "one-line.jsonl"], "one-line.jsonl"),
        "fit landmark csv": (["fit", "big.csv", "--out", "f.jsonl"], "big.csv"),
        "fit arkit csv": (["fit", "arkit.csv", "--out", "f.jsonl"], "arkit.csv"),
        "fit pc2": (["fit", "big.pc2", "--out", "f.jsonl"], "big.pc2"),
        "fit wav": (["fit", "big.wav", "--out", "f.jsonl"], "big.wav"),
        "recognize csv": (["recognize", "big.csv"], "big.csv"),
        "import-face": (["import-face", "big.obj", "--landmarks", "lm.json", "--out", "r.npz", "--no-image"],
                        "big.obj"),
        "import-face landmarks": (["import-face", str(ROOT / "tests" / "files" / "formats.py"), "--landmarks",
                                   "big.json", "--out", "r.npz", "--no-image"], "big.json"),
        "replay --curves": (["replay", "take.jsonl", "--curves", "big.curves", "--out", "y.csv"], "big.curves"),
        "live --map": (["live", "--map", "big.toml", "--headless", "--no-panel", "--duration", "0.05", "--device",
                        "mock://?sine=dial0"], "big.toml"),
        "pose --rig": (["pose", "--rig", "big.npz", "--seconds", "0", "--out", "p.npz"], "big.npz"),
        "fit --map": (["fit", "take.jsonl", "--map", "big.json", "--out", "f.jsonl"], "big.json"),
    }


HUGE_CASES = ["replay one line", "replay header then one line", "takes import", "fit landmark csv", "fit arkit csv",
              "fit pc2", "fit wav", "recognize csv", "import-face", "replay --curves", "live --map", "pose --rig"]


@pytest.mark.parametrize("case", HUGE_CASES)
def test_a_3_gb_file_is_one_line_without_being_read_whole(tmp_path: Path, case: str) -> None:
    argv, name = _huge_files(tmp_path)[case]
    r = _capped(argv, tmp_path)
    assert "Traceback" not in r.stderr and "MemoryError" not in r.stderr, r.stderr[-1500:]
    if case == "takes import":  # a folder's import skips what is not a recording, in one line
        assert r.returncode == 0 and "skipped" in r.stderr and name in r.stderr, r.stderr
        assert "runs on past" in r.stderr
        return
    if case == "replay header then one line":  # the header is a take's: it replays up to the damage
        assert "longer than 4 MB at line 2" in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert r.returncode == 2 and len(lines) == 1 and name in lines[0], r.stderr[-1500:]
    assert len(lines[0]) < formats.MAX_LINE


def _feed_endless(wr: int, chunk: bytes, head: bytes, fed: list[int]) -> None:
    """Writes `head` then `chunk` forever into the pipe `wr` until its reader is gone; counts."""
    try:
        os.write(wr, head)
        fed[0] += len(head)
        while True:
            fed[0] += os.write(wr, chunk)
    except OSError:  # EPIPE: the reader closed
        pass
    finally:
        os.close(wr)


def _endless_pipe(argv_for: object, tmp_path: Path, chunk: bytes, head: bytes = b"") -> tuple[subprocess.CompletedProcess[str], int]:
    rd, wr = os.pipe()
    fed = [0]
    feeder = threading.Thread(target=_feed_endless, args=(wr, chunk, head, fed), daemon=True)
    feeder.start()
    try:
        argv = argv_for(f"/dev/fd/{rd}")  # type: ignore[operator]
        env = {**os.environ, "PUPPET_FACE": "procedural"}
        r = subprocess.run([sys.executable, "-m", "puppet", *argv], capture_output=True, text=True, timeout=300,
                           pass_fds=(rd,), env=env, cwd=tmp_path)
    finally:
        os.close(rd)  # the feeder's next write fails: it stops
        feeder.join(timeout=30)
    return r, fed[0]


@pytest.mark.parametrize("source", ["zeros", "random bytes", "a take's header, then zeros"])
def test_replay_of_an_endless_pipe_reads_a_few_megabytes_then_refuses_it(tmp_path: Path, source: str) -> None:
    """`puppet replay <(cat /dev/zero)`: the reader took 2 GB from the pipe before refusing."""
    header = (DATA / "take_jaw_whole.jsonl").read_bytes().split(b"\n")[0] + b"\n"
    chunk = os.urandom(1 << 16) if source == "random bytes" else bytes(1 << 16)
    head = header if "header" in source else b""
    r, fed = _endless_pipe(lambda f: ["replay", f, "--out", "x.csv"], tmp_path, chunk, head)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert r.returncode == 2 and len(lines) == 1 and "/dev/fd/" in lines[0], r.stderr[-1500:]
    assert fed < PIPE_BOUND, f"the reader took {fed >> 20} MB from the pipe"
    assert not (tmp_path / "x.csv").exists()


def test_an_endless_stream_of_good_records_stops_at_the_take_bound(tmp_path: Path) -> None:
    """A pipe fed the same tick forever (a script gone wrong): the reader stops at what one replay
    holds (MAX_CELLS) with one line, instead of reading until the memory is gone."""
    from puppet.session_reader import MAX_CELLS

    lines = (DATA / "take_jaw_whole.jsonl").read_bytes().split(b"\n")
    header = lines[0] + b"\n"
    import json

    n = len(json.loads(lines[0])["channels"])
    big_tick = MAX_CELLS // n + 5  # past the bound at once: no need to write the ticks in between
    rec = b'{"t":"v","tick":%d,"v":{}}\n' % big_tick
    r, fed = _endless_pipe(lambda f: ["replay", f, "--out", "x.csv"], tmp_path, rec * 1000, header)
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert r.returncode == 2 and len(err) == 1 and "more than one replay holds" in err[0], r.stderr[-1500:]
    assert fed < PIPE_BOUND


def test_a_take_cut_at_every_byte_of_its_records_keeps_its_complete_ticks(tmp_path: Path) -> None:
    """A show killed at any moment: the recording cut at every record boundary and inside every
    record reads as the ticks whose records were whole before the cut, with one warning; a cut
    inside the header is one error line naming file:1. Never a traceback."""
    import json

    from puppet.errors import ConfigError
    from puppet.session import read_session

    data = (DATA / "take_jaw_whole.jsonl").read_bytes()
    lines = data.split(b"\n")
    ends, at = [], 0
    for ln in lines:
        at += len(ln) + 1
        ends.append(at)
    header_end = ends[0]
    whole = read_session(DATA / "take_jaw_whole.jsonl")
    cuts = sorted(set(ends[:-1]) | set(range(0, len(data), max(1, len(data) // 400))) | {len(data) - 1})
    f = tmp_path / "cut.jsonl"
    for cut in cuts:
        f.write_bytes(data[:cut])
        if cut < header_end:
            with pytest.raises(ConfigError, match=r"cut\.jsonl:1: "):
                read_session(f)
            continue
        s = read_session(f)
        complete = [json.loads(ln) for ln, end in zip(lines[1:], ends[1:]) if end - 1 <= cut and ln.strip()]
        vticks = [r["tick"] for r in complete if r["t"] == "v"]
        if any(r["t"] == "end" for r in complete):
            assert s.complete and s.ticks == whole.ticks
            continue
        assert not s.complete and len(s.warnings) == 1, (cut, s.warnings)
        want = max([max(vticks) + 1 if vticks else 0] + [r["tick"] for r in complete if r["t"] == "sync"])
        assert s.ticks == want, (cut, s.ticks, want)
        for k in range(s.ticks):  # what was kept is what was recorded
            assert s.values.get(k) == whole.values.get(k), cut
