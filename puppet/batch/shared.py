"""One copy in memory of the integrator's prepared arrays for every worker process on a machine.

The scanned head's implicit integrator reads ~12 MB of prepared arrays every step (the factored
matrix 5.7 MB, the skin's bending 1.8 MB, the lid and lip contact 1.8 MB, the fold guard 1.2 MB).
Each worker process loading its own copy puts two copies in the cores' shared last-level cache
with two workers, where they can evict each other (a take simulated about a fifth slower on each of
two workers than on one; how much of that the copies cause was within the noise of the machine it
was measured on, docs/studio.md). Here the first worker to need them writes them once to a file (in the
face cache's folder), and every worker maps that file: the same physical pages of the kernel's
page cache, so one copy in memory and in the CPU caches. The mapping is private (copy-on-write), so the arrays are ordinary writable numpy
arrays to the compiled kernels (which never write them), and the values, so the results, are the
very same bits.

`SharedStore` wraps the store `sim.prepared` uses (`puppet.face_cache.StepperStore`): a file here
is named by the same key (a digest of everything the arrays are made from) and checked by the
SHA-256 of its arrays' bytes; anything wrong with it is made again (and `sim.prepared.check`
checks the arrays' structure either way)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from puppet.mapped import ALIGN, MAGIC, read, write  # noqa: F401  (the file format, here since its start)

#: shared files kept (two per face and substep size: the prepared arrays and the jaw's grid,
#: `sim.prepared.kept`); older ones are removed (a process that mapped one keeps its pages)
KEEP = 8
PREFIX = "puppet-prepared-"


def shared_dir() -> Path:
    """Where the shared files live: the face cache's folder (`puppet.face_cache.cache_dir`), else
    shared memory (/dev/shm) or the temporary folder. Any file mapped by several processes is one
    copy in memory (the kernel's page cache); a file in the cache also serves the next batch."""
    from puppet.face_cache import cache_dir

    d = cache_dir()
    if d is not None:
        return d
    shm = Path("/dev/shm")
    return shm if shm.is_dir() and os.access(shm, os.W_OK) else Path(tempfile.gettempdir())


class SharedStore:
    """A `sim.prepared` store that serves every process on this machine one mapped copy of the
    arrays `inner` (the on-disk cache, or None) keeps or the integrator makes."""

    def __init__(self, inner: Any, directory: Path | None = None) -> None:
        self.inner = inner
        self.directory = directory or shared_dir()

    def path(self, key: str) -> Path:
        return self.directory / f"{PREFIX}{key[:40]}.shared"

    def load(self, key: str) -> dict[str, np.ndarray] | None:
        try:
            return read(self.path(key))
        except (OSError, ValueError, KeyError, TypeError):
            pass
        arrays = self.inner.load(key) if self.inner is not None else None
        if arrays is None:
            return None  # made by the integrator, then handed to save()
        return self._share(key, arrays)

    def save(self, key: str, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Kept by `inner` and shared; returns the shared (mapped) arrays to step on."""
        if self.inner is not None:
            try:
                self.inner.save(key, arrays)
            except OSError:
                pass
        return self._share(key, arrays)

    def _share(self, key: str, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            path = self.path(key)
            if not write(path, arrays, replace=False):
                try:
                    return read(path)  # another worker's, made at the same time: the same pages
                except (OSError, ValueError):
                    write(path, arrays)  # a damaged one: replaced
            _evict(self.directory)
            return read(path)
        except (OSError, ValueError):
            return arrays  # no shared memory here: this process's own copy


def _evict(directory: Path) -> None:
    files = sorted((p for p in directory.glob(PREFIX + "*") if not p.name.endswith(".part")),
                   key=lambda p: p.stat().st_mtime if p.exists() else 0.0)
    for p in files[:-KEEP] if len(files) > KEEP else []:
        try:
            p.unlink()
        except OSError:
            pass


def install() -> None:
    """This process's integrator takes its prepared arrays through a `SharedStore` (idempotent)."""
    from sim import prepared

    if not isinstance(prepared._STORE, SharedStore):
        from puppet.face_cache import StepperStore, cache_dir

        inner = prepared._STORE
        if inner is None:
            directory = cache_dir()
            inner = StepperStore(directory) if directory is not None else None
        prepared.use_store(SharedStore(inner))
