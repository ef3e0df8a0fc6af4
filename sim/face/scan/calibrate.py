"""Calibration of the scanned head's muscles against the scanned expressions.

What the physics leaves free is fitted to the scans: how densely each muscle inserts into the skin
over its zone (and so its strength), and how far the gaze carries the lids. Each muscle keeps its
direction of pull (towards its origin, the sphincter's centre, the sheet's direction); its field is
multiplied by a non-negative insertion gain g(x) = sum_b g_b phi_b(x) over a dozen smooth bumps
phi_b (a partition of unity over the muscle's zone), stored per skin vertex in the rig
(`FaceRig.insertion`). The two sides share their gains (the right bumps are the mirrored left ones).

In the small-motion regime the settled displacement is linear in the gains: u = K^-1 f, K the
skin's stiffness at rest (springs at their low modulus, tethers, normal support; held skin fixed),
so one sparse factorisation and one solve per bump give every column. The fit is a non-negative
least squares over all scanned shapes at once (each shape weighted by its own size, so a small
shape counts as much as a big one), with a pull towards gain 1 (the placed muscle) that keeps the
bumps from trading against each other. The gaze's share of the lids (the scan's lids follow
eyeLookUp/Down: the levator's tone follows the gaze) is fitted in turn, with the gains fixed.
Then the real simulator re-linearises: each shape is settled with the fitted gains, what the
linear model missed (the jaw, contact with the eyes, the skin's stiffening) is kept as an offset,
and the gains are fitted again.

    nice .venv/bin/python benchmarks/calibrate_scan.py [--rounds 2] [--holdout] [--no-write]

(the driver: it reads the scan's shapes and the channels the ARKit import gives each, which this
module, like all of `sim`, knows nothing of) writes `ict_rig.npz` (the insertion gains, `shipped`:
not for the muscles under which skin folded) and prints the gaze shares for
`puppet/maps/arkit.toml` and `puppet/export/arkit.py`.
"""

from __future__ import annotations

from typing import Any

import time
from dataclasses import dataclass, replace

import numpy as np

from sim.fit.rig_settled import bumps as _bumps  # the scan fits' bumps, written once

BUMPS = 12
PULL = 1e-3  # weight of the pull towards gain 1 (per gain), relative to one shape's own size
MAX_GAIN = 8.0
STILL_CM = 0.03  # a scan shape moving the skin less than this (RMS) is not fitted
# What ships is the fit, but for the lips' patches and incisivus, the upper lip's elevators, the
# mentalis and the levator palpebrae, which keep gain 1: fitted, compressed skin turned over under
# them (disgust 3.0 cm2, the incisivus 2.8, the lips' shift 2.9; limits in tests/sim/
# test_scan_face.py KNOWN_FOLDS). With them left out, anger folds 0.46 (1.4 before), disgust 0.71
# (1.0), the corrugator 0.34 (0.85); the fitted frontalis and zygomaticus fold surprise 0.27 (0.14)
# and happiness 0.22 (0.2).
SHIPPED_SHARE = 1.0
NOT_SHIPPED = ("incisivus", "orbicularis_oris_peripheralis_upper", "orbicularis_oris_peripheralis_lower",
               "orbicularis_oris_marginalis_upper", "orbicularis_oris_marginalis_lower", "lip_closure", "lip_lift",
               "mouth_shift", "platysma", "levator_labii", "levator_labii_alaeque_nasi", "levator_palpebrae", "mentalis",
               "orbicularis_oculi_lid")  # the fitted lid strip no longer closed the lids over the eyes


def shipped(insertion: dict[str, np.ndarray], not_shipped: tuple[str, ...] = NOT_SHIPPED) -> dict[str, np.ndarray]:
    """The insertion gains that ship: each channel's fitted gain g taken SHIPPED_SHARE of the way
    from 1 (none of the way for the `not_shipped` muscles, which are left out: gain 1)."""
    out = {}
    for ch, g in insertion.items():
        base = ch[:-2] if ch.endswith(("_l", "_r")) else ch
        if base not in not_shipped:
            out[ch] = np.round(np.maximum(1.0 + SHIPPED_SHARE * (g - 1.0), 0.0), 6)
    return out


