"""Where the implicit integrator's prepared arrays (`sim.implicit.prepare`: the factored matrix, the
contact's Green's function) are kept, so a second simulator of the same face in a process, and the
next start of the program, do not factor the matrix again (0.2-1 s for the scanned head).

`sim` knows no files: the application installs a store (`use_store`; `puppet.face_cache` keeps
them beside the compiled faces). A store has `load(key) -> dict | None` and `save(key,
arrays)`, the key a digest of everything the arrays are made from (`inputs_digest`); what it gives back is checked here before a stepper uses it
(`check`), so a damaged or foreign entry is made again, never stepped on. This module imports
nothing heavy: a start from the cache needs neither scipy nor the matrix."""

from __future__ import annotations

import hashlib
import weakref
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np


class Store(Protocol):
    def load(self, key: str) -> dict[str, np.ndarray] | None: ...

    def save(self, key: str, arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray] | None: ...


_STORE: Store | None = None
_MEMO: dict[str, dict[str, np.ndarray]] = {}
MEMO_ENTRIES = 2  # faces x substep sizes kept in the process (a show and its kernel warm-up share one)


def use_store(store: Store | None) -> None:
    """Keep prepared arrays in `store` from now on (None: in this process only)."""
    global _STORE
    _STORE = store


#: each face's digests by substep, while the face lives: a face is frozen with read-only arrays,
#: so a second simulator of it (a show's kernel warm-up) does not hash it again (~15 ms)
_DIGESTS: weakref.WeakKeyDictionary[Any, dict[float, str]] = weakref.WeakKeyDictionary()


def inputs_digest(model: Any, h: float) -> str:
    """`_inputs_digest`, once per face object and substep."""
    try:
        known = _DIGESTS.setdefault(model, {})
    except TypeError:  # (not weakly referable: hashed every time)
        return _inputs_digest(model, h)
    key = known.get(float(h))
    if key is None:
        key = known[float(h)] = _inputs_digest(model, h)
    return key


def _inputs_digest(model: Any, h: float) -> str:
    """SHA-256 of everything `sim.implicit.prepare(model, h)` reads: the substep, the springs and
    their stiffness, the per-vertex masses, damping and stiffnesses, the held vertices, the rest
    shape, the margin and skin bending parameters and the skin's bending weights, the triangles,
    the lid and lip rows and regions the fold guard's constants and the muscle matrix (a face's hash alone leaves out the mesh's
    annotations the rows and the thin skin come from)."""
    from sim.antifold import FLOOR, STRENGTH, bending_weights
    from sim.gaze_lids import ACROSS, LATERAL, LOWER, MEDIAL, N_BASIS, REACH, SPLIT, STIFFNESS, UPPER, WIDTH
    from sim.margin_contact import _rows

    d = hashlib.sha256(f"implicit h={float(h).hex()} lid={model.params.lid_bending!r} "
                       f"lip={model.params.lip_bending!r} skin={model.params.skin_bending!r} "
                       f"fold={FLOOR!r},{STRENGTH!r} gaze={STIFFNESS!r},{WIDTH!r},{REACH!r},{N_BASIS} "
                       f"lids apart={UPPER!r},{LOWER!r},{SPLIT!r},{MEDIAL!r},{LATERAL!r},{ACROSS!r} "
                       f"gaze tissue=3".encode())
    for arr in (model.spring_indices, model.spring_k_high, model.mass, model.damping, model.support_stiffness,
                model.rest_stiffness, model.held, model.rest, model.triangles,
                bending_weights(model)):
        a = np.ascontiguousarray(arr)
        d.update(f"{a.dtype.str}{a.shape}".encode() + a.tobytes())
    mm = model.muscle_matrix  # the muscles' responses (sim.implicit.muscle_responses)
    for arr in (mm.indptr, mm.indices, mm.data, np.array([c.kind == "muscle" for c in model.channels])):
        a = np.ascontiguousarray(arr)
        d.update(f"{a.dtype.str}{a.shape}".encode() + a.tobytes())
    gaze = getattr(getattr(model, "rig", None), "gaze", None) or {}  # the tissue carried by the eyes
    for name in sorted(gaze):
        d.update(b"gaze" + name.encode() + np.ascontiguousarray(gaze[name], np.float64).tobytes())
    for name, row in sorted(_rows(model.mesh).items()):
        d.update(name.encode() + np.ascontiguousarray(row, dtype=np.int64).tobytes())
    return d.hexdigest()


