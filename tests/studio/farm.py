"""A real Dask farm on 127.0.0.1 for the batch tests: `dask scheduler` and `dask worker` processes
started in their own sessions and stopped by PID (SIGTERM to the group, then SIGKILL)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

WORKER_ARGS = ["--host", "127.0.0.1", "--dashboard-address", "127.0.0.1:0", "--nworkers", "1", "--nthreads", "1"]


class Farm:
    def __init__(self, folder: Path, workers: int = 2) -> None:
        self.folder = folder
        self.file = folder / "scheduler.json"
        self.procs: list[subprocess.Popen] = []
        self.procs.append(self._spawn("scheduler", "scheduler", "--host", "127.0.0.1", "--port", "0",
                                      "--dashboard-address", "127.0.0.1:0", "--scheduler-file", str(self.file)))
        deadline = time.monotonic() + 60
        # the scheduler writes its file in place (not renamed into place): it is ready when the whole
        # of it parses, not when it first holds a few bytes
        while (address := self._scheduler_address()) is None:
            if time.monotonic() > deadline or self.procs[0].poll() is not None:
                self.stop()
                raise RuntimeError("the dask scheduler did not start: " + (folder / "scheduler.log").read_text()[-800:])
            time.sleep(0.1)
        self.address = address
        for k in range(workers):
            self.procs.append(self._spawn(f"worker{k}", "worker", "--scheduler-file", str(self.file), *WORKER_ARGS))
        self.wait_for_workers(workers)

    def _scheduler_address(self) -> str | None:
        try:
            return str(json.loads(self.file.read_text())["address"])
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def _spawn(self, log: str, *args: str) -> subprocess.Popen:
        out = open(self.folder / f"{log}.log", "wb")
        return subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                                cwd=self.folder)

    def client(self):  # type: ignore[no-untyped-def]
        from dask.distributed import Client

        return Client(self.address, timeout=30)

    def wait_for_workers(self, n: int) -> None:
        with self.client() as c:
            c.wait_for_workers(n, timeout=90)

    def stop(self) -> None:
        for p in reversed(self.procs):
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        for p in reversed(self.procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(p.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                p.wait(timeout=10)
