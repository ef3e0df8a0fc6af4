"""A fit on the simulator itself: parameters whose settled pose is closest to a target displacement.

The other fits (`sim.fit.solve`, `sim.face.scan.calibrate`) linearise about the rest pose and
correct by offsets; a settled pose far from rest answers a change of its inputs 2-3 times further,
and in another direction, than the rest's statics say (docs/scan-face.md, "Active strain"). Here
every derivative is taken where the face is: Levenberg-Marquardt (Levenberg 1944, Marquardt 1963)
on the residual r(x) = settle(values(x)) - rest - target over the skin, whose Jacobian column j
is the chord (settle(values(x + h e_j)) - settle(values(x))) / h of two *settled* poses about the
current one, each perturbed pose settled from the current settled state. Between full Jacobians
the columns are carried by Broyden's rank-one secant update (Broyden 1965) from each step's
observed change of the residual, so a round costs one settle per step and a full Jacobian
every `refresh` rounds.

The step solves min |J dx + r|^2 + mu |D dx|^2 within the bounds lo <= x + dx <= hi (D the
columns' norms, Marquardt's scaling), and is kept only if the settled misfit falls; otherwise mu
grows tenfold. Settling is tighter than `Simulator.settle`'s (a chord of a 0.05 step must not be
the settling's own noise): `SETTLE_SPEED` here is half the simulator's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear

from sim.fit.basis import Settler

SETTLE_SPEED = 0.01  # cm/s: the fastest vertex when a pose counts as settled here
MAX_SECONDS = 8.0
MIN_SECONDS = 0.2


@dataclass
class SettledFit:
    """x: the fitted parameters; error: |r| / |target| at x (settled from rest, as a user sees it);
    history: (settles so far, relative error) after each accepted step; settles: the poses settled."""

    x: np.ndarray
    error: float
    history: list[tuple[int, float]] = field(default_factory=list)
    settles: int = 0


def settle_tight(settler: Settler, values: np.ndarray, start: object) -> object:
    """The face settled under `values` from `start` (a FaceState, not changed) until no vertex
    moves faster than SETTLE_SPEED; returns the settled state."""
    state = start.copy()  # type: ignore[attr-defined]
    state.velocities[...] = 0.0
    settler.control.values[...] = values
    sim = settler.sim
    limit = max(1, int(round(MAX_SECONDS / sim.frame_dt)))
    for frame in range(1, limit + 1):
        sim.step(state, settler.control)
        speed = float(np.sqrt(np.max(np.sum(state.velocities**2, axis=1))))
        if frame * sim.frame_dt >= MIN_SECONDS and speed < SETTLE_SPEED:
            break
    settler.settles += 1
    return state


def fit_settled(settler: Settler, values: Callable[[np.ndarray], np.ndarray], target: np.ndarray,
                x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, rounds: int = 8, h: float = 0.05,
                refresh: int = 3, ridge: float = 1e-3, sparsity: np.ndarray | None = None,
                log: Callable[[str], None] | None = None) -> SettledFit:
    """Levenberg-Marquardt on settled poses. values(x) -> a full channel array; target (N, 3) the
    wanted displacement from the settled rest (cm); x0, lo, hi (P,) the start and the bounds.
    ridge: a pull of every step towards no change, relative to the mean column energy (keeps the
    parameters the target does not see where they are). sparsity (P,): an L1 cost per parameter
    (x >= 0 where it is set), relative to the target's energy: a parameter at 1 must take that
    much off the squared relative error to be worth it."""
    norm = float(np.linalg.norm(target))

    def residual(x: np.ndarray, start: object) -> tuple[np.ndarray, object]:
        state = settle_tight(settler, values(x), start)
        return (state.positions - settler.rest - target).ravel(), state  # type: ignore[attr-defined]

    l1 = None if sparsity is None else np.asarray(sparsity, float) * norm**2
    return levenberg_settled(settler, residual, settler.rest_state, x0, lo, hi, norm=norm, rounds=rounds,
                             h=h, refresh=refresh, ridge=ridge, l1=l1, log=log)


def levenberg_settled(settler: Settler, residual: Callable[[np.ndarray, object], tuple[np.ndarray, object]],
                      start: object, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, norm: float,
                      rounds: int = 8, h: float = 0.05, refresh: int = 3, ridge: float = 1e-3,
                      l1: np.ndarray | None = None, log: Callable[[str], None] | None = None) -> SettledFit:
    """The Levenberg-Marquardt of `fit_settled` on any settled residual: residual(x, start) ->
    (r, state), r the misfit of the pose(s) settled under parameters x from `start` (what a
    previous call returned: the perturbed poses of a Jacobian column settle from the current
    ones). norm: |r| is reported relative to it; l1 (P,): the absolute L1 cost per parameter."""
    x = np.clip(np.asarray(x0, float), lo, hi)
    l1 = np.zeros(x.size) if l1 is None else np.asarray(l1, float)

    def cost(res: np.ndarray, at: np.ndarray) -> float:
        return float(res @ res) + 2.0 * float(l1 @ at)

    r, state = residual(x, start)
    out = SettledFit(x.copy(), float(np.linalg.norm(r)) / norm)
    out.history.append((settler.settles, out.error))
    jac: np.ndarray | None = None
    mu, since = 1e-2, refresh
    for _ in range(rounds):
        if jac is None or since >= refresh:
            jac = np.empty((r.size, x.size))
            for j in range(x.size):
                step = h if x[j] + h <= hi[j] else -h if x[j] - h >= lo[j] else (
                    hi[j] - x[j] if hi[j] - x[j] >= x[j] - lo[j] else lo[j] - x[j])  # a range narrower than h
                if step == 0.0:
                    jac[:, j] = 0.0
                    continue
                xj = x.copy()
                xj[j] += step
                jac[:, j] = (residual(xj, state)[0] - r) / step
            since = 0
        scale = np.sqrt(np.sum(jac * jac, axis=0)) + 1e-12
        energy = float(np.mean(scale**2))
        accepted = False
        while mu < 1e6:
            damp = np.sqrt(mu * scale**2 + ridge * energy)
            a = np.vstack([jac, np.diag(damp)])
            b = np.concatenate([-r, np.zeros(x.size)])
            if np.any(l1):  # + 2 l1.dx folded into the right-hand side (a has full column rank)
                b = b - a @ np.linalg.solve(a.T @ a, l1)
            dx = lsq_linear(a, b, bounds=(lo - x, hi - x)).x
            if np.max(np.abs(dx)) < 1e-4:
                break
            r2, trial = residual(x + dx, state)
            jac += np.outer((r2 - r) - jac @ dx, dx) / float(dx @ dx)  # Broyden's secant update
            if cost(r2, x + dx) < cost(r, x):
                x, r, state = x + dx, r2, trial
                mu = max(mu / 3.0, 1e-4)
                accepted = True
                break
            mu *= 10.0
        since += 1
        if not accepted:
            if since == 1:  # a fresh Jacobian and no step helps: a local minimum
                break
            since = refresh
            continue
        out.x, out.error = x.copy(), float(np.linalg.norm(r)) / norm
        out.history.append((settler.settles, out.error))
        if log:
            log(f"  {settler.settles:4d} settles: {out.error:.3f}  " + " ".join(f"{v:.2f}" for v in x))
    out.settles = settler.settles
    return out
