"""The bulk writer behind point caches: the same bytes whether the file system takes direct I/O or
not, a header patched after the fact lands, and a failing disk is an error naming the file."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from puppet.errors import ConfigError
from puppet.export import bulk
from puppet.export.pc2 import PC2Writer, read_pc2

SHM = Path("/dev/shm")  # tmpfs: kernels before 6.6 refuse O_DIRECT there


def _pieces(seed: int) -> list[bytes]:
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, int(n), dtype=np.uint8).tobytes() for n in rng.integers(1, 30000, 40)]


@pytest.mark.parametrize("where", ["disk", "tmpfs", "no direct", "refused at write"])
def test_bytes_equal_a_plain_write_across_buffers(where: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bulk, "CHUNK", 3 * bulk.ALIGN)  # many buffers, ends of odd sizes
    folder = tmp_path
    if where == "tmpfs":
        if not SHM.is_dir():
            pytest.skip("no /dev/shm")
        folder = Path(__import__("tempfile").mkdtemp(dir=SHM))
    pieces = _pieces(7)
    target = folder / "a.bin"
    w = bulk.BulkWriter(target, direct=where != "no direct")
    if where == "refused at write":  # a file system that opens with O_DIRECT but refuses the writes
        real, direct_fd = bulk.os.pwrite, w._direct

        def pwrite(fd: int, data: memoryview, offset: int) -> int:
            if fd == direct_fd:
                raise OSError(22, "Invalid argument")
            return real(fd, data, offset)

        monkeypatch.setattr(bulk.os, "pwrite", pwrite)
    for p in pieces:
        w.write(p)
    w.patch(0, b"HEAD")  # long since on the disk
    w.patch(sum(map(len, pieces)) - 3, b"end")  # still in the last buffer
    w.close()
    want = bytearray(b"".join(pieces))
    want[:4] = b"HEAD"
    want[-3:] = b"end"
    try:
        assert target.read_bytes() == bytes(want)
    finally:
        if where == "tmpfs":
            target.unlink()
            folder.rmdir()


def test_point_cache_same_bytes_direct_or_not(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bulk, "CHUNK", 2 * bulk.ALIGN)
    frames = np.random.default_rng(3).normal(size=(9, 101, 3))
    for direct in (True, False):
        w = PC2Writer(tmp_path / f"{direct}.pc2", 101, start_frame=2.0, direct=direct)
        for f in frames:
            w.add(f)
        w.close()
    assert (tmp_path / "True.pc2").read_bytes() == (tmp_path / "False.pc2").read_bytes()
    head, data = read_pc2(tmp_path / "True.pc2")
    assert head["num_samples"] == 9 and head["start_frame"] == 2.0
    assert np.array_equal(data, frames.astype(np.float32))
    assert not any(t.name == "pc2-writer" for t in threading.enumerate())  # nothing left running


def test_a_full_disk_is_an_error_naming_the_file(monkeypatch: pytest.MonkeyPatch) -> None:
    full = Path("/dev/full")
    if not full.exists():
        pytest.skip("no /dev/full")
    monkeypatch.setattr(bulk, "CHUNK", bulk.ALIGN)
    w = PC2Writer(full, 1000)
    with pytest.raises(ConfigError, match="/dev/full: cannot write the point cache"):
        for _ in range(20):  # the background write fails; a later add or the close says so
            w.add(np.zeros((1000, 3)))
        w.close()