@dataclass
class Shape:
    """One scanned shape: label, ARKit name, target (N,3) cm, base channel values (C,) and the
    gaze coupling it may carry (lid channel, share name) or None."""

    label: str
    arkit: str
    target: np.ndarray
    values: np.ndarray
    coupling: tuple[str, str] | None


def rest_stiffness(model) -> object:  # type: ignore[no-untyped-def]
    """The skin's stiffness at rest, (3n, 3n) sparse: the springs' at their rest lengths and each
    vertex's support along its rest normal."""
    import scipy.sparse as sp

    from sim.build import stiffness_matrix

    n = model.n_vertices
    k = stiffness_matrix(model.rest, model.spring_indices, model.spring_k_low, model.rest_stiffness)
    nrm = model.rest_normal
    blocks = model.support_stiffness[:, None, None] * nrm[:, :, None] * nrm[:, None, :]
    rows = (3 * np.arange(n)[:, None, None] + np.arange(3)[None, :, None]) + 0 * np.arange(3)[None, None, :]
    cols = (3 * np.arange(n)[:, None, None] + np.arange(3)[None, None, :]) + 0 * np.arange(3)[None, :, None]
    return k + sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * n, 3 * n))


def _stiffness(model) -> tuple[object, np.ndarray]:  # type: ignore[no-untyped-def]
    """The factorised stiffness at rest over the free degrees of freedom, and their indices."""
    from scipy.sparse.linalg import splu

    k = rest_stiffness(model)
    free = np.flatnonzero(np.repeat(~np.asarray(model.held, bool), 3))
    return splu(k[free][:, free].tocsc()), free


def coupled_values(model: Any, shares: dict[str, float], s: Shape) -> np.ndarray:
    """The channel values a shape is driven with: its map's, with a coupled channel (the lids
    following a gaze) raised to the fitted share of that gaze."""
    v = s.values.copy()
    if s.coupling:
        i = model.channel_index[s.coupling[0]]
        v[i] = max(v[i], shares[s.coupling[1]])
    return v

