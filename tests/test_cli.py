import subprocess
import sys


def test_puppet_help_lists_commands() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "puppet", "--help"], capture_output=True, text=True, check=True
    )
    assert "usage: puppet" in out.stdout


def test_unknown_command_is_an_error() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "puppet", "no-such-command"], capture_output=True, text=True
    )
    assert out.returncode == 2
