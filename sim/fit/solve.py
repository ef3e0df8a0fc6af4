"""The per-frame fit: channel activations that explain observed skin displacement.

Method (stated, since the issue leaves the choice to us):

1. **Alignment.** Frame t's points X_t are mapped by a similarity (Procrustes, `sim.fit.align`)
   onto the reference plus the displacement the fit predicts for that frame, alternating twice
   (align, fit, align again), so an expression is not mistaken for head motion. The reference is
   the rig's settled rest at the observed vertices (`neutral=None`, a capture of the rig itself)
   or the neutral frame mapped onto the rig by one similarity (a capture of someone else: their
   face shape differs from the rig's, so only motion relative to their own neutral is fitted).
2. **Bounded least squares per frame** on the simulator-built basis B (`sim.fit.basis`):
   min |B a - d|^2 + lambda |a - p|^2 + 2 mu sum(a) + eps |a|^2, 0 <= a <= hi. p is the previous
   frame's solution on the first pass (warm start, causal smoothing) and the mean of both
   neighbours on the second (smoothing without lag); mu is an L1 penalty (a >= 0, so it is linear)
   that keeps noise out of channels the motion does not need; its shrinkage of the active values is
   then removed by solving again without it on the active set only. lambda, mu and eps are relative
   to the mean column energy of B at the observed points, so they mean the same for 20 points or
   800. Solved exactly as a bounded linear least-squares problem on the Cholesky factor of the
   normal matrix (scipy `lsq_linear`, BVLS).
3. **Re-linearisation where the channels interact.** Channels do not add linearly (biphasic
   springs, the jaw). Where a frame's relative misfit |B a - d| / |d| stays above a threshold, the
   simulator settles the solved pose and the fit is repeated with the difference between that
   true pose and the linear prediction taken off the data (a chord / fixed-point step around the
   current pose). Settled poses are cached on a grid of `quantum` in activation, and at most
   `max_settles` are made per fit, so a long take costs a bounded number of settles.

Each frame gets a report: residual (RMS distance, mm) between the fitted and the observed points,
the relative misfit, the active channels, the condition number of the basis restricted to them,
and the alignment's scale and rotation.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import lsq_linear

from sim.fit.align import Similarity, rms, similarity
from sim.fit.basis import Basis, Settler


INVISIBLE = 1e-3  # a basis column this small relative to the largest: the channel is not seen
STILL_CM = 1e-6  # a displacement norm below this is no motion (misfit is 0, not 0/0)


@dataclass
class FitOptions:
    """smooth: temporal prior weight; sparsity: L1 weight; ridge: tiny Tikhonov term (all relative
    to the mean column energy); active: the activation above which a channel counts as active;
    relinearise: the relative misfit above which a frame is re-linearised (None: never), only if
    its residual exceeds min_mm, at most `iterations` times; align: "similarity", "rigid" or "none"."""

    smooth: float = 0.02
    sparsity: float = 0.004
    ridge: float = 1e-4
    active: float = 0.05
    relinearise: float | None = 0.08
    min_mm: float = 0.3
    max_settles: int = 40
    quantum: float = 0.1
    iterations: int = 3
    align: str = "similarity"


@dataclass
class Track:
    """An observation: times (T,) s ascending; points (T, P, 3) in any units and frame;
    vertices (P,) the rig vertex each point corresponds to; neutral: the frame showing the
    performer at rest, or None when the points are the rig's own skin (compare with its rest)."""

    times: np.ndarray
    points: np.ndarray
    vertices: np.ndarray
    neutral: int | None = 0


@dataclass
class FrameReport:
    time: float
    residual_mm: float
    misfit: float
    active: tuple[str, ...]
    condition: float
    relinearised: bool
    scale: float
    rotation_degrees: float


@dataclass
class FitResult:
    """channels (K,); activations (T, K); displacements (T, P, 3) observed after alignment, cm
    (what recognition matches); reports per frame; neutral: the similarity taking the neutral
    frame onto the rig (None for the rig's own skin) and neutral_rms_mm what it leaves (the shape
    difference between the performer and the rig); settles: poses settled for re-linearisation."""

    channels: tuple[str, ...]
    times: np.ndarray
    activations: np.ndarray
    displacements: np.ndarray
    vertices: np.ndarray
    reports: list[FrameReport]
    neutral: Similarity | None
    neutral_rms_mm: float
    condition: float
    settles: int = 0
    scales: np.ndarray = field(default_factory=lambda: np.zeros(0))
    invisible: tuple[str, ...] = ()


