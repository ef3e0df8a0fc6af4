"""An orbit camera framed on the face: the window orbits and zooms it, the offscreen renderer uses
its default, so both see the same picture of the same state."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def perspective(fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL projection matrix (row-major numpy; transpose when uploading)."""
    f = 1.0 / math.tan(math.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """View matrix taking world coordinates to camera coordinates (camera looks down -Z)."""
    f = target - eye
    f = f / np.linalg.norm(f)
    s = np.cross(f, up)
    s = s / np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


@dataclass
class OrbitCamera:
    """Looks at the centre of a box from a distance that frames it, turned by `yaw`/`pitch`
    (radians) around it and moved in by `zoom`. The face looks along +Z, so yaw = pitch = 0 is the
    frontal view. The framing distance depends on the aspect ratio, so a tall window still shows
    the whole face."""

    lo: np.ndarray = field(default_factory=lambda: -np.ones(3))
    hi: np.ndarray = field(default_factory=lambda: np.ones(3))
    yaw: float = 0.0
    pitch: float = 0.0
    scale: float = 1.0
    fov_y: float = 25.0
    margin: float = 1.12

    def fit(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Frame the box [lo, hi] (cm) frontally with a little margin, and reset the view."""
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        self.reset()

    def reset(self) -> None:
        self.yaw = self.pitch = 0.0
        self.scale = 1.0

    @property
    def target(self) -> np.ndarray:
        return (self.lo + self.hi) / 2.0

    @property
    def radius(self) -> float:
        return float(np.linalg.norm(self.hi - self.lo) / 2.0)

    def distance(self, aspect: float) -> float:
        half = (self.hi - self.lo) / 2.0 * self.margin
        need = max(half[1], half[0] / max(aspect, 1e-6))
        return self.scale * (need / math.tan(math.radians(self.fov_y) / 2.0) + half[2])

    def orbit(self, d_yaw: float, d_pitch: float) -> None:
        """Turn around the target; pitch stays short of the poles so `up` is never degenerate."""
        self.yaw += d_yaw
        self.pitch = float(np.clip(self.pitch + d_pitch, -1.45, 1.45))

    def zoom(self, steps: float) -> None:
        """Positive steps move closer, by 10 % each."""
        self.scale = float(np.clip(self.scale * 0.9**steps, 0.2, 5.0))

    def eye(self, aspect: float) -> np.ndarray:
        cp = math.cos(self.pitch)
        d = np.array([math.sin(self.yaw) * cp, math.sin(self.pitch), math.cos(self.yaw) * cp])
        return self.target + self.distance(aspect) * d

    def matrices(self, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        """(view, projection) for a viewport of this aspect ratio (width / height)."""
        dist = self.distance(aspect)
        view = look_at(self.eye(aspect), self.target, np.array([0.0, 1.0, 0.0]))
        near = max(dist - 3.0 * self.radius, 0.05 * dist)
        far = dist + 3.0 * self.radius
        return view, perspective(self.fov_y, aspect, near, far)
