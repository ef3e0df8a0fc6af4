"""The rig's own muscles fitted on settled poses: insertion gains over smooth bumps, every shape at once.

`sim.fit.settled` fits channel values; here the parameters are the rig's: for each fitted muscle a
gain on each of a few smooth bumps over its zone (a partition of unity, so all gains 1 is the rig as
it is; a muscle's strength is its gains moved together), multiplying the insertion it already has.
The right side's bumps mirror the left's and share their gains, so a fit on the left and unsided
shapes can be checked on the right ones. The step is linear in a muscle's force, and the implicit
step adds each active channel's response (A^-1 of its field, `sim.implicit.muscle_responses`) times
its activation; so a bump's response is solved once with the step's own factors and a gain change
rewrites the channel's response in the running simulator (no recompile, no refactorisation). Each
Jacobian column then settles every shape again from its current settled pose, and the residual of a
shape is its misfit relative to its own size, so the objective is the sum over the shapes of the
squared relative error (what `benchmarks/scan_match.py` reports per shape).

`insertion(x)` gives the per-vertex gains a rig file stores (`FaceRig.insertion`), the product of
the shipped ones and the fitted bumps.

`SkinBumps` / `fit_skin_settled` do the same for the skin's fields (`FaceRig.skin`) about chosen
points; those change the step's matrix, so every parameter vector is a rig compiled again.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from sim.fit.basis import Settler
from sim.fit.settled import SettledFit, levenberg_settled, settle_tight

MIRROR = np.array([-1.0, 1.0, 1.0])  # the face's left-right mirror (x -> -x)


def bumps(points: np.ndarray, zone: np.ndarray, n: int, centres: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(B, N) Gaussian bumps normalised to a partition of unity over the zone's vertices (zero
    elsewhere), about `centres` or n centres spread over the zone by farthest-point sampling; and
    the centres."""
    idx = np.flatnonzero(zone)
    p = points[idx]
    if centres is None:
        chosen = [int(np.argmin(np.linalg.norm(p - p.mean(axis=0), axis=1)))]
        d = np.linalg.norm(p - p[chosen[0]], axis=1)
        for _ in range(min(n, len(idx)) - 1):
            chosen.append(int(np.argmax(d)))
            d = np.minimum(d, np.linalg.norm(p - p[chosen[-1]], axis=1))
        centres = p[chosen]
    cd = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.eye(len(centres)) * 1e9
    sigma = max(0.6 * float(np.median(cd.min(axis=1))), 0.05) if len(centres) > 1 else 1.0
    w = np.exp(-np.sum((p[None] - centres[:, None]) ** 2, axis=2) / (2 * sigma**2))
    w /= np.maximum(w.sum(axis=0), 1e-300)
    out = np.zeros((len(centres), len(points)))
    out[:, idx] = w
    return out, centres


def mirrored_bumps(points: np.ndarray, zone: np.ndarray, n: int) -> np.ndarray:
    """(n, N) bumps over a zone that straddles the midline, each the sum of a bump about a centre
    on the left half (x >= 0, farthest-point sampled) and one about its mirror image: a partition
    of unity whose every member is mirror-symmetric, so a left shape's fit moves the right side
    as the left."""
    left = zone & (points[:, 0] >= 0.0)
    _, centres = bumps(points, left, n)
    phi, _ = bumps(points, zone, 2 * n, np.concatenate([centres, centres * MIRROR]))
    return phi[:n] + phi[n:]


@dataclass
class Pose:
    """One shape of the fit: its channel values and the wanted displacement (N, 3) from rest (cm)."""

    label: str
    values: np.ndarray
    target: np.ndarray


