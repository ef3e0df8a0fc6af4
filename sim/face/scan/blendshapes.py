"""Still poses of the scanned head from its own shapes: neutral + identity + weighted expression
shapes (`neutral + identities.T @ w_id + expressions.T @ w_expr`, the toolkit's linear model).
The scan's own expressions are the reference the simulated face is compared with (same camera,
same light, `docs/make_gallery.py`)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from sim.face.scan.data import scan_data


class StateControl:
    """What a dressing reads besides the surface (`get(name)`), taken from a drawn or exported
    state: its channel values when it carries a control, else the jaw and the eyes' yaw, pitch and
    vergence that every FaceState keeps from its last step."""

    _FIELDS = {"eyes_yaw": "eye_yaw", "eyes_pitch": "eye_pitch", "eyes_vergence": "eye_vergence"}

    def __init__(self, state: object) -> None:
        self.state = state

    def get(self, name: str) -> float:
        ctrl = getattr(self.state, "control", None)
        if ctrl is not None:
            return float(ctrl.get(name))
        return float(getattr(self.state, self._FIELDS.get(name, name), 0.0))


class ScanShapes:
    """A scan pose that ignores the simulation: `pose(surface, control)` gives the same (26719, 3)
    float32 positions every call (the renderer's dressing interface)."""

    def __init__(self, identity: np.ndarray | None = None, expressions: Mapping[str, float] | None = None) -> None:
        d = scan_data()
        p = d.neutral.copy()
        if identity is not None and len(identity):
            p += d.identity_delta(np.asarray(identity, np.float64))
        self.rest = p.astype(np.float32)  # the head at rest, for what is baked from it
        for name, w in (expressions or {}).items():
            if name not in d.expression_names:
                raise ValueError(f"unknown scan expression {name!r}; known: {', '.join(d.expression_names)}")
            p += float(w) * d.expression(name)
        self.positions = p.astype(np.float32)

    def pose(self, surface: np.ndarray, control: object) -> np.ndarray:
        return self.positions

    def pose_turned(self, surface: np.ndarray, control: object, state: object) -> np.ndarray:
        """The same pose: the scan's own shapes do not turn the head."""
        return self.positions
