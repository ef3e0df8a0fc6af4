"""Sequential writing of a large output file (a point cache: 190 MB for 10 s of the scanned head)
that costs the writing process almost no CPU.

A buffered write copies every byte into the page cache: the kernel allocates, fills and later
flushes ~46,000 pages per 190 MB, 0.1-1.2 s of system CPU per file on the development machine,
paid again by the kernel's flusher threads. Where the file system allows it (ext4, xfs, btrfs),
this writer opens the file with O_DIRECT: the bytes go from a few page-aligned staging buffers,
reused by every file this process writes, to the disk, written by a background thread while the
caller computes the next frames. Anywhere O_DIRECT is refused (tmpfs, some network or FUSE file
systems, not Linux), it writes through the page cache as before. The file's bytes are the same
either way; the ends that are not whole disk blocks, and any later patch (a header's count), are
written through the page cache, which the kernel keeps coherent with the direct writes."""

from __future__ import annotations

import mmap
import os
import queue
import threading
from typing import Any

#: bytes per staging buffer and disk write (a multiple of any disk block size in use)
CHUNK = 4 << 20
#: staging buffers a writer may have in flight (one filling, the others queued for the disk: a
#: short stall of a shared disk does not stop the frames)
BUFFERS = 8
#: direct writes start and end on multiples of this (the largest logical block size in use)
ALIGN = 4096

_pool: list[mmap.mmap] = []  # staging buffers kept between files (first touches cost page faults)
_pool_lock = threading.Lock()


def _take() -> mmap.mmap:
    with _pool_lock:
        while _pool:
            buf = _pool.pop()
            if len(buf) == CHUNK:
                return buf
            # one kept from when buffers had another size: dropped (unmapped once nothing views it)
    return mmap.mmap(-1, CHUNK)  # anonymous, page-aligned


def _give(buf: mmap.mmap) -> None:
    with _pool_lock:
        if len(_pool) < BUFFERS:
            _pool.append(buf)
    # else dropped: unmapped once nothing views it (closing it now fails while a view is alive)


class BulkWriter:
    """Appends bytes to a new file at `path` (created or truncated, mode 0o666 less the umask);
    `patch` overwrites a few bytes already written; `close` completes the file. Errors of the
    background writes are raised by the next `write`, `patch` or `close`."""

    def __init__(self, path: str | os.PathLike[str], direct: bool = True) -> None:
        self.path = os.fspath(path)
        self._flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0)
        self._plain = os.open(self.path, self._flags, 0o666)  # page cache: ends and patches
        self._direct: int | None = None
        o_direct = getattr(os, "O_DIRECT", 0)
        if direct and o_direct:
            try:
                self._direct = os.open(self.path, os.O_WRONLY | o_direct | getattr(os, "O_CLOEXEC", 0))
            except OSError:  # the file system does not do direct I/O
                self._direct = None
        self._pos = 0  # bytes handed to write()
        self._buf: mmap.mmap | None = None
        self._fill = 0
        self._error: BaseException | None = None
        self._free: queue.Queue[mmap.mmap] = queue.Queue()
        self._jobs: queue.Queue[Any] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._budget = BUFFERS

    @property
    def direct(self) -> bool:
        """True while the bulk of the file goes past the page cache."""
        return self._direct is not None

    def write(self, data: Any) -> None:
        """Append a bytes-like object."""
        self._check()
        mv = memoryview(data).cast("B")
        while len(mv):
            if self._buf is None:
                self._buf = self._next_buffer()
                self._fill = 0
            n = min(len(mv), CHUNK - self._fill)
            self._buf[self._fill:self._fill + n] = mv[:n]
            self._fill += n
            self._pos += n
            mv = mv[n:]
            if self._fill == CHUNK:
                self._submit(self._pos - CHUNK, self._buf, CHUNK)
                self._buf = None

    def patch(self, offset: int, data: bytes) -> None:
        """Overwrite bytes at `offset` (already written), through the page cache, after every
        write before it has reached the file."""
        mv = memoryview(data).cast("B")
        if offset < 0 or offset + len(mv) > self._pos:
            raise ValueError("a patch must lie within the bytes written")
        held = self._pos - self._fill if self._buf is not None else self._pos  # first byte still in a buffer
        if offset + len(mv) > held:  # the part not yet handed to the disk: change the buffer
            k = max(0, held - offset)
            start = offset + k - held
            assert self._buf is not None
            self._buf[start:start + len(mv) - k] = mv[k:]
            mv = mv[:k]
        if len(mv):
            self._drain()
            self._pwrite_all(self._plain, mv, offset)

    def close(self) -> None:
        """Write what is left and close the file (raises what went wrong, if anything did)."""
        try:
            if self._buf is not None and self._fill:
                self._submit(self._pos - self._fill, self._buf, self._fill)
                self._buf = None
            self._drain()
        finally:
            self._shutdown()

    def abort(self) -> None:
        """Stop and close without completing (the caller removes the file)."""
        self._shutdown()

    # ------------------------------------------------------------------------------ internals

    def _next_buffer(self) -> mmap.mmap:
        if self._budget > 0:
            self._budget -= 1
            return _take()
        buf = self._free.get()  # back-pressure: wait for a written buffer
        if self._error is not None:
            self._free.put(buf)  # returned to the pool by abort()
            self._check()
        return buf

    def _submit(self, offset: int, buf: mmap.mmap, n: int) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="pc2-writer", daemon=True)
            self._thread.start()
        self._jobs.put((offset, buf, n))

    def _run(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            offset, buf, n = job
            try:
                if self._error is None:
                    self._write_at(offset, buf, n)
            except BaseException as err:  # raised in the caller's thread
                self._error = err
            finally:
                self._free.put(buf)

    def _write_at(self, offset: int, buf: mmap.mmap, n: int) -> None:
        mv = memoryview(buf)[:n]
        try:
            whole = n - n % ALIGN if self._direct is not None else 0
            if whole:
                try:
                    self._pwrite_all(self._direct, mv[:whole], offset)  # type: ignore[arg-type]
                except OSError as err:
                    if err.errno != 22:  # EINVAL: direct I/O refused here after all
                        raise
                    self._stop_direct()
                    whole = 0
            if whole < n:
                self._pwrite_all(self._plain, mv[whole:], offset + whole)
        finally:
            mv.release()

    @staticmethod
    def _pwrite_all(fd: int, mv: memoryview, offset: int) -> None:
        while len(mv):
            k = os.pwrite(fd, mv, offset)
            mv, offset = mv[k:], offset + k

    def _stop_direct(self) -> None:
        fd, self._direct = self._direct, None
        if fd is not None:
            os.close(fd)

    def _drain(self) -> None:
        """Wait until every submitted buffer is written."""
        if self._thread is not None:
            self._jobs.put(None)
            self._thread.join()
            self._thread = None
        self._check()

    def _check(self) -> None:
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def _shutdown(self) -> None:
        if self._thread is not None:
            self._jobs.put(None)
            self._thread.join()
            self._thread = None
        if self._buf is not None:
            _give(self._buf)
            self._buf = None
        while True:
            try:
                _give(self._free.get_nowait())
            except queue.Empty:
                break
        self._stop_direct()
        if self._plain >= 0:
            os.close(self._plain)
            self._plain = -1
