"""A farm left without a worker mid-batch: the scheduler keeps the tasks for a worker to come and
the batch waited without a word, forever. It says so (one line, what to do) and goes on when a
worker joins, the outputs equal to the single command's."""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from farm import WORKER_ARGS, Farm
from puppet.cli import main
from takes import write_take


def test_a_farm_left_without_workers_says_so_and_goes_on_when_one_joins(tmp_path: Path) -> None:
    (tmp_path / "farm").mkdir()
    f = Farm(tmp_path / "farm", workers=1)
    try:
        shoot = tmp_path / "shoot"
        takes = [write_take(shoot / f"long{k}.jsonl", ticks=420, seed=40 + k) for k in range(3)]
        out = tmp_path / "out"
        out.mkdir()
        batch = subprocess.Popen([sys.executable, "-m", "puppet", "batch", "export", str(shoot), "--out", str(out),
                                  "--to", "pc2", "--scheduler", f.address], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True)
        lines: queue.Queue[str] = queue.Queue()

        def pump() -> None:
            assert batch.stderr is not None
            for line in batch.stderr:
                lines.put(line)

        pumping = threading.Thread(target=pump, daemon=True)
        pumping.start()
        with f.client() as c:  # the only worker (and its nanny) stopped once a task runs
            deadline = time.monotonic() + 300
            while not any(str(k).startswith("export-") for keys in c.processing().values() for k in keys):
                assert time.monotonic() < deadline and batch.poll() is None, "no task was seen running"
                time.sleep(0.05)
        worker = f.procs.pop()
        os.killpg(worker.pid, signal.SIGTERM)
        worker.wait(60)
        said = ""
        deadline = time.monotonic() + 120
        while "no worker" not in said:
            assert time.monotonic() < deadline and batch.poll() is None, f"nothing said; stderr so far: {said!r}"
            try:
                said += lines.get(timeout=1)
            except queue.Empty:
                pass
        assert f"dask worker {f.address}" in said and "Ctrl+C" in said, said
        f.procs.append(f._spawn("again", "worker", "--scheduler-file", str(f.file), *WORKER_ARGS))
        assert batch.stdout is not None  # stderr is the pump's alone: communicate() would take lines from it
        stdout = batch.stdout.read()
        batch.wait(600)
        pumping.join(60)
        rest = "".join(iter(lambda: lines.get_nowait() if not lines.empty() else "", ""))
        assert batch.returncode == 0, said + rest
        assert "wrote 6 files" in stdout, stdout
        assert "in the farm again" in said + rest, said + rest
        for t in takes:
            assert main(["replay", str(t), "--out", str(tmp_path / (t.stem + ".pc2"))]) == 0
            assert (out / (t.stem + ".pc2")).read_bytes() == (tmp_path / (t.stem + ".pc2")).read_bytes(), t.stem
    finally:
        f.stop()
