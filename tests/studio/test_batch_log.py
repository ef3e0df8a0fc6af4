"""`puppet batch` run from a script or cron: its stderr is a log, so no progress bar is drawn
there (a bar in a log is a line of carriage returns); the summary line still is."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

from takes import write_take


def test_a_batch_whose_stderr_is_not_a_terminal_draws_no_progress_bar(tmp_path: Path) -> None:
    from puppet.cli import main

    write_take(tmp_path / "a.jsonl")
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = main(["batch", "export", str(tmp_path / "a.jsonl"), "--to", "csv", "--workers", "1",
                   "--out", str(tmp_path / "out")])
    assert rc == 0, err.getvalue()
    assert (tmp_path / "out" / "a.csv").is_file()
    log = err.getvalue() + out.getvalue()
    assert "\r" not in log and "task/s" not in log, log[:500]
    assert "batch export: wrote 1 file" in log


def test_a_large_input_makes_no_dask_warning(tmp_path: Path) -> None:
    """A task carries its input's bytes: a capture of more than 10 MB made Dask print its six-line
    'Sending large graph of size ... MiB' UserWarning on the user's terminal."""
    import os
    import subprocess
    import sys

    from puppet.export.arkit import ARKIT_SHAPES, ROTATIONS, timecode

    names = [*ARKIT_SHAPES, *ROTATIONS]
    row = ",".join(["0.123456"] * len(names))
    lines = [",".join(["Timecode", "BlendShapeCount", *names])]
    lines += [f"{timecode(k, 60.0)},61,{row}" for k in range(24000)]
    capture = tmp_path / "long.arkit.csv"
    capture.write_text("\n".join(lines) + "\n")
    assert capture.stat().st_size > 11 * 2**20
    root = Path(__file__).resolve().parents[2]
    r = subprocess.run([sys.executable, "-m", "puppet", "batch", "fit", str(capture), "--workers", "1",
                        "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=600,
                       env=dict(os.environ, PYTHONPATH=str(root)))
    assert r.returncode == 0, r.stderr
    assert "Sending large graph" not in r.stderr and "warn" not in r.stderr.lower(), r.stderr
    assert (tmp_path / "out" / "long.jsonl").is_file()