_KEYS: dict[int, tuple[dict[str, np.ndarray], str]] = {}


def key_of(arrays: dict[str, np.ndarray], model: Any, h: float) -> str:
    """The key (`inputs_digest`) of prepared `arrays` that `prepared` gave for this face and
    substep, without hashing the face again; made anew for arrays from elsewhere."""
    hit = _KEYS.get(id(arrays))
    return hit[1] if hit is not None and hit[0] is arrays else inputs_digest(model, h)


def prepared(model: Any, h: float) -> dict[str, np.ndarray]:
    """`sim.implicit.prepare(model, h)`, from this process's memory, else the store, else made
    (and given to the store). The arrays are shared: a stepper must not write to them."""
    key = inputs_digest(model, h)
    if key in _MEMO:
        return _MEMO[key]
    arrays = None
    if _STORE is not None:
        try:
            arrays = _STORE.load(key)
            if arrays is not None:
                check(arrays, model.n_vertices, float(h))
        except (ValueError, KeyError, TypeError, OSError):
            arrays = None
    if arrays is None:
        from sim.implicit import prepare

        arrays = prepare(model, h)
        if _STORE is not None:
            try:
                kept = _STORE.save(key, arrays)
                if isinstance(kept, dict):  # the store's own copy of them (a mapped file) serves from now on
                    arrays = kept
            except OSError:
                pass  # a read-only cache: the next start factors again
    while len(_MEMO) >= MEMO_ENTRIES:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[key] = arrays
    _KEYS.clear()
    _KEYS.update((id(a), (a, k)) for k, a in _MEMO.items())
    return arrays


_KEPT: dict[str, dict[str, np.ndarray]] = {}


def kept(kind: str, key: str, make: Callable[[], dict[str, np.ndarray]],
         check_arrays: Callable[[dict[str, np.ndarray]], None]) -> dict[str, np.ndarray]:
    """Other arrays made once per face and substep, kept like the prepared ones: from this process's
    memory, else the store (under `kind:key`, checked by `check_arrays`, which raises ValueError
    for anything it cannot step on), else `make()` (and given to the store). `key` must be a digest
    of everything `make` reads; the store adds the version of the code. The arrays are shared: a
    simulator must not write to them."""
    name = f"{kind}:{key}"
    if name in _KEPT:
        return _KEPT[name]
    arrays = None
    if _STORE is not None:
        try:
            arrays = _STORE.load(name)
            if arrays is not None:
                check_arrays(arrays)
        except (ValueError, KeyError, TypeError, OSError):
            arrays = None
    if arrays is None:
        arrays = make()
        if _STORE is not None:
            try:
                saved = _STORE.save(name, arrays)
                if isinstance(saved, dict):
                    arrays = saved
            except OSError:
                pass
    while len(_KEPT) >= MEMO_ENTRIES:
        _KEPT.pop(next(iter(_KEPT)))
    _KEPT[name] = arrays
    return arrays


_INT = ("free", "held", "fh_ptr", "fh_idx", "bend_ptr", "bend_idx", "lu_perm_r", "lu_perm_c", "lu_sn_ptr",
        "lu_r_ptr", "lu_v_ptr", "lu_t_ptr", "fold_tri")
_FLOAT = ("mass_h2", "damp_h", "kn", "fh_val", "bend_val", "lu_lv", "lu_uv", "lu_tv", "lu_u_diag", "fold_frame",
          "fold_dm_inv", "fold_area", "fold_k", "fold_floor", "resp")
_CONTACT_INT = ("c_idx", "c_dim", "c_opp", "c_row_ptr", "c_row_v", "c_loc", "c_gptr", "c_gvert")
_CONTACT_FLOAT = ("c_w", "c_sg", "c_green", "c_gval")


