"""Arrays in one file that a process maps instead of reading: a short header (magic, the data's
start, a JSON index of names, dtypes, shapes and offsets, and one SHA-256 of every array's bytes),
then each array on a 64-byte boundary. Reading maps the file privately (copy-on-write) and hands
out views of the mapping: ordinary writable, aligned, C-ordered numpy arrays (the compiled kernels
see the types they see in arrays made in memory, so the same compiled signatures), no copy and no
per-array parsing; the checksum is checked over the mapped bytes. Used by the face cache's stepper
entries (`puppet.face_cache.StepperStore`) and the batch's machine-wide store (`puppet.batch.shared`)."""

from __future__ import annotations

import contextlib
import hashlib
import json
import mmap
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

#: each array starts on a multiple of this many bytes (a cache line; numpy's own alignment)
ALIGN = 64
MAGIC = b"PUPPETSHARED1\n"


def _layout(arrays: dict[str, np.ndarray]) -> tuple[bytes, list[tuple[str, np.ndarray, int]], int]:
    """The file's header (magic, length, JSON index), each array with its offset, the file's size."""
    index, places, pos = [], [], 0
    for name, a in arrays.items():
        a = np.asarray(a) if np.asarray(a).flags.c_contiguous else np.array(a, order="C")  # 0-d stays 0-d
        index.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape), "offset": pos})
        places.append((name, a, pos))
        pos += -(-a.nbytes // ALIGN) * ALIGN
    h = hashlib.sha256()
    for _, a, _ in places:
        h.update(a.tobytes())
    text = json.dumps({"arrays": index, "sha256": h.hexdigest()}).encode()
    head = len(MAGIC) + 8 + len(text)
    start = -(-head // ALIGN) * ALIGN
    header = MAGIC + start.to_bytes(8, "little") + text
    return header + b"\0" * (start - head), [(n, a, start + p) for n, a, p in places], start + pos


def dump(fh: Any, arrays: dict[str, np.ndarray]) -> None:
    """The arrays in the file open for binary writing as `fh` (from its start)."""
    header, places, size = _layout(arrays)
    fh.write(header)
    for _, a, offset in places:
        fh.seek(offset)
        fh.write(a.tobytes())
    fh.truncate(size)


def write(path: Path, arrays: dict[str, np.ndarray], replace: bool = True) -> bool:
    """The arrays in one file at `path`, written beside it and moved into place; with `replace`
    False a file already there (another process's, written at the same time) is kept instead, so
    every process maps the same one. True when this call's file is in place."""
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            dump(fh, arrays)
        if replace:
            os.replace(tmp, path)
            return True
        try:
            os.link(tmp, path)  # only where none is: the first writer's file stays
            return True
        except FileExistsError:
            return False
        finally:
            os.unlink(tmp)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def read(path: Path) -> dict[str, np.ndarray]:
    """The arrays of a file `write` made, as views of one private mapping of it (ValueError or
    OSError when it is not such a file)."""
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size < len(MAGIC) + 8:
            raise ValueError("too short")
        m = mmap.mmap(fh.fileno(), size, access=mmap.ACCESS_COPY)
    if m[:len(MAGIC)] != MAGIC:
        raise ValueError("not a shared arrays file")
    start = int.from_bytes(m[len(MAGIC):len(MAGIC) + 8], "little")
    if not len(MAGIC) + 8 <= start <= size:
        raise ValueError("bad header")
    head = json.loads(bytes(m[len(MAGIC) + 8:start]).rstrip(b"\0"))
    out, h = {}, hashlib.sha256()
    for e in head["arrays"]:
        dtype = np.dtype(e["dtype"])
        if dtype.hasobject:
            raise ValueError("object arrays")
        count = int(np.prod(e["shape"], dtype=np.int64))
        offset = start + int(e["offset"])  # from the first array's start
        if offset < start or offset % ALIGN or offset + count * dtype.itemsize > size:
            raise ValueError(f"member {e['name']} out of the file")
        out[str(e["name"])] = np.frombuffer(m, dtype, count, offset).reshape(tuple(e["shape"]))
        h.update(memoryview(m)[offset:offset + count * dtype.itemsize])
    if h.hexdigest() != head["sha256"]:
        raise ValueError("damaged (checksum)")
    return out


