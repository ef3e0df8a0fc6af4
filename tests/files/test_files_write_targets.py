"""Where a command writes: a full disk, a folder where a file is named, a file where a folder is
named, a folder of frames from an earlier export, a disk that cannot sync. Each is a result or one
line naming the file the user gave (never the hidden temporary one), exit 2, and the old file kept."""

from __future__ import annotations

import errno
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

import formats
from safefile import BadFile, atomic_write

ROOT = Path(__file__).resolve().parents[2]
OLD = formats.OLD


def _full_disk() -> None:
    """The child's files stop growing at 600 bytes: each write past that fails as on a full disk
    (EFBIG; Python ignores SIGXFSZ)."""
    resource.setrlimit(resource.RLIMIT_FSIZE, (600, 600))


def _puppet(args: list[str], cwd: Path, full: bool = False) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=300, preexec_fn=_full_disk if full else None)


def _one_line(r: subprocess.CompletedProcess, *names: str) -> str:
    assert r.returncode == 2, r.stderr[-2000:]
    assert "Traceback" not in r.stderr, r.stderr[-2000:]
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert len(lines) == 1, r.stderr[-2000:]
    assert any(n in lines[0] for n in names), lines[0]
    assert ".part" not in lines[0] and len(lines[0]) < formats.MAX_LINE, lines[0]
    return lines[0]


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".part" in p.name)


@pytest.mark.parametrize("name", ["take.csv", "take.arkit.csv", "take.pc2", "still.png", "take.mp4", "frames"])
def test_a_full_disk_is_one_line_naming_the_export_and_the_old_file_stays(tmp_path: Path, name: str) -> None:
    formats.good_recording(tmp_path)
    out = tmp_path / name
    old = formats.old_output(out)
    r = _puppet(["replay", "good.jsonl", "--fps", "60", "--size", "320x240", "--out", name], tmp_path, full=True)
    line = _one_line(r, name, *(["take.obj"] if name == "take.pc2" else []))  # the rest mesh is written first
    assert "cannot write" in line
    assert old.read_bytes() == OLD
    assert _leftovers(tmp_path) == [] and (name != "frames" or _leftovers(out) == [])


def test_an_mp4_that_ffmpeg_could_not_finish_is_an_error_and_the_old_video_stays(tmp_path: Path) -> None:
    """A short video is held in ffmpeg until its end, so a full disk shows only in ffmpeg's exit
    status (here ffmpeg is stopped by the file size limit): it used to be renamed over the old
    video, 600 bytes without its index, exit 0."""
    formats.good_recording(tmp_path)
    (tmp_path / "short.mp4").write_bytes(OLD)
    r = _puppet(["replay", "good.jsonl", "--to", "0.2", "--size", "320x240", "--out", "short.mp4"], tmp_path, full=True)
    _one_line(r, "short.mp4")
    assert (tmp_path / "short.mp4").read_bytes() == OLD and _leftovers(tmp_path) == []


@pytest.mark.parametrize("name", ["still.png", "pose.npz", "pose.obj"])
def test_a_full_disk_under_pose_is_one_line(tmp_path: Path, name: str) -> None:
    (tmp_path / name).write_bytes(OLD)
    r = _puppet(["pose", "--seconds", "0", "--size", "320x240", "--out", name], tmp_path, full=True)
    _one_line(r, name)
    assert (tmp_path / name).read_bytes() == OLD and _leftovers(tmp_path) == []


@pytest.mark.parametrize("argv", [["replay", "good.jsonl", "--out", "named.arkit.csv"],
                                  ["pose", "--seconds", "0", "--out", "named.npz"],
                                  ["pose", "--seconds", "0", "--out", "named.obj"],
                                  ["pose", "--seconds", "0", "--size", "64x48", "--out", "named.png"]],
                         ids=["replay-arkit", "pose-npz", "pose-obj", "pose-png"])
