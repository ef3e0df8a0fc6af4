"""A listing piped into a reader that stops early (`puppet takes list | head`) ends quietly."""

from __future__ import annotations

import subprocess
import sys


def test_a_closed_pipe_ends_the_command_without_a_traceback() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "channels"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader is gone before the first line is written
    err = proc.stderr.read().decode()
    code = proc.wait(timeout=60)
    assert err == "", err
    assert code == 141  # as a shell reports a command ended by SIGPIPE
