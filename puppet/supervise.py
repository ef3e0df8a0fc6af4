"""`puppet live --supervise`: the show comes back after a crash.

The supervisor is a small process that runs the show as a child (`puppet live ... --record FILE`)
and keeps a second child on standby: started with `--resume --standby`, it has imported
everything, loaded the face and its kernels, and waits on its standard input. When the show's
process dies other than by finishing (a signal such as SIGKILL, an exception, any exit code but 0
and 2), the standby is told to go at once: it opens the devices, continues the same recording as
a new segment (puppet.resume) and reaches its first tick in a fraction of a second; a new standby
is then started. Exit 0 (the show ended) and exit 2 (the user's error, which a restart would
repeat) end the supervisor with that code; SIGINT/SIGTERM are passed to the show, which stops
cleanly. A show that dies within `QUICK_S` of its start `MAX_QUICK` times in a row is given up."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

POLL_S = 0.005
FOLLOW_S = 0.1  # a standby reads the new records of the recording this often
QUICK_S = 3.0
MAX_QUICK = 5
STANDBY_FLAG = "--standby"


def child_argv(argv: list[str], record: str) -> list[str]:
    """The show's command: this command line without --supervise (and without --record, given
    again with the recording's path)."""
    out: list[str] = []
    skip = False
    for a in argv:
        if skip:
            skip = False
            continue
        if a == "--supervise" or a == "--resume":
            continue
        if a == "--record":
            skip = True
            continue
        if a.startswith("--record="):
            continue
        out.append(a)
    return [sys.executable, "-m", "puppet", *out, "--record", record]


def _describe(code: int) -> str:
    if code < 0:
        try:
            return f"signal {signal.Signals(-code).name}"
        except ValueError:
            return f"signal {-code}"
    return f"exit code {code}"


class Supervisor:
    """Runs `cmd` (see the module docstring)."""

    def __init__(self, cmd: list[str], record: Path, log: Any = None) -> None:
        self.cmd, self.record = cmd, record
        self.log = log or (lambda msg: print(f"puppet: {msg}", file=sys.stderr, flush=True))
        self.stopping = False
        self.show: subprocess.Popen[bytes] | None = None
        self.standby: subprocess.Popen[bytes] | None = None
        self.restarts = 0
        self._size_at_start: int | None = None

    def _spawn(self, standby: bool) -> subprocess.Popen[bytes]:
        cmd = [*self.cmd, "--resume", STANDBY_FLAG] if standby else self.cmd
        return subprocess.Popen(cmd, stdin=subprocess.PIPE if standby else None)

    def _signal(self, signum: int, frame: object) -> None:
        self.stopping = True
        for p in (self.show, self.standby):
            if p is not None and p.poll() is None:
                try:
                    p.send_signal(signal.SIGTERM)
                except OSError:
                    pass

    def _show_is_up(self, started: float) -> bool:
        """The show has performed a tick since it started (its recording grew), or 10 s passed."""
        if time.monotonic() - started > 10.0:
            return True
        try:
            st = self.record.stat()
        except OSError:
            return False
        if self._size_at_start is None or st.st_size < self._size_at_start:  # new, or started again
            self._size_at_start = st.st_size
        return st.st_size > self._size_at_start + 256

    def _go(self) -> subprocess.Popen[bytes] | None:
        """Wake the standby (None if it died; a fresh show is then started the slow way)."""
        sb, self.standby = self.standby, None
        if sb is None or sb.poll() is not None or sb.stdin is None:
            return None
        try:
            sb.stdin.write(b"go\n")
            sb.stdin.close()
        except OSError:
            return None
        return sb

    def run(self) -> int:
        old = {s: signal.signal(s, self._signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            return self._loop()
        finally:
            for s, h in old.items():
                signal.signal(s, h)
            if self.standby is not None and self.standby.poll() is None:
                self.standby.terminate()
                try:
                    self.standby.wait(10)
                except subprocess.TimeoutExpired:
                    self.standby.kill()

    def _loop(self) -> int:
        self.show = self._spawn(False)
        started = time.monotonic()
        quick = 0
        while True:
            code = self.show.poll()
            if code is None:
                if self.standby is None and not self.stopping and self._show_is_up(started):
                    self.standby = self._spawn(True)  # after the show's own start, not during it
                elif self.standby is not None and self.standby.poll() is not None and not self.stopping:
                    self.standby = None  # it died (e.g. the machine is short of memory): try again
                time.sleep(POLL_S)
                continue
            if self.stopping or code in (0, 2):
                return 0 if self.stopping and code in (0, -signal.SIGTERM) else code
            t_crash = time.monotonic()
            quick = quick + 1 if t_crash - started < QUICK_S else 0
            if quick >= MAX_QUICK:
                self.log(f"the show died {quick} times within {QUICK_S:g} s of starting ({_describe(code)}); "
                         "giving up: see the errors above")
                return 1
            nxt = self._go()
            how = "from standby"
            if nxt is None:
                nxt, how = subprocess.Popen([*self.cmd, "--resume"]), "cold"
            self.show, started = nxt, time.monotonic()
            self._size_at_start = None
            self.restarts += 1
            self.log(f"the show stopped ({_describe(code)}); restarted ({how}) "
                     f"{(started - t_crash) * 1e3:.0f} ms later, continuing the same take")


def stand_by(args: Any, load: Any) -> bool:
    """In a standby child: get everything ready (face, kernels, a full garbage collection), then
    follow the recording (`args.follower`) until "go" arrives on stdin. False if told to quit
    instead (stdin closed without "go")."""
    import gc
    import select

    from puppet.resume import TakeFollower

    face = load()
    from sim.integrator import warm_up

    warm_up(implicit=False)
    if args.rig is None:
        import sim.wrinkles.layer  # noqa: F401  (its import is most of the wrinkle layer's cost)
    follower = TakeFollower(args.record, face)
    gc.collect()
    gc.freeze()  # what exists now is not collected again: the show's first collection is short
    while True:
        follower.poll()
        ready, _, _ = select.select([sys.stdin], [], [], FOLLOW_S)
        if ready:
            break
    args.follower = follower
    return sys.stdin.readline().strip() == "go"


def run_supervised(args: Any, warn: Any) -> int:
    """`puppet live --supervise`: the recording is where the take is kept, so there is always one."""
    from puppet import live

    record = args.record
    if not record:
        record = str(live.default_record_path())
        warn(f"--supervise records the show (a restart continues the take): recording to {record}")
    argv = sys.argv[1:]
    if "live" not in argv:
        from puppet.errors import PuppetError

        raise PuppetError("--supervise works from the command line (`puppet live --supervise ...`)")
    path = Path(record).resolve()
    return Supervisor(child_argv(argv, str(path)), path).run()