class _Problem:
    """The normal equations of one point set, factored once, over the channels that move at
    least one of the points (the others cannot be fitted and stay at 0)."""

    def __init__(self, basis: Basis, vertices: np.ndarray, opts: FitOptions) -> None:
        self.A = basis.matrix(vertices)
        self.k = self.A.shape[1]
        norms = np.linalg.norm(self.A, axis=0)
        self.visible = norms > INVISIBLE * max(float(norms.max()), 1e-12)
        self.vis = np.flatnonzero(self.visible)
        av = self.A[:, self.vis]
        g0 = av.T @ av
        s = float(np.trace(g0)) / max(1, len(self.vis))
        self.lam = opts.smooth * s
        self.mu = opts.sparsity * s
        self.g = g0 + (self.lam + opts.ridge * s) * np.eye(len(self.vis))
        self.active = opts.active
        self.chol = np.linalg.cholesky(self.g) if len(self.vis) else np.zeros((0, 0))
        self.lt = self.chol.T.copy()
        self.av = av
        self.hi = basis.hi[self.vis]
        self.condition = float(np.linalg.cond(av)) if len(self.vis) else float("inf")
        self._cond: dict[tuple[int, ...], float] = {}

    def solve(self, d: np.ndarray, prior: np.ndarray) -> np.ndarray:
        """The bounded solution with the L1 term (which picks the active set), then the same
        problem without it on that set only (the L1 term's shrinkage of the active values is a
        bias, not information: a "relaxed lasso"). Returns all K channels."""
        full = np.zeros(self.k)
        if not len(self.vis):
            return full
        atd = self.av.T @ d
        p = prior[self.vis]
        rhs = solve_triangular(self.chol, atd + self.lam * p - self.mu, lower=True)
        a = np.clip(lsq_linear(self.lt, rhs, bounds=(0.0, self.hi), method="bvls").x, 0.0, self.hi)
        if self.mu > 0.0:
            act = np.flatnonzero(a > self.active)
            a = np.zeros_like(a)
            if len(act):
                chol = np.linalg.cholesky(self.g[np.ix_(act, act)])
                r = solve_triangular(chol, atd[act] + self.lam * p[act], lower=True)
                sub = lsq_linear(chol.T, r, bounds=(0.0, self.hi[act]), method="bvls").x
                a[act] = np.clip(sub, 0.0, self.hi[act])
        full[self.vis] = a
        return full

    def cond(self, active: tuple[int, ...]) -> float:
        if not active:
            return 1.0
        if active not in self._cond:
            sv = np.linalg.svd(self.A[:, list(active)], compute_uv=False)
            self._cond[active] = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
        return self._cond[active]


