"""No command destroys or half-writes a file it was asked to write: every export, rig, pose and
learned map goes to a temporary file beside the target and is renamed into place when complete."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import formats
from safefile import BadFile, atomic_dir, atomic_write

OLD = formats.OLD


class Crash(RuntimeError):
    pass


def _performance(tmp_path: Path):
    from puppet.replay import build_performance
    from puppet.session import read_session

    formats.good_recording(tmp_path)
    return build_performance(read_session(tmp_path / "good.jsonl"), None)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".part" in p.name)


KINDS = [("take.csv", 2), ("take.arkit.csv", 2), ("take.curves", 1), ("take.pc2", 2), ("still.png", 1),
         ("take.mp4", 2), ("frames", 2)]


@pytest.mark.parametrize("name,after", KINDS, ids=[k for k, _ in KINDS])
def test_an_export_that_fails_midway_leaves_the_old_file_and_a_good_one_replaces_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, after: int) -> None:
    from puppet.export import runner
    from puppet.export.runner import ExportOptions, export

    perf = _performance(tmp_path)
    out = tmp_path / name
    old = formats.old_output(out)
    obj = out.with_suffix(".obj")
    old_obj = b"# facepuppet rest pose of an earlier export\n" + OLD  # a foreign OBJ is refused, not replaced
    if name.endswith(".pc2"):
        obj.write_bytes(old_obj)
    real_bar = runner._bar

    def crashing_bar(total: int, what: str):
        bar = real_bar(total, what)
        count = {"n": 0}
        update = bar.update

        def upd(k: int = 1) -> None:
            count["n"] += 1
            update(k)
            if count["n"] >= after:
                raise Crash("the disk went away")

        bar.update = upd
        return bar

    opts = ExportOptions(fps=30.0, size=(64, 48), parallel=False)
    monkeypatch.setattr(runner, "_bar", crashing_bar)
    with pytest.raises(Crash):
        export(perf, out, opts)
    assert old.read_bytes() == OLD
    if name.endswith(".pc2"):
        assert obj.read_bytes() == old_obj
    assert _leftovers(tmp_path) == []
    monkeypatch.setattr(runner, "_bar", real_bar)
    export(perf, out, opts)
    assert old.read_bytes() != OLD and old.stat().st_size > 0
    if name.endswith(".pc2"):
        assert obj.read_bytes() != old_obj
    assert _leftovers(tmp_path) == []


def test_a_rig_save_that_fails_leaves_the_old_rig(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from sim.face import default_rig
    from sim.rig import load_rig, save_rig

    rig = default_rig(0)
    p = tmp_path / "face.npz"
    save_rig(rig, p)
    before = p.read_bytes()

    def half(fh, **arrays):  # writes part of an archive, then fails
        fh.write(b"PK\x03\x04 half a rig")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", half)
    with pytest.raises(BadFile, match="face.npz: cannot write: No space left on device"):  # one line, not a traceback
        save_rig(rig, p)
    assert p.read_bytes() == before
    assert _leftovers(tmp_path) == []
    monkeypatch.undo()
    assert load_rig(p).name == rig.name


def test_learn_keeps_comments_and_permissions_and_never_loses_the_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from puppet.errors import ConfigError
    from puppet.mapping.learn import learn_binding

    p = tmp_path / "show.toml"
    p.write_text("# my show's map: keep this comment\nversion = 1\n\n[[binding]]  # the jaw dial\n"
                 'control = "dial0"\ntarget = "jaw"\n')
    os.chmod(p, 0o640)
    assert learn_binding(p, "dial1", "sgi://", "eyes_yaw", "dial") == "added"
    text = p.read_text()
    assert "# my show's map: keep this comment" in text and "# the jaw dial" in text and "eyes_yaw" in text
    assert stat.S_IMODE(p.stat().st_mode) == 0o640
    before = p.read_bytes()

    def no_rename(a, b):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "replace", no_rename)
    with pytest.raises(ConfigError, match="cannot write the mapping file"):
        learn_binding(p, "dial2", "sgi://", "age", "dial")
    assert p.read_bytes() == before
    assert _leftovers(tmp_path) == []
    monkeypatch.undo()
    (tmp_path / "broken.toml").write_text("version = 1\n[[binding]\ncontrol = 3\n")
    with pytest.raises(ConfigError, match="broken.toml:2"):
        learn_binding(tmp_path / "broken.toml", "dial2", "sgi://", "age", "dial")
    assert (tmp_path / "broken.toml").read_text() == "version = 1\n[[binding]\ncontrol = 3\n"


def test_a_new_file_gets_the_permissions_open_would_give(tmp_path: Path) -> None:
    umask = os.umask(0o022)
    try:
        with atomic_write(tmp_path / "new.txt") as fh:
            fh.write("hello\n")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "new.txt").stat().st_mode) == 0o644
    with pytest.raises(Crash):
        with atomic_dir(tmp_path / "shots") as d:
            (d / "a.png").write_bytes(b"1")
            raise Crash()
    assert not (tmp_path / "shots").exists() and _leftovers(tmp_path) == []


def test_sigkill_in_the_middle_of_a_write_leaves_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "take.csv"
    target.write_bytes(OLD)
    code = ("import sys, time\nfrom safefile import atomic_write\n"
            "with atomic_write(sys.argv[1]) as fh:\n    fh.write('frame,time\\n' * 10000)\n    fh.flush()\n"
            "    print('half', flush=True)\n    time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", code, str(target)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "half"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(10)
    assert target.read_bytes() == OLD
