"""WAV files: a bounded reader (PCM 8/16/24/32-bit and float, any channel count, mono mix or one
channel) and a writer for a recording made while a show runs.

The writer writes 16-bit PCM to `NAME.partial` beside the target, rewrites the header's sizes about
once a second (a crash leaves a readable file holding all but the last second), and renames the
file into place when it is closed, so an earlier take's sound is never half overwritten."""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

import numpy as np

from safefile import MAX_BYTES, BadFile, fitting_stem, read_bytes

_PCM, _FLOAT, _EXTENSIBLE = 1, 3, 0xFFFE


def read_wav(path: str | Path, channel: int | None = None, limit: int = MAX_BYTES * 4) -> tuple[np.ndarray, int]:
    """(float64 samples in -1..1, rate): the mean of the channels, or channel `channel` (0-based).
    A file that is not a WAV this reads is a BadFile naming it and what is wrong."""
    src = str(path)
    try:
        data = read_bytes(path, "WAV file", limit=limit)
    except BadFile:
        raise
    except OSError as err:
        raise BadFile(f"{src}: cannot read the WAV file: {err.strerror or err}") from err
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise BadFile(f"{src}: not a WAV file (no RIFF/WAVE header); give a .wav recording")
    pos, fmt, body = 12, None, None
    while pos + 8 <= len(data):
        cid, size = data[pos:pos + 4], struct.unpack_from("<I", data, pos + 4)[0]
        chunk = data[pos + 8:pos + 8 + size]
        if cid == b"fmt ":
            fmt = chunk
        elif cid == b"data":
            body = chunk  # a data chunk cut short (a crash) is read as far as it goes
            break
        pos += 8 + size + (size & 1)
    if fmt is None or len(fmt) < 16:
        raise BadFile(f"{src}: WAV file without a valid fmt chunk")
    if body is None:
        raise BadFile(f"{src}: WAV file without a data chunk")
    tag, nch, rate, _, align, bits = struct.unpack_from("<HHIIHH", fmt)
    if tag == _EXTENSIBLE and len(fmt) >= 26:
        tag = struct.unpack_from("<H", fmt, 24)[0]
    if nch < 1 or nch > 64 or not (8000 <= rate <= 384000) or bits not in (8, 16, 24, 32, 64):
        raise BadFile(f"{src}: unsupported WAV layout ({nch} channels, {rate} Hz, {bits} bits)")
    width = bits // 8
    if align != width * nch:
        raise BadFile(f"{src}: inconsistent WAV header (block align {align} for {nch} x {bits} bits)")
    n = len(body) // align
    raw = np.frombuffer(body[:n * align], dtype=np.uint8)
    if tag == _FLOAT and bits in (32, 64):
        x = raw.view("<f4" if bits == 32 else "<f8").astype(np.float64)
        x = np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=-1.0)
    elif tag == _PCM and bits == 8:
        x = (raw.astype(np.float64) - 128.0) / 128.0
    elif tag == _PCM and bits == 16:
        x = raw.view("<i2").astype(np.float64) / 32768.0
    elif tag == _PCM and bits == 24:
        b = raw.reshape(-1, 3).astype(np.int32)
        v = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
        x = np.where(v >= 1 << 23, v - (1 << 24), v).astype(np.float64) / float(1 << 23)
    elif tag == _PCM and bits == 32:
        x = raw.view("<i4").astype(np.float64) / float(1 << 31)
    else:
        raise BadFile(f"{src}: unsupported WAV encoding (format tag {tag}, {bits} bits); use PCM or float")
    x = x.reshape(n, nch)
    if channel is not None:
        if not 0 <= channel < nch:
            raise BadFile(f"{src}: has {nch} channel(s); channel {channel + 1} does not exist")
        return np.clip(x[:, channel], -1.0, 1.0), int(rate)
    return np.clip(x.mean(axis=1), -1.0, 1.0), int(rate)


def wav_header(rate: int, frames: int, channels: int = 1) -> bytes:
    """The 44-byte header of a 16-bit PCM WAV holding `frames` frames."""
    data = frames * 2 * channels
    return (b"RIFF" + struct.pack("<I", 36 + data) + b"WAVE" + b"fmt " +
            struct.pack("<IHHIIHH", 16, _PCM, channels, rate, rate * 2 * channels, 2 * channels, 16) +
            b"data" + struct.pack("<I", data))


def to_pcm16(x: np.ndarray) -> bytes:
    return np.round(np.clip(np.asarray(x, dtype=np.float64), -1.0, 32767 / 32768) * 32768.0).astype("<i2").tobytes()


def _partial_name(path: Path) -> Path:
    """`NAME.partial` beside `path`; for a name within 8 bytes of the file system's limit (a take
    named near 255 bytes records `take.wav`), the part before `.wav` is cut to fit, in bytes on a
    character boundary, so the sound of a take the file system accepts is recorded."""
    stem = fitting_stem(path.parent, path.stem, len(os.fsencode(path.suffix + ".partial")))
    return path.with_name(stem + path.suffix + ".partial")


class WavWriter:
    """Mono 16-bit WAV written as it comes (see the module docstring). Not thread-safe."""

    HEADER_EVERY = 1.0

    def __init__(self, path: str | Path, rate: int) -> None:
        self.path = Path(path)
        self.rate = int(rate)
        self.partial = _partial_name(self.path)
        self.frames = 0
        self._f = open(self.partial, "wb")
        self._f.write(wav_header(self.rate, 0))
        self._next_header = time.monotonic() + self.HEADER_EVERY
        self.error: OSError | None = None

    def write(self, samples: np.ndarray) -> None:
        """Append samples (float, -1..1)."""
        if self._f is None or len(samples) == 0:
            return
        try:
            self._f.write(to_pcm16(samples))
            self.frames += len(samples)
            if time.monotonic() >= self._next_header:
                self._patch_header()
                self._next_header = time.monotonic() + self.HEADER_EVERY
        except OSError as err:  # disk full: stop writing, keep what is there
            self.error = err
            self._abandon()

    def write_silence(self, n: int) -> None:
        if n > 0:
            self.write(np.zeros(n))

    def truncate(self, frames: int) -> None:
        """Keep only the first `frames` frames."""
        if self._f is None or frames >= self.frames:
            return
        try:
            self._f.seek(44 + 2 * max(0, frames))
            self._f.truncate()
            self.frames = max(0, frames)
        except OSError as err:
            self.error = err
            self._abandon()

    def _patch_header(self) -> None:
        assert self._f is not None
        here = self._f.tell()
        self._f.seek(0)
        self._f.write(wav_header(self.rate, self.frames))
        self._f.seek(here)
        self._f.flush()

    def _abandon(self) -> None:
        try:
            if self._f is not None:
                self._patch_header()
                self._f.close()
        except OSError:
            pass
        self._f = None

    def close(self) -> Path | None:
        """Finish the header, make it durable and move it into place; the final path (None when
        writing failed: the partial file is left as it is)."""
        if self._f is None:
            return None
        try:
            self._patch_header()
            os.fsync(self._f.fileno())
            self._f.close()
            self._f = None
            os.replace(self.partial, self.path)
        except OSError as err:
            self.error = err
            self._abandon()
            return None
        return self.path