class Fitter:
    """Fits tracks against one basis; `settler` (the same model's) enables re-linearisation."""

    def __init__(self, basis: Basis, settler: Settler | None = None, options: FitOptions | None = None) -> None:
        self.basis = basis
        self.settler = settler
        self.opts = options or FitOptions()
        self._poses: dict[tuple[int, ...], tuple[np.ndarray, object]] = {}
        self._full_index = None
        if settler is not None:
            from sim.channels import CHANNEL_INDEX

            self._full_index = np.array([CHANNEL_INDEX[c] for c in basis.channels])

    # -- alignment -------------------------------------------------------------------------
    def _reference(self, track: Track) -> tuple[np.ndarray, Similarity | None, float]:
        rest = self.basis.rest[track.vertices]
        if track.neutral is None:
            return rest, None, 0.0
        x0 = track.points[track.neutral]
        if self.opts.align == "none":
            return x0, None, 0.0
        t0 = similarity(x0, rest, scale=self.opts.align == "similarity")
        ref = t0.apply(x0)
        return ref, t0, rms(ref, rest) * 10.0

    def _align(self, x: np.ndarray, target: np.ndarray, base_scale: float) -> tuple[np.ndarray, float, float]:
        if self.opts.align == "none":
            return x, 1.0, 0.0
        t = similarity(x, target, scale=self.opts.align == "similarity")
        return t.apply(x), t.scale / base_scale, t.angle_degrees

    # -- the fit ---------------------------------------------------------------------------
    def fit(self, track: Track) -> FitResult:
        settles0 = self.settler.settles if self.settler else 0
        pts = np.asarray(track.points, float)
        n_frames = pts.shape[0]
        verts = np.asarray(track.vertices, int)
        prob = _Problem(self.basis, verts, self.opts)
        k = len(self.basis.channels)
        ref, t0, neutral_mm = self._reference(track)
        base_scale = t0.scale if t0 is not None else 1.0
        disp = np.empty((n_frames, len(verts), 3))
        acts = np.zeros((n_frames, k))
        scales = np.ones(n_frames)
        angles = np.zeros(n_frames)
        prev = np.zeros(k)
        for t in range(n_frames):  # pass 1: align against the prediction, warm-started
            a = prev
            for _ in range(2):
                target = ref + self.basis.predict(a, verts)
                aligned, scales[t], angles[t] = self._align(pts[t], target, base_scale)
                d = (aligned - ref).ravel()
                a = prob.solve(d, prev)
            disp[t] = (aligned - ref)
            acts[t] = prev = a
        acts = self._second_pass(prob, disp, acts)
        offsets = np.zeros((n_frames, len(verts), 3))
        relin = np.zeros(n_frames, bool)
        if self.settler is not None and self.opts.relinearise is not None:
            acts, offsets, relin = self._relinearise(prob, disp, acts, verts)
        reports = []
        for t in range(n_frames):
            pred = self.basis.predict(acts[t], verts) + offsets[t]
            res = disp[t] - pred
            res_mm = float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) * 10.0
            norm = float(np.linalg.norm(disp[t]))
            misfit = float(np.linalg.norm(res) / norm) if norm > STILL_CM else 0.0
            active = tuple(int(i) for i in np.flatnonzero(acts[t] > self.opts.active))
            reports.append(FrameReport(float(track.times[t]), res_mm, misfit,
                                       tuple(self.basis.channels[i] for i in active), prob.cond(active),
                                       bool(relin[t]), float(scales[t]), float(angles[t])))
        return FitResult(self.basis.channels, np.asarray(track.times, float), acts, disp, verts, reports, t0,
                         neutral_mm, prob.condition, (self.settler.settles - settles0) if self.settler else 0, scales,
                         tuple(c for c, v in zip(self.basis.channels, prob.visible) if not v))

    def _second_pass(self, prob: _Problem, disp: np.ndarray, acts: np.ndarray,
                     offsets: np.ndarray | None = None, frames: np.ndarray | None = None) -> np.ndarray:
        """Smoothing without lag: the prior is the mean of each frame's neighbours (all frames,
        or only `frames`)."""
        n = len(acts)
        out = acts.copy()
        for t in (range(n) if frames is None else frames):
            nb = [acts[j] for j in (t - 1, t + 1) if 0 <= j < n]
            prior = np.mean(nb, axis=0) if nb else acts[t]
            d = disp[t] if offsets is None else disp[t] - offsets[t]
            out[t] = prob.solve(d.ravel(), prior)
        return out

    def _relinearise(self, prob: _Problem, disp: np.ndarray, acts: np.ndarray,
                     verts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Up to `iterations` chord steps on the frames whose misfit stays high; a step is kept
        only where it explains the data better (the data minus the settled correction)."""
        opts = self.opts
        assert self.settler is not None and opts.relinearise is not None
        n = len(acts)
        offsets = np.zeros_like(disp)
        relin = np.zeros(n, bool)
        for _ in range(opts.iterations):
            cand = offsets.copy()
            todo = []
            for t in range(n):
                res = disp[t] - offsets[t] - self.basis.predict(acts[t], verts)
                norm = float(np.linalg.norm(disp[t]))
                res_mm = float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) * 10.0
                if norm <= STILL_CM or res_mm < opts.min_mm or np.linalg.norm(res) / norm < opts.relinearise:
                    continue
                off = self._offset(acts[t])
                if off is None:
                    continue
                cand[t] = off[verts]
                todo.append(t)
            if not todo:
                break
            new = self._second_pass(prob, disp, acts, cand, np.array(todo))
            improved = False
            for t in todo:
                before = np.linalg.norm(disp[t] - offsets[t] - self.basis.predict(acts[t], verts))
                after = np.linalg.norm(disp[t] - cand[t] - self.basis.predict(new[t], verts))
                if after < before:
                    acts[t], offsets[t], relin[t] = new[t], cand[t], True
                    improved = True
            if not improved:
                break
        return acts, offsets, relin

    def _offset(self, a: np.ndarray) -> np.ndarray | None:
        """True settled displacement minus the linear prediction at the pose nearest `a` on the
        grid (all vertices), settling it if the budget allows, else the nearest cached pose within
        one grid step; None if there is none."""
        q = self.opts.quantum
        key = tuple(int(v) for v in np.round(a / q))
        if key not in self._poses:
            if self.settler is None:
                return None
            if len(self._poses) >= self.opts.max_settles:
                best, dist = None, np.inf
                for kk in self._poses:
                    dd = max(abs(x - y) for x, y in zip(kk, key))
                    if dd < dist:
                        best, dist = kk, dd
                if best is None or dist > 1:
                    return None
                key = best
            else:
                aq = np.array(key, float) * q
                aq = np.clip(aq, 0.0, self.basis.hi)
                values = self.settler.defaults.copy()
                values[self._full_index] = aq
                start = None
                if self._poses:
                    near = min(self._poses, key=lambda kk: sum(abs(x - y) for x, y in zip(kk, key)))
                    start = self._poses[near][1]
                pos = self.settler.pose(values, start)
                off = pos - self.basis.rest - self.basis.predict(aq)
                self._poses[key] = (off, self.settler.last_state)
        return self._poses[key][0]