class InsertionBumps:
    """Gains on bumps over the zones of `groups` (a muscle's name without its side: both sides share
    the gains, mirrored), applied to `settler`'s running implicit simulator."""

    def __init__(self, settler: Settler, groups: Sequence[str], per_group: int = 4) -> None:
        model = settler.model
        stepper = settler.sim._implicit  # type: ignore[attr-defined]
        if stepper is None:
            raise ValueError("the settled rig fit needs the implicit integrator")
        self.settler, self.stepper = settler, stepper
        stepper._resp = np.array(stepper._resp)  # this simulator's own copy: the shared one stays
        self.base_resp = stepper._resp.copy()
        rest = np.asarray(model.rest)
        n = len(rest)
        mm = model.muscle_matrix
        indptr, indices, data = (np.asarray(a) for a in (mm.indptr, mm.indices, mm.data))
        rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        free = np.asarray(stepper.prepared["free"])
        self.phi: dict[str, np.ndarray] = {}  # channel -> (B, N)
        self.resp: dict[str, np.ndarray] = {}  # channel -> (B, free, 3)
        self.offset: dict[str, int] = {}
        self.channels: list[str] = []
        k = 0
        for g in groups:
            sides = [c for c in (g + "_l", g + "_r") if c in model.channel_index] or [g]
            centres = None
            for ch in sides:
                c = model.channel_index[ch]
                f = np.zeros(3 * n)
                on = indices == c
                np.add.at(f, rows[on], data[on])
                f = f.reshape(n, 3)
                mag = np.linalg.norm(f, axis=1)
                if not mag.any():
                    raise ValueError(f"{ch} has no force field to fit")
                zone = mag > 1e-3 * mag.max()
                if len(sides) == 1:  # one muscle across the midline: each bump paired with its mirror image
                    phi = mirrored_bumps(rest, zone, per_group)
                else:
                    phi, found = bumps(rest, zone, per_group, None if centres is None else centres * MIRROR)
                    centres = found if centres is None else centres
                resp = np.zeros((len(phi), len(free), 3))
                for b in range(len(phi)):
                    stepper.solver.solve(np.ascontiguousarray((phi[b][:, None] * f)[free]), resp[b])
                self.phi[ch], self.resp[ch] = phi, resp
                self.offset[ch] = k
                self.channels.append(ch)
            k += per_group
        self.n_params = k
        self.names = [f"{g}:{b}" for g in groups for b in range(per_group)]

    def apply(self, x: np.ndarray) -> None:
        """The running simulator's responses for gains x (all 1: the rig as it is)."""
        for ch in self.channels:
            o = self.offset[ch]
            g = x[o:o + len(self.phi[ch])]
            self.stepper._resp[self.settler.model.channel_index[ch]] = np.tensordot(g, self.resp[ch], axes=1)

    def restore(self) -> None:
        self.stepper._resp[...] = self.base_resp

    def insertion(self, x: np.ndarray, shipped: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Per fitted channel the (N,) insertion gain a rig stores: the shipped gain (1 where the rig
        has none) times the fitted bumps' sum."""
        out = {}
        for ch in self.channels:
            o = self.offset[ch]
            fitted = self.phi[ch].T @ x[o:o + len(self.phi[ch])]
            zone = self.phi[ch].sum(axis=0) > 0
            base = np.asarray(shipped.get(ch, np.ones(len(fitted))), np.float64)
            out[ch] = np.where(zone, base * fitted, base)
        return out


def fit_rig_settled(settler: Settler, rig: InsertionBumps, poses: Sequence[Pose], x0: np.ndarray,
                    lo: np.ndarray, hi: np.ndarray, *, rounds: int = 6, h: float = 0.1, refresh: int = 3,
                    ridge: float = 1e-3, log: Callable[[str], None] | None = None,
                    weights: Sequence[float] | None = None) -> SettledFit:
    """Levenberg-Marquardt (`sim.fit.settled.levenberg_settled`) of the rig's bump gains over every
    pose at once. weights: each pose's weight on its squared relative error (1 each; a pose held
    where it is, a preset, may weigh otherwise). SettledFit.error: the root mean square of the
    poses' weighted relative errors."""
    w = np.ones(len(poses)) if weights is None else np.asarray(weights, float)
    norms = [float(np.linalg.norm(p.target)) / np.sqrt(wi) for p, wi in zip(poses, w)]

    def residual(x: np.ndarray, start: object) -> tuple[np.ndarray, object]:
        rig.apply(x)
        states, parts = [], []
        for p, s0, nrm in zip(poses, start, norms):  # type: ignore[call-overload]
            st = settle_tight(settler, p.values, s0)
            states.append(st)
            parts.append((st.positions - settler.rest - p.target).ravel() / nrm)
        return np.concatenate(parts), states

    starts = [settler.rest_state] * len(poses)
    try:
        return levenberg_settled(settler, residual, starts, x0, lo, hi, norm=float(np.sqrt(np.sum(w))),
                                 rounds=rounds, h=h, refresh=refresh, ridge=ridge, log=log)
    finally:
        rig.restore()


def relative_errors(settler: Settler, rig: InsertionBumps, poses: Sequence[Pose], x: np.ndarray) -> dict[str, float]:
    """Each pose settled from rest under gains x by the simulator's own settling (as
    `benchmarks/scan_match.py` measures): {label: relative RMS error}."""
    rig.apply(x)
    try:
        out = {}
        for p in poses:
            d = settler.pose(p.values) - settler.rest - p.target
            out[p.label] = float(np.sqrt(np.sum(d * d) / np.sum(p.target * p.target)))
        return out
    finally:
        rig.restore()


class SkinBumps:
    """The skin's fields (`FaceRig.skin`: tether, support, modulus) scaled by exp(sum of theta_b
    phi_b) over smooth Gaussian bumps (width `sigma` cm, about `centres`, mirror pairs sharing a
    parameter): theta 0 is the rig as it is. The step's matrix changes with them, so each parameter
    vector is a rig compiled and prepared again (a few seconds) and its rest settled (a caller that
    does not want those trial faces in the face cache turns its store off: `sim.prepared.use_store`)."""

    def __init__(self, model: object, centres: Sequence[np.ndarray], fields: Sequence[str] = ("tether", "modulus"),
                 sigma: float = 0.8, method: str = "auto") -> None:
        self.model, self.method = model, method
        rest = np.asarray(model.rest)  # type: ignore[attr-defined]
        self.phi = np.array([sum(np.exp(-np.sum((rest - c) ** 2, axis=1) / (2 * sigma**2)) for c in pair)
                             for pair in centres])
        self.fields = tuple(fields)
        self.n_params = len(self.fields) * len(self.phi)
        self.names = [f"{f}:{b}" for f in self.fields for b in range(len(self.phi))]
        self._memo: dict[bytes, Settler] = {}

    def skin(self, x: np.ndarray) -> dict[str, np.ndarray]:
        rig = self.model.rig  # type: ignore[attr-defined]
        n = len(self.phi[0])
        out = {name: np.asarray(rig.skin.get(name, np.ones(n)), np.float64) for name in rig.skin}
        for k, name in enumerate(self.fields):
            theta = x[k * len(self.phi):(k + 1) * len(self.phi)]
            out[name] = np.asarray(rig.skin.get(name, np.ones(n)), np.float64) * np.exp(theta @ self.phi)
        return out

    def settler(self, x: np.ndarray) -> Settler:
        from dataclasses import replace

        from sim.build import compile_model

        key = np.round(x, 6).tobytes()
        if key not in self._memo:
            if len(self._memo) >= 4:
                self._memo.pop(next(iter(self._memo)))
            m = self.model
            self._memo[key] = Settler(compile_model(replace(m.rig, skin=self.skin(x)), m.params),  # type: ignore[attr-defined]
                                      method=self.method)
        return self._memo[key]


def fit_skin_settled(skin: SkinBumps, poses: Sequence[Pose], x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, *,
                     rounds: int = 6, h: float = 0.1, refresh: int = 3, ridge: float = 1e-3,
                     log: Callable[[str], None] | None = None) -> SettledFit:
    """Levenberg-Marquardt of the skin's bump parameters over every pose at once, each pose settled
    on the rig compiled with them, from the pose settled before (the same vertices)."""
    norms = [float(np.linalg.norm(p.target)) for p in poses]

    class Count:
        settles = 0

    count = Count()

    def residual(x: np.ndarray, start: object) -> tuple[np.ndarray, object]:
        s = skin.settler(x)
        states, parts = [], []
        for p, s0, nrm in zip(poses, start, norms):  # type: ignore[call-overload]
            st = settle_tight(s, p.values, s0 if s0 is not None else s.rest_state)
            states.append(st)
            parts.append((st.positions - s.rest - p.target).ravel() / nrm)
        count.settles += len(poses)
        return np.concatenate(parts), states

    return levenberg_settled(count, residual, [None] * len(poses), x0, lo, hi,  # type: ignore[arg-type]
                             norm=float(np.sqrt(len(poses))), rounds=rounds, h=h, refresh=refresh, ridge=ridge, log=log)