class Calibration:
    """The linear model of one compiled face: per fitted channel its bumps and their settled
    displacement columns; the gains (shared by the two sides) and the gaze shares."""

    def __init__(self, model, bumps: int = BUMPS) -> None:  # type: ignore[no-untyped-def]
        from sim.build import vertex_normals
        from sim.muscles import muscle_field

        self.model = model
        rig = model.rig
        rest = np.asarray(model.rest)
        self.rest = rest
        n = len(rest)
        lu, free = _stiffness(model)
        normal = vertex_normals(rest, np.asarray(rig.mesh.triangles, np.int32))
        self.channels = [c for c in rig.muscles if c in model.channel_index]
        self.groups: list[str] = sorted({c[:-2] if c.endswith(("_l", "_r")) else c for c in self.channels})
        self.phi: dict[str, np.ndarray] = {}
        self.cols: dict[str, np.ndarray] = {}  # channel -> (B, N, 3) displacement per unit gain
        self.offset_of: dict[str, int] = {}
        k = 0
        for g in self.groups:
            left = g + "_l" if g + "_l" in rig.muscles else g
            fields = {}
            for ch in ((left, g + "_r") if left != g else (g,)):
                base = muscle_field(rig.muscles[ch], rest, np.asarray(model.area), normal)
                fields[ch] = base
            f0 = fields[left]
            mag = np.linalg.norm(f0, axis=1)
            phi, centres = _bumps(rest, mag > 1e-3 * mag.max(), bumps)
            self.phi[left] = phi
            if left != g:
                fr = fields[g + "_r"]
                magr = np.linalg.norm(fr, axis=1)
                mc = centres * np.array([-1.0, 1.0, 1.0])
                self.phi[g + "_r"], _ = _bumps(rest, magr > 1e-3 * magr.max(), bumps, mc)
            for ch, f in fields.items():
                ph = self.phi[ch]
                rhs = (ph[:, :, None] * f[None]).reshape(len(ph), 3 * n)
                sol = np.zeros_like(rhs)
                sol[:, free] = lu.solve(np.ascontiguousarray(rhs[:, free].T)).T
                self.cols[ch] = sol.reshape(len(ph), n, 3)
            self.offset_of[g] = k
            k += len(phi)
        self.n_params = k
        self.gains = np.ones(k)
        self.shares = {"EyeLookUp": 0.0, "EyeLookDown": 0.0}
        self.fit_shares = True  # False: the shares stay as set (the ARKit map's)

    def group(self, ch: str) -> str:
        return ch[:-2] if ch.endswith(("_l", "_r")) else ch

    def _design(self, s: Shape, values: np.ndarray) -> np.ndarray:
        """(3N, P) displacement of shape s per unit parameter at the given channel values."""
        a = np.zeros((3 * len(self.rest), self.n_params))
        for ch, col in self.cols.items():
            v = float(values[self.model.channel_index[ch]])
            if v == 0.0:
                continue
            o = self.offset_of[self.group(ch)]
            a[:, o:o + len(col)] += v * col.reshape(len(col), -1).T
        return a

    def shape_values(self, s: Shape) -> np.ndarray:
        return coupled_values(self.model, self.shares, s)

    def predict(self, s: Shape) -> np.ndarray:
        return (self._design(s, self.shape_values(s)) @ self.gains).reshape(-1, 3)

    def fit(self, items: list[Shape], offsets: dict[str, np.ndarray], pull: float = PULL) -> None:
        """The gains by bounded least squares over `items` (offsets: what the linear model misses),
        then the gaze shares with the gains fixed."""
        from scipy.optimize import lsq_linear

        ata = np.zeros((self.n_params, self.n_params))
        atb = np.zeros(self.n_params)
        for s in items:
            a = self._design(s, self.shape_values(s))
            nz = np.flatnonzero(np.any(a != 0.0, axis=0))
            a = a[:, nz]
            b = (s.target - offsets[s.label]).ravel()
            w = 1.0 / float(np.sum(s.target**2))
            ata[np.ix_(nz, nz)] += w * a.T @ a
            atb[nz] += w * a.T @ b
        ata += pull * np.eye(self.n_params)
        atb += pull * np.ones(self.n_params)
        low = np.linalg.cholesky(ata + 1e-12 * np.eye(self.n_params))
        rhs = np.linalg.solve(low, atb)
        self.gains = lsq_linear(low.T, rhs, bounds=(0.0, MAX_GAIN), method="bvls").x
        for name in self.shares if self.fit_shares else ():  # one share per gaze direction, both sides
            num = den = 0.0
            for s in items:
                if not s.coupling or s.coupling[1] != name:
                    continue
                v0 = s.values.copy()
                base = (self._design(s, v0) @ self.gains)
                v1 = v0.copy()
                v1[self.model.channel_index[s.coupling[0]]] = 1.0
                col = (self._design(s, v1) @ self.gains) - base
                r = (s.target - offsets[s.label]).ravel() - base
                num += float(col @ r)
                den += float(col @ col)
            if den > 0:
                self.shares[name] = float(np.clip(num / den, 0.0, 1.0))

    def insertion(self) -> dict[str, np.ndarray]:
        """Per channel the (N,) insertion gain the rig stores."""
        out = {}
        for ch, ph in self.phi.items():
            o = self.offset_of[self.group(ch)]
            out[ch] = np.round(np.maximum(ph.T @ self.gains[o:o + len(ph)], 0.0), 6)
        return out


