"""Real MIDI ports for tests: a private JACK server (Debian's jackd2, dummy driver) started and
stopped by PID, and a MIDI controller emulated in a separate process, the way a real box is
another process's port: it opens ports named like the box, plays what the test tells it, reports
every message the host sends it (the lights), and exits to unplug.

Import the ``jack_server`` fixture into a test module to use it.
"""

from __future__ import annotations

import os
import queue
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

BOX_SCRIPT = Path(__file__).with_name("midi_box.py")
#: A 1024-frame period at 48 kHz: no XRun on a loaded 2-core machine, so delivery is exact.
PERIOD = 1024


#: how long one `jack_lsp` may take: a client connecting while its server is still starting can
#: block for good; such a call is abandoned (killed) and counts as no answer
LSP_TIMEOUT_S = 5.0


def jack_lsp(server: str, *flags: str) -> subprocess.CompletedProcess[str] | None:
    """`jack_lsp -s server FLAGS` (never starting a server); None when it did not answer in time."""
    try:
        return subprocess.run(["jack_lsp", "-s", server, *flags], capture_output=True, text=True,
                              env={**os.environ, "JACK_NO_START_SERVER": "1"}, timeout=LSP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return None


def _server_up(name: str) -> bool:
    run = jack_lsp(name)
    return run is not None and run.returncode == 0


def _die_with_parent() -> None:
    """In the child: get SIGTERM when the test process dies, even if it crashes (Linux)."""
    try:
        import ctypes
        import signal

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except Exception:
        pass


def start_jackd(name: str) -> subprocess.Popen[bytes]:
    """Start a dummy JACK server called ``name`` and wait until it answers."""
    if shutil.which("jackd") is None:
        pytest.fail("jackd is not installed: run `bash .ci/setup` (Debian package jackd2)")
    proc = subprocess.Popen(["jackd", "-n", name, "--no-realtime", "-d", "dummy", "-r", "48000", "-p", str(PERIOD)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, preexec_fn=_die_with_parent)
    deadline = time.monotonic() + 15
    while not _server_up(name):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"jackd did not start (exit {proc.poll()})")
        time.sleep(0.05)
    return proc


def stop_jackd(proc: subprocess.Popen[bytes]) -> None:
    proc.terminate()
    try:
        proc.wait(5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)


_SERVERS = 0


def _forget_enumerators() -> None:
    """Close the port-listing clients discovery kept in this process, before their server stops."""
    from devices.midi import port

    with port._ENUM_LOCK:
        for _, client in port._ENUMERATORS.values():
            port.delete_client(client)
        port._ENUMERATORS.clear()


@pytest.fixture(scope="module")
def jack_server() -> Iterator[str]:
    """A private JACK server for this module; JACK_DEFAULT_SERVER names it while it runs."""
    global _SERVERS
    _SERVERS += 1
    name = f"fptest{os.getpid()}x{_SERVERS}"  # never the name of a server stopped before in this process
    proc = start_jackd(name)
    old = {k: os.environ.get(k) for k in ("JACK_DEFAULT_SERVER", "JACK_NO_START_SERVER")}
    os.environ["JACK_DEFAULT_SERVER"] = name
    os.environ["JACK_NO_START_SERVER"] = "1"
    try:
        yield name
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        _forget_enumerators()
        stop_jackd(proc)


class MidiBox:
    """An emulated controller in its own process: ``plug()`` starts it (ports appear),
    ``unplug()`` ends it (ports vanish). ``received`` holds what the host sent it."""

    def __init__(self, client: str, port: str = "_MIDI 1") -> None:
        self.client, self.port = client, port
        self.proc: subprocess.Popen[str] | None = None
        self.received: list[tuple[int, ...]] = []
        self._cond = threading.Condition()
        self._lines: queue.Queue[str] = queue.Queue()

    def plug(self) -> MidiBox:
        self.proc = subprocess.Popen([sys.executable, str(BOX_SCRIPT), self.client, self.port],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True, bufsize=1)
        threading.Thread(target=self._pump, args=(self.proc,), daemon=True).start()
        line = ready_line(self._lines, self.proc)
        assert line == "ready", line
        return self

    def _pump(self, proc: subprocess.Popen[str]) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            line = line.strip()
            if line.startswith("got "):
                msg = tuple(int(x, 16) for x in line[4:].split())
                with self._cond:
                    self.received.append(msg)
                    self._cond.notify_all()
            else:
                self._lines.put(line)

    def send(self, *msgs: tuple[int, ...] | list[int], gap: float = 0.0) -> None:
        """Messages from the box to the host, ``gap`` seconds apart."""
        assert self.proc is not None and self.proc.stdin is not None
        for m in msgs:
            self.proc.stdin.write("send " + " ".join(f"{b:02x}" for b in m) + "\n")
            self.proc.stdin.flush()
            if gap:
                time.sleep(gap)

    def wait_received(self, pred: object, timeout: float = 10.0) -> list[tuple[int, ...]]:
        with self._cond:
            ok = self._cond.wait_for(lambda: pred(self.received), timeout)  # type: ignore[operator]
            assert ok, f"the box never received what was expected; got {self.received}"
            return list(self.received)

    def unplug(self) -> None:
        stop_child(self.proc)
        self.proc = None

    close = unplug


def ready_line(lines: queue.Queue[str], proc: subprocess.Popen, timeout: float = 120.0) -> str:  # type: ignore[type-arg]
    """The first line a port-playing child says ("ready" once its JACK port is up). Its start (an
    interpreter, numpy, a JACK client) took over 30 s at a load of 25 on 2 cores: `timeout` is only a
    hang guard, and a child that exited fails at once."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return lines.get(timeout=0.2)
        except queue.Empty:
            assert proc.poll() is None, f"the port's process exited ({proc.returncode}) before it was ready"
            assert time.monotonic() < deadline, f"the port's process said nothing in {timeout:g} s"


def connected_to(server: str, port: str) -> list[str]:
    """The ports connected to ``port`` on the JACK server (from ``jack_lsp -c``)."""
    run = jack_lsp(server, "-c")
    out = run.stdout if run is not None else ""
    peers: list[str] = []
    current = None
    for line in out.splitlines():
        if line.startswith((" ", "\t")):
            if current == port:
                peers.append(line.strip())
        else:
            current = line.strip()
    return peers


def wait_for_host(server: str, port: str, timeout: float = 60.0) -> None:
    """Wait until a facepuppet client has opened ``port``."""
    deadline = time.monotonic() + timeout
    while not any(p.startswith("facepuppet") for p in connected_to(server, port)):
        assert time.monotonic() < deadline, f"nothing opened {port} within {timeout} s"
        time.sleep(0.05)


def stop_child(proc: subprocess.Popen | None) -> None:  # type: ignore[type-arg]
    """Ask a port-playing child process to quit (a line "quit" on its stdin); kill it if it will not."""
    if proc is None:
        return
    try:
        assert proc.stdin is not None
        proc.stdin.write("quit\n")
        proc.stdin.flush()
        proc.wait(10)
    except (BrokenPipeError, subprocess.TimeoutExpired, OSError):
        proc.kill()
        proc.wait(5)
