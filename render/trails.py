"""The recent path of every mesh node, for the trails view (seed 000 Fig. 8, right column): a ring
buffer of surface samples taken at a fixed rate of simulated time, so the drawn trail covers the
same seconds whatever the frame rate."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


class TrailHistory:
    """Ring buffer of the last `seconds` of surfaces, sampled every `sample_dt` of state time.

    `head` is the slot of the newest sample, `count` how many slots hold samples. `dirty` lists the
    slots changed since the renderer last uploaded them (the GPU copy is updated slot by slot).
    `path` (N,) is each node's path length over the window (cm), kept up to date per sample so the
    renderer can tell motionless nodes without scanning the whole history."""

    def __init__(self, n_vertices: int, seconds: float = 2.0, sample_dt: float = 1.0 / 30.0) -> None:
        self.sample_dt = sample_dt
        self.capacity = max(2, int(round(seconds / sample_dt)))
        self.frames = np.zeros((self.capacity, n_vertices, 3), np.float32)
        self.seg = np.zeros((self.capacity, n_vertices), np.float32)  # slot s: length from s-1 to s
        self.path = np.zeros(n_vertices, np.float32)
        self.head = -1
        self.count = 0
        self.last_time: float | None = None
        self.dirty: set[int] = set()

    def clear(self) -> None:
        self.head, self.count, self.last_time = -1, 0, None
        self.seg[:] = 0.0
        self.path[:] = 0.0
        self.dirty.clear()

    def push(self, surface: np.ndarray, time: float | None = None) -> bool:
        """Record `surface` if `sample_dt` has passed since the last sample (always when `time` is
        None). Time running backwards (a new take, a reset) starts a fresh history."""
        if time is not None and self.last_time is not None:
            if time < self.last_time:
                self.clear()
            elif time - self.last_time < self.sample_dt * 0.999:
                return False
        prev = self.head
        self.head = (self.head + 1) % self.capacity
        if self.count == self.capacity:  # the oldest sample goes, and the segment after it
            nxt = (self.head + 1) % self.capacity
            self.path -= self.seg[nxt]
            self.seg[nxt] = 0.0
        self.frames[self.head] = surface
        if self.count:
            # each node's step, |new - previous|, by components: np.linalg.norm(d, axis=1)'s bits (the
            # same sums in the same order) for a tenth of its time, as its reduction over rows of 3
            # values is slow (0.25 ms for 6k nodes, on every recorded frame's serial path)
            d = self.frames[self.head] - self.frames[prev]
            d *= d
            step = self.seg[self.head]
            np.add(d[:, 0], d[:, 1], out=step)
            step += d[:, 2]
            np.sqrt(step, out=step)
            self.path += step
            np.maximum(self.path, 0.0, out=self.path)
        self.count = min(self.count + 1, self.capacity)
        self.last_time = time
        self.dirty.add(self.head)
        return True

    def set(self, frames: Sequence[np.ndarray] | np.ndarray) -> None:
        """Replace the history with given surfaces, oldest first. A longer history than the ring
        holds is thinned evenly (keeping the first and the newest), so the whole span is drawn."""
        arr = np.asarray(frames, np.float32)
        if arr.ndim != 3 or arr.shape[1:] != self.frames.shape[1:]:
            raise ValueError(f"history must be (K, {self.frames.shape[1]}, 3), got {arr.shape}")
        self.clear()
        if len(arr) > self.capacity:
            arr = arr[np.unique(np.linspace(0, len(arr) - 1, self.capacity).round().astype(int))]
        for f in arr:
            self.push(f)

    def ordered(self) -> np.ndarray:
        """(count, N, 3) samples, oldest first."""
        idx = (self.head - np.arange(self.count)[::-1]) % self.capacity
        return self.frames[idx]

    @property
    def oldest(self) -> int:
        """Slot of the oldest sample (meaningful when count > 0)."""
        return (self.head - self.count + 1) % self.capacity