def rms(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def settle_all(model, cal: Calibration, items: list[Shape]) -> dict[str, np.ndarray]:  # type: ignore[no-untyped-def]
    """Settled displacement (N,3) of every shape on the real simulator of `model`."""
    from sim.fit.basis import Settler

    st = Settler(model)
    return {s.label: st.pose(cal.shape_values(s)) - st.rest for s in items}


def calibrated_model(base_model, cal: Calibration):  # type: ignore[no-untyped-def]
    """The base model recompiled with the fitted gains (the base's own gains kept for the channels
    the fit left alone) and the fitted skin (or the base's)."""
    from sim.build import compile_model

    skin = cal.skin() if hasattr(cal, "skin") else base_model.rig.skin
    muscles = cal.muscles() if hasattr(cal, "muscles") else base_model.rig.muscles
    rig = replace(base_model.rig, insertion={**base_model.rig.insertion, **cal.insertion()}, skin=skin,
                  muscles=muscles)
    return compile_model(rig, base_model.params)


def group(ch: str) -> str:
    """A channel's muscle, both sides together ("zygomaticus_major_l" -> "zygomaticus_major")."""
    return ch[:-2] if ch.endswith(("_l", "_r")) else ch


def run(rounds: int, train: list[Shape], test: list[Shape], log=print, per_vertex: bool = False,  # type: ignore[no-untyped-def]
        skin: bool = False, keep: tuple[str, ...] = (), keep_skin: bool = False,
        shares: dict[str, float] | None = None, fibres: bool = False):
    """Fit on `train` over `rounds` re-linearisations; report the settled relative errors of both.
    per_vertex: a gain per zone vertex (`sim.face.scan.insertion_fit`) instead of the bumps;
    skin: that, and the skin's material fitted with them (`sim.face.scan.skin_fit`).
    keep: muscles (both sides) whose gains are not fitted but the shipped rig's (gain 1 where it
    has none); keep_skin: the shipped rig's skin material, not uniform skin (per-vertex gains
    fitted on it); shares: the gaze's shares of the lids held at these values, not fitted;
    fibres: the muscles' lines of action fitted with the per-vertex gains (`sim.face.scan.fibre_fit`)."""
    from sim.build import compile_model
    from sim.face.scan.rig import scan_model

    shipped_rig = scan_model().rig
    kept = frozenset(c for c in shipped_rig.muscles if group(c) in keep)
    if skin and (keep_skin or fibres):
        raise ValueError("the skin's material is fitted alone with the gains")
    if fibres:  # the lines of action start from where the transfer placed them, not the file's fit
        from sim.face.scan.make_rig import transferred_rig

        placed = transferred_rig().muscles
        shipped_rig = replace(shipped_rig, muscles={c: parts if c in kept else placed[c]
                                                    for c, parts in shipped_rig.muscles.items()})
    # start from the placed muscles (gain 1, or the kept gains) and uniform skin (or the kept skin)
    base = compile_model(replace(shipped_rig, insertion={c: g for c, g in shipped_rig.insertion.items() if c in kept},
                                 skin=shipped_rig.skin if keep_skin else {}), scan_model().params)
    t0 = time.monotonic()
    if skin:
        from sim.face.scan.skin_fit import SkinCalibration

        cal = SkinCalibration(base, fixed=kept)
    elif fibres:
        from sim.face.scan.fibre_fit import FibreCalibration

        cal = FibreCalibration(base, fixed=kept)
    elif per_vertex or keep_skin or kept:
        from sim.face.scan.insertion_fit import VertexCalibration

        cal = VertexCalibration(base, fixed=kept)
    else:
        cal = Calibration(base)
    if shares is not None:
        cal.shares = dict(shares)
        cal.fit_shares = False
    log(f"linear model: {cal.n_params} gains over {len(cal.groups)} muscles in {time.monotonic() - t0:.0f} s")
    every = {s.label: s for s in train + test}
    model = base
    real = settle_all(model, cal, list(every.values()))
    log(f"placed muscles settled in {time.monotonic() - t0:.0f} s: median relative error "
        f"{np.median([rms(real[s.label] - s.target) / rms(s.target) for s in train]):.2f} (fitted set)")
    for r in range(rounds):
        offsets = {k: real[k] - cal.predict(s) for k, s in every.items()}
        cal.fit(train, offsets)
        model = calibrated_model(base, cal)
        real = settle_all(model, cal, list(every.values()))
        for what, items in (("fitted", train), ("held out", test)):
            rel = [rms(real[s.label] - s.target) / rms(s.target) for s in items]
            if rel:
                log(f"round {r + 1} {what}: median relative error {np.median(rel):.2f}, max {max(rel):.2f} "
                    f"({len(rel)} shapes)")
        log(f"  gains {cal.gains.min():.2f}..{cal.gains.max():.2f}, shares {cal.shares}")
    return cal, model, real