def _ptr(ptr: np.ndarray, rows: int, idx: np.ndarray, cols: int) -> None:
    if ptr.shape != (rows + 1,) or ptr[0] != 0 or ptr[-1] != len(idx) or np.any(np.diff(ptr) < 0):
        raise ValueError("bad sparse structure")
    if len(idx) and (idx.min() < 0 or idx.max() >= cols):
        raise ValueError("index out of range")


def check(a: dict[str, np.ndarray], n: int, h: float) -> None:
    """Raises ValueError unless `a` is a complete, consistent set of prepared arrays for a face of
    n vertices at substep h: every index the kernels follow in range, permutations that are
    permutations, finite values (the checksums are the store's)."""
    contact = "c_idx" in a
    names = _INT + _FLOAT + ("h", "lu_r_idx") + ((_CONTACT_INT + _CONTACT_FLOAT) if contact else ())
    if set(a) != set(names):
        raise ValueError("not a prepared stepper")
    if a["h"].shape != () or float(a["h"]) != h:
        raise ValueError("another substep")
    for k in _INT + (_CONTACT_INT if contact else ()):
        if a[k].dtype != np.int64:
            raise ValueError(f"{k}: not int64")
    for k in _FLOAT + (_CONTACT_FLOAT if contact else ()):
        if a[k].dtype != np.float64 or not np.all(np.isfinite(a[k])):
            raise ValueError(f"{k}: not finite float64")
    free, held = a["free"], a["held"]
    if np.any(np.bincount(np.concatenate([free, held]), minlength=n) != 1) or len(free) + len(held) != n:
        raise ValueError("free and held vertices do not cover the face")
    nf = len(free)
    for k in ("mass_h2", "damp_h", "kn"):
        if a[k].shape != (n,):
            raise ValueError(f"{k}: wrong shape")
    if a["resp"].ndim != 3 or a["resp"].shape[1:] != (nf, 3):
        raise ValueError("resp: wrong shape")
    for k in ("lu_perm_r", "lu_perm_c"):
        if a[k].shape != (nf,) or np.any(np.bincount(a[k], minlength=nf) != 1):
            raise ValueError(f"{k}: not a permutation")
    _ptr(a["fh_ptr"], nf, a["fh_idx"], len(held))
    _ptr(a["bend_ptr"], n, a["bend_idx"], n)
    m = len(a["fold_tri"])
    if a["fold_tri"].shape != (m, 3) or a["fold_frame"].shape != (m, 2, 3) or a["fold_dm_inv"].shape != (m, 2, 2) \
            or a["fold_area"].shape != (m,) or a["fold_k"].shape != (m,) or a["fold_floor"].shape != ():
        raise ValueError("fold guard: wrong shapes")
    if m and (a["fold_tri"].min() < 0 or a["fold_tri"].max() >= n):
        raise ValueError("fold guard: vertex out of range")
    from sim.supernodal import check_layout

    check_layout(a, nf)
    if contact:
        p = len(a["c_idx"])
        if a["c_idx"].shape != (p, 3) or a["c_sg"].shape != (p, 4) or a["c_loc"].shape != (n,):
            raise ValueError("contact: wrong shapes")
        if a["c_idx"].min() < 0 or a["c_idx"].max() >= n or a["c_row_v"].min() < 0 or a["c_row_v"].max() >= n:
            raise ValueError("contact: vertex out of range")
        g = a["c_green"].shape[0]
        if a["c_green"].shape != (g, g) or a["c_loc"].max() >= g or a["c_loc"].min() < -1:
            raise ValueError("contact: wrong Green's function")
        _ptr(a["c_gptr"], g, a["c_gvert"], n)
        rows = len(a["c_row_ptr"]) - 1
        if np.any(a["c_dim"] < 0) or np.any(a["c_dim"] > 2) or np.any(a["c_opp"] >= rows) or \
                np.any(a["c_opp"] < -1):
            raise ValueError("contact: bad rows")
        _ptr(a["c_row_ptr"], rows, a["c_row_v"], n)
