"""The scanned head's skin cut into named regions, and where a pose's error against the scan lies.

Used by `anchor_limits.py --where` and `scan_residuals.py`. Regions (each vertex in the first that
takes it, in this order): the lips' inside edge (the mouth opening's first two rings of the mesh),
the upper and lower lips' red part (`contact_limits.lip_parts` without that edge), the lids (within
1 cm of an eye's opening), the nasolabial band (within 6 mm of the line from the nose's wing to a
point 8 mm outside and 3 mm below the mouth's corner), the nose, the skin of the upper lip (between the nose and
the red lip), the chin (below the red lower lip, as wide as the mouth and 5 mm more), the brows
(within 12 mm of the brows' landmark line), the forehead (above the brows), the cheeks (between the
eyes' and the mouth's height) and the rest (the jaw's sides, the neck, the ears' side).
"""

from __future__ import annotations

import numpy as np

REGIONS = ("lip edge", "upper red", "lower red", "lids", "nasolabial", "nose", "upper lip skin", "chin",
           "brows", "forehead", "cheeks", "rest")


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((p - a) @ ab / float(ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def face_regions(model) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N,) int index into REGIONS for every vertex of the compiled scanned head."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    from scipy.spatial import cKDTree

    from contact_limits import lip_parts
    from sim.springs import boundary_loops

    rest = np.asarray(model.rest)
    n = len(rest)
    tri = np.asarray(model.rig.mesh.triangles, np.int64)

    def lm(name: str) -> np.ndarray:
        return rest[model.landmark_index(name)]

    loops = [np.asarray(lp) for lp in boundary_loops(tri)]
    mouth = min((lp for lp in loops if len(lp) < 400), key=lambda lp: rest[lp, 1].mean())
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    ring = dijkstra(g + g.T, unweighted=True, indices=mouth, min_only=True)
    parts = lip_parts(model)
    out = np.full(n, len(REGIONS) - 1)
    free = np.ones(n, bool)

    def take(name: str, mask: np.ndarray) -> None:
        m = mask & free
        out[m] = REGIONS.index(name)
        free[m] = False

    take("lip edge", ring <= 1)
    take("upper red", (parts == 3) | (parts == 4))
    take("lower red", (parts == 1) | (parts == 2))
    eye_d = np.full(n, np.inf)
    for side in ("l", "r"):
        centre = 0.5 * (lm(f"eye_inner_{side}") + lm(f"eye_outer_{side}"))
        lp = min(loops, key=lambda lp: float(np.linalg.norm(rest[lp].mean(axis=0) - centre)))
        eye_d = np.minimum(eye_d, cKDTree(rest[lp]).query(rest)[0])
    take("lids", eye_d <= 1.0)
    fold = np.full(n, np.inf)
    for side in ("l", "r"):
        corner = lm(f"mouth_corner_{side}")
        wing = lm(f"nose_wing_{side}")
        fold = np.minimum(fold, _segment_distance(rest, wing, corner + np.array([0.8 * np.sign(corner[0]), -0.3, 0.0])))
    take("nasolabial", fold <= 0.6)
    wing_x = max(abs(lm("nose_wing_l")[0]), abs(lm("nose_wing_r")[0]))
    corner_x = max(abs(lm("mouth_corner_l")[0]), abs(lm("mouth_corner_r")[0]))
    take("nose", (rest[:, 1] >= lm("subnasale")[1]) & (rest[:, 1] <= lm("nose_bridge")[1])
         & (np.abs(rest[:, 0]) <= wing_x + 0.2))
    take("upper lip skin", (rest[:, 1] < lm("subnasale")[1]) & (rest[:, 1] > lm("upper_lip_center")[1])
         & (np.abs(rest[:, 0]) <= corner_x))
    take("chin", (rest[:, 1] < lm("lower_lip_center")[1]) & (rest[:, 1] > lm("chin")[1] - 1.0)
         & (np.abs(rest[:, 0]) <= corner_x + 0.5))
    brow = np.full(n, np.inf)
    for side in ("l", "r"):
        pts = [lm(f"brow_inner_{side}"), lm(f"brow_mid_{side}"), lm(f"brow_outer_{side}")]
        for a, b in zip(pts[:-1], pts[1:]):
            brow = np.minimum(brow, _segment_distance(rest, a, b))
    take("brows", brow <= 1.2)
    brow_y = np.mean([lm(f"brow_mid_{s}")[1] for s in "lr"])
    take("forehead", rest[:, 1] > brow_y)
    eye_y = np.mean([lm(f"lower_lid_{s}")[1] for s in "lr"])
    take("cheeks", (rest[:, 1] <= eye_y) & (rest[:, 1] >= lm("mouth_corner_l")[1] - 0.5))
    return out


def smooth_part(model, r: np.ndarray, sigma: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N, 3) the part of a displacement field r that is smooth on the scale sigma (cm): r diffused
    over the mesh's edges ((I + t L) s = r, L the graph Laplacian weighted by 1 / length^2, t =
    sigma^2 / 2; the mouth's and eyes' openings are not crossed)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    rest = np.asarray(model.rest)
    n = len(rest)
    tri = np.asarray(model.rig.mesh.triangles, np.int64)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = 1.0 / np.sum((rest[e[:, 0]] - rest[e[:, 1]]) ** 2, axis=1)
    a = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    a = a + a.T
    lap = sp.diags(np.asarray(a.sum(axis=1)).ravel()) - a
    key = (id(model), sigma)
    lu = _LU.get(key)
    if lu is None:
        lu = _LU[key] = splu((sp.eye(n) + 0.5 * sigma * sigma * lap).tocsc())
    return lu.solve(np.ascontiguousarray(r, dtype=np.float64))


