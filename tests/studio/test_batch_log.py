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
