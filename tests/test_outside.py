"""The program tried from outside, as a new user types it: mistyped options said before anything
loads, Ctrl-C at awkward moments, outputs that cannot be written. Each case was found doing so
(docs/files.md, "Tried from outside")."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _puppet(*args: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PUPPET_DATA_DIR": str(cwd / "data"), "PUPPET_FACE": "procedural"}
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout, env=env)


def _one_error(r: subprocess.CompletedProcess[str]) -> str:
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr[-1500:]
    return lines[0]


def test_ctrl_c_while_a_command_starts_is_exit_130_without_a_traceback(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C in the first 0.1-0.3 s (the command's modules importing) printed a KeyboardInterrupt
    traceback and the process died of the signal; later it is exit 130, quietly."""
    import importlib

    from puppet import cli

    real = importlib.import_module

    def interrupted(name: str, *a: object) -> object:
        if name == "puppet.cmd_replay":
            raise KeyboardInterrupt
        return real(name, *a)

    monkeypatch.setattr(importlib, "import_module", interrupted)
    assert cli.main(["replay", "take.jsonl", "--out", "x.csv"]) == 130


def test_a_malformed_panel_role_is_said_before_the_face_loads(tmp_path: Path) -> None:
    """`--panel-role x` (no NAME=PATTERNS) was accepted without a word when no page was served
    (a demo: `puppet live --headless` with no device), and said only after the face had loaded
    otherwise."""
    r = _puppet("live", "--panel-role", "x", "--headless", "--duration", "0.1", cwd=tmp_path)
    line = _one_error(r)
    assert "NAME=PATTERN" in line and "'x'" in line
    assert "preparing the face" not in r.stderr
    assert not list(tmp_path.glob("puppet-demo-*"))  # the demo did not run


def test_a_take_library_that_cannot_be_created_says_why(tmp_path: Path) -> None:
    """`puppet takes --library /sys/lib.db import .` (a folder nobody may write: a read-only disk)
    said only SQLite's "unable to open database file"."""
    r = _puppet("takes", "--library", "/sys/lib.db", "import", str(tmp_path), cwd=tmp_path)
    line = _one_error(r)
    assert "/sys/lib.db" in line and "cannot create it" in line and "unable to open" not in line


def test_pose_into_a_missing_folder_is_said_before_the_simulation(tmp_path: Path) -> None:
    """`puppet pose --out /nonexistent/dir/a.npz` simulated for 10-30 s, then said it could not
    write; a folder named as --out was found only then too."""
    r = _puppet("pose", "--au", "AU12=0.8", "--out", str(tmp_path / "no" / "such" / "a.npz"), cwd=tmp_path)
    line = _one_error(r)
    assert "does not exist" in line and str(tmp_path / "no" / "such") in line
    assert "preparing" not in r.stderr and "simulat" not in r.stderr.replace(line, "")
    (tmp_path / "dir.obj").mkdir()
    line = _one_error(_puppet("pose", "--out", str(tmp_path / "dir.obj"), cwd=tmp_path))
    assert "is a folder" in line