def test_a_folder_where_a_file_is_named_is_one_line_and_the_folder_is_kept(tmp_path: Path, argv: list[str]) -> None:
    formats.good_recording(tmp_path)
    folder = tmp_path / argv[-1]
    folder.mkdir()
    (folder / "mine.txt").write_bytes(OLD)
    r = _puppet(argv, tmp_path)
    line = _one_line(r, argv[-1])
    assert "folder" in line
    assert sorted(p.name for p in folder.iterdir()) == ["mine.txt"] and _leftovers(tmp_path) == []


def test_a_file_where_a_frames_folder_is_named_is_one_line_and_the_file_is_kept(tmp_path: Path) -> None:
    formats.good_recording(tmp_path)
    (tmp_path / "shots").write_bytes(OLD)
    r = formats.run_cli(["replay", str(tmp_path / "good.jsonl"), "--out", str(tmp_path / "shots")],
                        tmp_path / "shots")
    assert r.kind == "error", r.text
    assert (tmp_path / "shots").read_bytes() == OLD and _leftovers(tmp_path) == []


def test_a_shorter_export_into_a_frames_folder_leaves_only_its_own_frames(tmp_path: Path) -> None:
    """A folder that held a longer export's frames holds only the new export's after it (an image
    sequence read by Blender or ffmpeg would otherwise run on into the old take); other files stay."""
    formats.good_recording(tmp_path)
    take, shots = tmp_path / "good.jsonl", tmp_path / "shots"
    common = ["replay", str(take), "--size", "64x48", "--fps", "60", "--out", str(shots)]
    assert formats.run_cli(common, take).kind == "ok"
    first = sorted(p.name for p in shots.iterdir())
    (shots / "notes.txt").write_bytes(OLD)
    assert formats.run_cli([*common, "--to", "0.1"], take).kind == "ok"
    second = sorted(p.name for p in shots.glob("frame_*.png"))
    assert 3 <= len(second) < len(first) and second == first[:len(second)]
    assert (shots / "notes.txt").read_bytes() == OLD


def test_a_sync_that_fails_keeps_the_old_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """fsync reporting an I/O error means the new bytes may not be on the disk: renaming them over
    the old file could lose both, so the write fails and the old file stays."""
    target = tmp_path / "keep.csv"
    target.write_bytes(OLD)

    def broken(fd: int) -> None:
        raise OSError(errno.EIO, os.strerror(errno.EIO))

    monkeypatch.setattr(os, "fsync", broken)
    with pytest.raises(BadFile, match="keep.csv: cannot write"):
        with atomic_write(target) as fh:
            fh.write("new")
    assert target.read_bytes() == OLD and _leftovers(tmp_path) == []


@pytest.mark.parametrize("name", ["b" * 246 + ".csv", "é" * 121 + ".pc2", "c" * 250],
                         ids=["250-byte-csv", "246-byte-unicode-pc2", "250-byte-frames-folder"])
def test_an_output_name_as_long_as_the_file_system_allows_is_written(tmp_path: Path, name: str) -> None:
    """The temporary name beside the target is longer than the target's: a name near the file
    system's 255-byte limit was refused as 'File name too long' though the file itself could be."""
    formats.good_recording(tmp_path)
    take, out = tmp_path / "good.jsonl", tmp_path / name
    r = formats.run_cli(["replay", str(take), "--to", "0.05", "--size", "64x48", "--out", str(out)], take)
    assert r.kind == "ok", r.text
    assert out.exists() and _leftovers(tmp_path) == []
    if out.suffix == ".pc2":
        assert out.with_suffix(".obj").is_file()


def test_a_file_system_without_fsync_still_gets_the_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Some file systems (FUSE mounts, pipes' folders) answer fsync with EINVAL or ENOSYS: nothing
    was lost there, so the write completes."""
    target = tmp_path / "synced.csv"
    target.write_bytes(OLD)
    for code in (errno.EINVAL, errno.ENOSYS):
        def unsupported(fd: int, code: int = code) -> None:
            raise OSError(code, os.strerror(code))

        monkeypatch.setattr(os, "fsync", unsupported)
        with atomic_write(target) as fh:
            fh.write(f"new {code}")
        assert target.read_text() == f"new {code}"
