"""Point cache export for Blender's Mesh Cache modifier: a PC2 file of the drawn surface per frame
plus a rest-pose OBJ with the same vertex order.

PC2 layout (little-endian, Blender `MOD_meshcache_pc2.c`): b"POINTCACHE2\\0", int32 version = 1,
int32 point count, float32 start frame, float32 sampling (scene frames between samples), int32
sample count, then float32 x, y, z per point per sample. The start frame and sampling are always
written explicitly, so the cache lands on the frames the user expects."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from puppet.errors import ConfigError
from puppet.export.bulk import BulkWriter

PC2_MAGIC = b"POINTCACHE2\0"
PC2_HEADER = struct.Struct("<12siiffi")


class PC2Writer:
    """Streams frames to a PC2 file; the sample count in the header is patched on close, so a
    long export never holds all frames in memory. The frames go to the disk past the page cache
    where the file system allows it (`puppet.export.bulk`): a scanned head's cache is ~19 MB a
    second of take, and copying it through the page cache cost as much CPU as posing the scan."""

    def __init__(self, path: str | Path, num_points: int, start_frame: float = 1.0, sampling: float = 1.0,
                 direct: bool = True) -> None:
        self.path = Path(path)
        self.num_points = num_points
        self.start_frame, self.sampling = float(start_frame), float(sampling)
        self.count = 0
        try:
            self._out: BulkWriter | None = BulkWriter(self.path, direct=direct)
        except OSError as err:
            raise ConfigError(f"{self.path}: cannot write the point cache: {err.strerror}") from err
        self._out.write(self._header())

    def _header(self) -> bytes:
        return PC2_HEADER.pack(PC2_MAGIC, 1, self.num_points, self.start_frame, self.sampling, self.count)

    def add(self, points: np.ndarray) -> None:
        """Append one sample: (num_points, 3) positions."""
        assert self._out is not None
        pts = np.ascontiguousarray(points, dtype="<f4")
        if pts.shape != (self.num_points, 3):
            raise ValueError(f"expected ({self.num_points}, 3) points, got {pts.shape}")
        self._write(pts)
        self.count += 1

    def _write(self, data: np.ndarray | bytes) -> None:
        assert self._out is not None
        try:
            self._out.write(data)
        except OSError as err:
            self._out.abort()
            self._out = None
            raise ConfigError(f"{self.path}: cannot write the point cache: {err.strerror or err}") from err

    def close(self) -> None:
        if self._out is None:
            return
        out, self._out = self._out, None
        try:
            out.patch(0, self._header())
            out.close()
        except OSError as err:
            out.abort()
            raise ConfigError(f"{self.path}: cannot write the point cache: {err.strerror or err}") from err


def read_pc2(path: str | Path) -> tuple[dict[str, float | int], np.ndarray]:
    """(header fields, (samples, points, 3) float32) of a PC2 file: used by tests and to check
    a cache before handing it to Blender."""
    # the header first, the body's size against the file's before the body is read: a file that is
    # not a point cache (a 3 GB video named .pc2) was read whole, a MemoryError traceback
    try:
        with open(path, "rb") as fh:
            data = fh.read(PC2_HEADER.size)
            size = os.fstat(fh.fileno()).st_size
            if len(data) < PC2_HEADER.size:
                raise ConfigError(f"{path}: too short for a PC2 file")
            magic, version, n, start, sampling, samples = PC2_HEADER.unpack_from(data)
            if magic != PC2_MAGIC:
                raise ConfigError(f"{path}: not a PC2 file (bad magic)")
            if n < 0 or samples < 0:
                raise ConfigError(f"{path}: the PC2 header counts {n} points and {samples} samples; not a PC2 file")
            if size - PC2_HEADER.size != samples * n * 12:
                raise ConfigError(f"{path}: PC2 body holds {size - PC2_HEADER.size} bytes, header promises "
                                  f"{samples * n * 12} (cut short or damaged; export it again)")
            body = np.fromfile(fh, dtype="<f4", count=samples * n * 3)
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the point cache: {err.strerror or err}") from err
    except MemoryError as err:
        raise ConfigError(f"{path}: the point cache ({size // (1024 * 1024)} MB) does not fit in the memory") from err
    if len(body) != samples * n * 3:
        raise ConfigError(f"{path}: the point cache was cut short while it was read; export it again")
    head = {"version": version, "num_points": n, "start_frame": start, "sampling": sampling, "num_samples": samples}
    return head, body.reshape(samples, n, 3)


def write_obj(path: str | Path, vertices: np.ndarray, triangles: np.ndarray, comment: str = "") -> None:
    """A rest-pose OBJ: vertices in the simulation's order (which the PC2 relies on), 1-based faces,
    no normals or UVs so no importer is tempted to split vertices."""
    lines = [f"# {c}" for c in comment.splitlines()] if comment else []
    lines += [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in np.asarray(vertices, dtype=np.float64)]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(triangles, dtype=np.int64)]
    try:
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot write the mesh: {err.strerror}") from err