_LU: dict = {}


def where(model, target: np.ndarray, pose: np.ndarray, regions: np.ndarray) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """Per region its share of rel^2 (the squared error over the scan's squared motion, so the
    regions' figures sum to the squared relative error)."""
    err = np.sum((pose - target) ** 2, axis=1)
    tot = float(np.sum(target * target))
    return {name: float(err[regions == k].sum()) / tot for k, name in enumerate(REGIONS)}


def print_where(model, labels: list[str], targets: list[np.ndarray], poses: list[np.ndarray], name: str) -> None:  # type: ignore[no-untyped-def]
    regions = face_regions(model)
    print(f"where the error lies ({name}): per region its share of rel^2 (sums to rel^2)")
    print(f"{'shape':20s} {'rel':>5s} " + " ".join(f"{r[:9]:>9s}" for r in REGIONS))
    for lab, t, p in zip(labels, targets, poses):
        w = where(model, t, p, regions)
        rel = float(np.sqrt(sum(w.values())))
        print(f"{lab:20s} {rel:5.3f} " + " ".join(f"{w[r]:9.3f}" for r in REGIONS))


def print_scales(model, labels: list[str], targets: list[np.ndarray], poses: list[np.ndarray], name: str,
                 sigmas: tuple[float, ...] = (0.2, 0.4, 0.8)) -> None:  # type: ignore[no-untyped-def]
    """Per shape how much of the error (and of the scan's own motion) is finer than each scale: the
    share of rel^2 left once the error's part smooth on sigma (`smooth_part`) is taken away."""
    print(f"how fine the error is ({name}): per scale sigma the share of rel^2 in the part finer than sigma "
          f"(error; the scan's motion's own fine share beside it)")
    print(f"{'shape':20s} {'rel^2':>6s} " + " ".join(f"{'err<' + str(int(s * 10)) + 'mm':>9s} {'scan':>5s}" for s in sigmas))
    for lab, t, p in zip(labels, targets, poses):
        tot = float(np.sum(t * t))
        r = p - t
        cells = []
        for s in sigmas:
            fine_r = r - smooth_part(model, r, s)
            fine_t = t - smooth_part(model, t, s)
            cells.append(f"{float(np.sum(fine_r ** 2)) / tot:9.3f} {float(np.sum(fine_t ** 2)) / tot:5.3f}")
        print(f"{lab:20s} {float(np.sum(r * r)) / tot:6.3f} " + " ".join(cells))
