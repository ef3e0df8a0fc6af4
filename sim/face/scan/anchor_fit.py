"""The deep tissue moving with the muscle: the skin's tether anchors displaced per channel.

The skin is tethered to its rest place on the tissue beneath (seed 003 eq 9: F_r = k_r (target -
x)). A mimetic muscle lies in that deep layer (the superficial musculo-aponeurotic system), so as
it contracts the places the skin is tied to over its zone move with it. Modelled per channel as a
smooth displacement field of the tether's anchors over the channel's zone, d_c (three numbers per
zone vertex; the right side's the left's mirrored, x -> -x), scaled by the channel's value: the
tether's force gains k_r,i v_c d_c,i. Unlike active strain (`sim.face.scan.strain_fit`), whose
forces are internal to the sheet and sum to zero over a zone, this force is external to the sheet:
it can carry a region as a whole against the tether.

The tether is linear in x, so the displaced anchors are exactly a constant force per channel,
k_r d_c: the step can carry it as part of the channel's field (its response in the implicit step).

Linear statics about the rest shape, as the other fits: u = K^-1 sum_c v_c K_r P_c p_c, K the
skin's stiffness at rest with the step's bending terms (`strain_fit.step_stiffness`). Parameters
are in millimetres; a graph-Laplacian smoothness over the zone's edges and a small ridge keep the
fields tissue-like; each component is bounded (BOUND mm). A pose's evenness can join the objective
(`AnchorCalibration.even_over`): the lumps its displacement keeps beyond a local average
(`forehead_lumps`), and how far the fields move its smooth part.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.face.scan.strain_fit import FieldCalibration

SMOOTH = 1e-3  # Laplacian weight per edge and component (per mm squared), relative to one shape's own size
RIDGE = 1e-5  # pull of each component towards 0 (per mm squared)
BOUND = 5.0  # |d| at most this per component, mm
MM = 0.1  # cm per parameter unit
_MIRROR = np.array([-1.0, 1.0, 1.0])


def channel_zones(model: Any, grow: float = 0.0) -> dict[str, np.ndarray]:
    """Per muscle channel the (N,) bool zone its field reaches (above 1e-3 of its largest), grown by
    `grow` cm over the skin (vertices within that distance of the zone)."""
    from scipy.spatial import cKDTree

    from sim.build import vertex_normals
    from sim.muscles import muscle_field

    rig = model.rig
    rest = np.asarray(model.rest)
    n = len(rest)
    normal = vertex_normals(rest, np.asarray(rig.mesh.triangles, np.int32))
    held = np.asarray(model.held, bool)
    out = {}
    for c in rig.muscles:
        if c not in model.channel_index:
            continue
        f = muscle_field(rig.muscles[c], rest, np.asarray(model.area), normal)
        mag = np.linalg.norm(f, axis=1)
        z = mag > 1e-3 * mag.max() if mag.max() > 0 else np.zeros(n, bool)
        if grow > 0 and z.any():
            d, _ = cKDTree(rest[z]).query(rest)
            z = d <= grow
        out[c] = z & ~held
    from sim.build import side_weight
    from sim.channels import HALVES

    for half, (whole, side) in HALVES.items():  # a half reaches its whole's zone on its side
        if whole in out and half in model.channel_index:
            out[half] = out[whole] & (side_weight(rig.mesh, rest, side) > 0.01)
    return out


def forehead_lumps(model: Any, radius: float = 1.0, low: float = 2.0, average: bool = False) -> Any:
    """(3M, 3N) sparse: a displacement (3N,) of the scanned head to what it keeps beyond its average
    within `radius` cm on the forehead (M vertices: `low` to 7 cm above the upper lids' middles,
    within 5.5 cm of the midline, the front 4 cm), the lumps `tests/sim/test_scan_face.py` measures;
    with `average` to that average."""
    import scipy.sparse as sp
    from scipy.spatial import cKDTree

    rest = np.asarray(model.rest, np.float64)
    lm = model.mesh.landmarks
    eye_y = float(np.mean([rest[lm[f"upper_lid_{s}"], 1] for s in "lr"]))
    fh = np.flatnonzero((rest[:, 1] > eye_y + low) & (rest[:, 1] < eye_y + 7.0) & (np.abs(rest[:, 0]) < 5.5)
                        & (rest[:, 2] > rest[:, 2].max() - 4.0))
    near = cKDTree(rest[fh]).query_ball_point(rest[fh], radius)
    rows = np.concatenate([np.full(len(j), i) for i, j in enumerate(near)])
    cols = np.concatenate([fh[np.asarray(j)] for j in near])
    vals = np.concatenate([np.full(len(j), 1.0 / len(j)) for j in near])
    a = sp.csr_matrix((vals, (rows, cols)), shape=(len(fh), len(rest)))
    if not average:
        a = sp.csr_matrix((np.ones(len(fh)), (np.arange(len(fh)), fh)), shape=a.shape) - a
    return sp.kron(a, sp.eye(3)).tocsr()


class AnchorCalibration(FieldCalibration):
    """The linear model of one compiled face with a tether-anchor displacement field per muscle
    (sides shared, mirrored)."""

    FTOL = 1e-15

    def __init__(self, model: Any, smooth: float = SMOOTH, ridge: float = RIDGE, bound: float = BOUND,
                 grow: float = 0.0, bending: bool = True, zones: dict[str, np.ndarray] | None = None) -> None:
        import scipy.sparse as sp

        from sim.face.scan.insertion_fit import mirror_map
        from sim.face.scan.strain_fit import step_stiffness

        self.model = model
        rest = np.asarray(model.rest)
        n = self.n = len(rest)
        self.lu, self.free = step_stiffness(model, bending)
        mirror = mirror_map(rest)
        kr = np.asarray(model.rest_stiffness, np.float64)
        tri = np.asarray(model.rig.mesh.triangles, np.int64)
        e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
        e = np.unique(np.sort(e[(e < n).all(axis=1)], axis=1), axis=0)
        zones = channel_zones(model, grow) if zones is None else zones
        self.channels = sorted(zones)
        from sim.channels import HALVES

        halved = {whole for half, (whole, _) in HALVES.items() if half in zones}
        groups: dict[str, list[str]] = {}
        for c in self.channels:  # a whole channel beside its sided halves (HALVES) is a group apart from theirs
            key = c[:-2] if c.endswith(("_l", "_r")) else c + " whole" if c in halved else c
            groups.setdefault(key, []).append(c)
        self.groups = sorted(groups)
        self.par_of: dict[str, tuple[np.ndarray, bool]] = {}
        self.force_of: dict[str, Any] = {}
        self.parts: dict[str, tuple[int, int]] = {}
        lap, k = [], 0
        for g in self.groups:
            chans = groups[g]
            zone, ids, look, edges = self._group_zone(g, chans, zones, mirror, e, k)
            lap.append(edges)
            self.parts[g] = (k, len(ids))
            for c in chans:
                right = c == g + "_r"
                par = look[mirror] if right else look
                par = np.where(zones[c], par, -1)
                self.par_of[c] = (par, right)
            k += len(ids)
        self.n_params = 3 * k
        for c, (par, right) in self.par_of.items():
            on = np.flatnonzero(par >= 0)
            sign = _MIRROR if right else np.ones(3)
            rows = (3 * on[:, None] + np.arange(3)).ravel()
            cols = (3 * par[on][:, None] + np.arange(3)).ravel()
            vals = (MM * kr[on][:, None] * sign[None]).ravel()
            self.force_of[c] = sp.csr_matrix((vals, (rows, cols)), shape=(3 * n, self.n_params))
        self._edge_differences(lap, k, 3)
        self.smooth, self.ridge, self.bound = smooth, ridge, bound
        self.params = np.zeros(self.n_params)
        self.even: list[tuple[np.ndarray, np.ndarray, Any, float, np.ndarray]] = []

    def even_over(self, values: np.ndarray, settled: np.ndarray, smoothing: Any, weight: float,
                  target: np.ndarray | None = None) -> None:
        """Adds to the objective weight * |S (u0 + u(p)) - t|^2 for the pose of channel `values` (C,),
        settled `settled` (N, 3) cm on the rig the fit adds to, u(p) the fields' linear change to it:
        with `smoothing` S taking a displacement to what it keeps beyond its local average
        (`forehead_lumps`) and t 0 the pose's lumps; with S the local average and t that of the pose
        as it was, how far the fields move the pose's smooth part."""
        s = smoothing
        self.even.append((np.asarray(values, np.float64), np.asarray(settled, np.float64).ravel(), s, float(weight),
                          np.zeros(s.shape[0]) if target is None else np.asarray(target, np.float64)))

    def objective(self, p: np.ndarray, vals: np.ndarray, b: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
        """The misfit, smoothness and ridge (`FieldCalibration.objective`) plus each evenness term
        (`even_over`) and its gradient (one adjoint solve a pose)."""
        val, grad = super().objective(p, vals, b, w)
        ci = self.model.channel_index
        for v, u0, s, wt, t in self.even:
            su = s @ (self._solve(self.forces(p, v[None]))[:, 0] + u0) - t
            val += wt * float(su @ su)
            lam = 2.0 * wt * self._solve((s.T @ su)[:, None])[:, 0]
            for c, f in self.force_of.items():
                if v[ci[c]]:
                    grad += v[ci[c]] * (f.T @ lam)
        return val, grad

    def field(self, c: str, p: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) channel c's anchor displacement at full value, cm (zero outside its zone)."""
        p = (self.params if p is None else p).reshape(-1, 3)
        par, right = self.par_of[c]
        d = np.zeros((self.n, 3))
        z = par >= 0
        d[z] = MM * p[par[z]] * (_MIRROR if right else 1.0)
        return d

    def force(self, c: str, p: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) channel c's added tether force at full value, dyn."""
        return np.asarray(self.model.rest_stiffness, np.float64)[:, None] * self.field(c, p)


def half_anchors(rig: Any) -> Any:
    """The rig with every sided half's (`sim.channels.HALVES`) anchor field set to its whole
    channel's weighted by the side's share (`sim.build.side_weight`), rounded as the fitted fields
    are, so the two halves at one value move the anchors as the whole does; a half's field the rig
    had is replaced. The start of the halves' own fit (`benchmarks/anchor_limits.py --halves`),
    which so gives the same rig whether or not the rig it starts from had them."""
    from dataclasses import replace

    from sim.build import side_weight
    from sim.channels import HALVES

    rest = np.asarray(rig.mesh.vertices, np.float64)
    anchor = dict(rig.anchor)
    for half, (whole, side) in HALVES.items():
        anchor.pop(half, None)
        if whole in anchor:
            anchor[half] = np.round(np.asarray(anchor[whole], np.float64) * side_weight(rig.mesh, rest, side)[:, None], 6)
    return replace(rig, anchor=anchor)
