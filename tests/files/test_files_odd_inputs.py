"""Names given as files to read that are not files: a folder, a pipe with no writer, a pipe fed by
the shell (`--map <(make_map)`). Each is a result, or one line saying what the name is (not "no
such file" for a folder that is there), exit 2, and nothing waits forever."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import formats

ROOT = Path(__file__).resolve().parents[2]


def _commands(name: str, tmp_path: Path) -> dict[str, list[str]]:
    return {
        "fit": ["fit", name, "--out", str(tmp_path / "fit.jsonl")],
        "import-face": ["import-face", name, "--landmarks", str(tmp_path / "lm.json"), "--out",
                        str(tmp_path / "r.npz"), "--no-image"],
        "pose --rig": ["pose", "--rig", name, "--seconds", "0", "--out", str(tmp_path / "p.npz")],
        "live --map": ["live", "--map", name, "--headless", "--no-panel", "--duration", "0.05", "--device",
                       "mock://?sine=dial0"],
    }


@pytest.mark.parametrize("command", ["fit", "import-face", "pose --rig", "live --map"])
def test_a_folder_named_as_the_file_to_read_is_one_line_saying_so(tmp_path: Path, command: str) -> None:
    folder = tmp_path / "named.csv"
    folder.mkdir()
    r = formats.run_cli(_commands(str(folder), tmp_path)[command], folder)
    assert r.kind == "error", r.text
    assert "is a folder" in r.text and "no such" not in r.text


@pytest.mark.parametrize("command", ["fit", "import-face", "pose --rig"])
def test_a_pipe_named_where_a_file_is_read_twice_is_one_line_and_does_not_wait(tmp_path: Path, command: str) -> None:
    """A FIFO with no writer: opening it would wait forever; these readers need a file they can
    read twice (the format told by the first line, a zip's directory), so they say so at once."""
    fifo = tmp_path / "named.obj"
    os.mkfifo(fifo)
    r = formats.run_cli(_commands(str(fifo), tmp_path)[command], fifo)
    assert r.kind == "error", r.text
    assert "not a regular file" in r.text


def test_a_map_fed_through_a_pipe_by_the_shell_is_read(tmp_path: Path) -> None:
    """`puppet live --map <(make_map)`: the shell names a pipe /dev/fd/N; it was refused as 'no
    such map file'."""
    text = (ROOT / "puppet" / "maps" / "sgi.toml").read_bytes()
    rd, wr = os.pipe()
    try:
        os.write(wr, text)  # the whole map fits in the pipe's buffer
        os.close(wr)
        wr = -1
        r = formats.run_cli(_commands(f"/dev/fd/{rd}", tmp_path)["live --map"], Path(f"/dev/fd/{rd}"))
    finally:
        os.close(rd)
        if wr >= 0:
            os.close(wr)
    assert r.kind == "ok", r.text


def test_a_take_read_from_a_pipe_says_it_waits_then_replays_what_comes(tmp_path: Path) -> None:
    """`puppet replay fifo.jsonl` with no writer waited forever without a word. It says at once
    what it waits for (one line, Ctrl+C stops) and replays the take once one is written in."""
    import subprocess
    import sys

    data = ROOT / "tests" / "puppet" / "data"
    fifo = tmp_path / "live.jsonl"
    os.mkfifo(fifo)
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "replay", str(fifo), "--headless", "--rig",
                             str(data / "take_jaw_whole_rig.npz")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()  # before anything is written: the reader must speak first
        assert "is a pipe and nothing has been written to it yet" in line and str(fifo) in line, line
        with open(fifo, "wb") as fh:
            fh.write((data / "take_jaw_whole.jsonl").read_bytes())
        out, err = proc.communicate(timeout=300)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 0 and "bit-identical" in out, out + err


def _endless_device_run(argv: list[str]) -> "subprocess.CompletedProcess[str]":
    """`puppet ARGV` in a child whose address space is capped at 4 GB: a reader with no bound on
    an endless device fails there at once instead of taking the machine's memory."""
    import resource
    import subprocess
    import sys

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))

    env = {**os.environ, "JACK_NO_START_SERVER": "1"}
    return subprocess.run([sys.executable, "-m", "puppet", *argv], capture_output=True, text=True, timeout=300,
                          preexec_fn=cap, env=env)


@pytest.mark.parametrize("argv", [
    ["live", "--map", "/dev/zero", "--headless", "--no-panel", "--duration", "0.05", "--device", "mock://?sine=dial0"],
    ["monitor", "midi://nanoKONTROL2?profile=/dev/zero&api=jack", "--duration", "0.1"],
    ["monitor", "can://virtual/x?dbc=/dev/zero", "--duration", "0.1"],
], ids=["live --map", "midi profile=", "can dbc="])
def test_an_endless_device_named_as_a_small_file_is_one_line(argv: list[str]) -> None:
    """`--map /dev/zero` (or a profile= or dbc= naming it, or any multi-gigabyte file given by
    mistake) was read whole: 21 GB of memory before a MemoryError traceback, or exit 0 saying
    nothing. Now the read stops at the file's bound: one line naming it, exit 2."""
    r = _endless_device_run(argv)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert r.returncode == 2 and len(lines) == 1, r.stderr[-1500:]
    assert "/dev/zero" in lines[0], lines[0]
    assert "larger than" in lines[0] or "not a regular file" in lines[0], lines[0]  # not "MemoryError"
    assert "Traceback" not in r.stderr
