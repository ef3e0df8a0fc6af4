"""Compiled faces cached on disk, so `puppet live` does not rebuild the default face at every start.

An entry is named by a key: the SHA-256 of everything the compiled face is built from — the source
of every module of the `sim` package (the face builder, the rig, springs, muscles, the compiler:
editing any of them changes the key), the numpy/scipy versions, this format's version, and what
was asked for (the default face at a resolution, or the bytes of a rig file). Files, no pickle:

- `<key>.npz`: the FaceModel's arrays (`a_<field>`; the muscle matrix as CSR parts `mm_data`,
  `mm_indices`, `mm_indptr`) and `meta`, a 0-d unicode array holding JSON: {"format", "version",
  "key", "scalars": {field: number or text}, "params": SkinParams fields, "mm_shape", "arrays":
  SHA-256 of every array, "rig_sha": SHA-256 of the rig file below or null}.
- `<key>.rig.arrays`: for the default face, the arrays of its rig file (`sim.rig.rig_arrays`) in the
  mapped format (`puppet.mapped`), read back through the rig loader's checks (`sim.rig.rig_from_arrays`).
- `head-<key>.npz`: the held head shell around a default-face mask (`sim.face.head.HeadShell`'s
  arrays and a JSON `meta` with their checksums), keyed by the sim sources and the mask's geometry;
  built by the first window or export that draws the head (~0.4 s) and read back by the next ones
  through `sim.face.head.check_shell`.
- `implicit-<key>.arrays`: the implicit integrator's prepared arrays for a face and a substep size
  (`sim.implicit.prepare`: the factored matrix, the lid and lip contact's Green's function; 0.2-1 s
  to make for the scanned head), keyed by the sim sources and a digest of what they are made from
  (`sim.prepared.inputs_digest`), in the mapped format (`puppet.mapped`: one file mapped, not
  read, with one checksum of its arrays) and a JSON `meta`; read back through `sim.prepared.check`.
- `jaw-<key>.arrays`: the jaw's responses and poses at the grid's openings for a face and a substep
  (`sim.integrator._jaw_arrays`, ~0.1 s to make), kept the same way and checked by shape and finiteness.

An entry is never trusted blindly: a missing, corrupt, foreign (another key) or inconsistent entry
(checksums, shapes, index ranges, finiteness, the rig's own digest) is ignored and rebuilt. Entries
are written to a temporary file beside the target and renamed into place.

Where: $PUPPET_CACHE_DIR, else $XDG_CACHE_HOME/facepuppet/faces, else ~/.cache/facepuppet/faces;
the KEEP_ENTRIES most recently used entries are kept.
`PUPPET_CACHE_DIR=off` (or an unwritable place) builds every time, with one warning line."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import sys
import tempfile
import zipfile
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "facepuppet-face-cache"
VERSION = 1
ENV = "PUPPET_CACHE_DIR"
MAX_ENTRY_BYTES = 1 << 30  # an entry larger than this is not a face of ours
KEEP_ENTRIES = 8  # after writing an entry, only the most recently used this many are kept
KEEP_STEPPERS = 4  # the same for the implicit integrator's entries (~25 MB each for the scanned head)
#: arrays kept beside the implicit integrator's (`sim.prepared.kept`), each kind KEEP_STEPPERS entries:
#: the jaw's responses and poses at the grid's openings (~13 MB for the scanned head)
KEPT_KINDS = ("jaw",)
#: FaceModel fields that are not stored as arrays or scalars (rebuilt from the rig or constant)
_NOT_STORED = {"rig", "mesh", "channels", "channel_index", "muscle_matrix", "params"}


class CacheEntryError(ValueError):
    """A cache entry that cannot be used (it is then rebuilt)."""


def cache_dir() -> Path | None:
    """Where compiled faces are kept (None: caching is off)."""
    env = os.environ.get(ENV)
    if env:
        return None if env.lower() == "off" else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "facepuppet" / "faces"


@lru_cache(maxsize=4)
def source_digest(root: Path | None = None) -> str:
    """SHA-256 of every source and data file of the `sim` package (or of the package folder
    `root`: its modules and the scanned head's arrays), of its layout, and of the library versions (scipy's read from its metadata: importing scipy
    costs ~0.3 s that a start from the cache does not otherwise pay)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        scipy_version = version("scipy")
    except PackageNotFoundError:
        scipy_version = "none"
    if root is None:
        import sim.face

        root = Path(sim.__file__).resolve().parent
    h = hashlib.sha256(f"{FORMAT}/{VERSION} numpy {np.__version__} scipy {scipy_version}".encode())
    for path in sorted([*root.rglob("*.py"), *root.rglob("*.npz")]):
        h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def entry_key(what: bytes) -> str:
    return hashlib.sha256(source_digest().encode() + b"\0" + what).hexdigest()[:32]


def _array_digest(arrays: dict[str, np.ndarray]) -> dict[str, str]:
    out = {}
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        out[name] = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode() + a.tobytes()).hexdigest()
    return out


def _write_atomic(target: Path, write: Callable[[str], None]) -> None:
    """`write(path)` fills a temporary file beside `target`, which is then renamed into place."""
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp.npz")
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _split(model: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """A FaceModel's arrays and scalars, by field name."""
    arrays: dict[str, np.ndarray] = {}
    scalars: dict[str, Any] = {}
    for f in dataclasses.fields(model):
        if f.name in _NOT_STORED:
            continue
        val = getattr(model, f.name)
        if isinstance(val, np.ndarray):
            arrays[f"a_{f.name}"] = val
        else:
            scalars[f.name] = val.item() if isinstance(val, np.generic) else val
    mm = model.muscle_matrix
    arrays.update(mm_data=mm.data, mm_indices=mm.indices, mm_indptr=mm.indptr)
    return arrays, scalars


def save_entry(directory: Path, key: str, model: Any, with_rig: bool) -> None:
    """Write the entry for `model` under `key` (rig file first, then the model that names it)."""
    from puppet import mapped
    from sim.rig import rig_arrays

    directory.mkdir(parents=True, exist_ok=True)
    rig_sha = None
    if with_rig:
        rig_path = directory / f"{key}.rig.arrays"

        def write_rig(tmp: str) -> None:
            with open(tmp, "wb") as fh:
                mapped.dump(fh, rig_arrays(model.rig))

        _write_atomic(rig_path, write_rig)
        rig_sha = hashlib.sha256(rig_path.read_bytes()).hexdigest()
    arrays, scalars = _split(model)
    meta = {"format": FORMAT, "version": VERSION, "key": key, "scalars": scalars,
            "params": dataclasses.asdict(model.params), "mm_shape": list(model.muscle_matrix.shape),
            "arrays": _array_digest(arrays), "rig_sha": rig_sha}
    payload = {"meta": np.array(json.dumps(meta)), **arrays}
    _write_atomic(directory / f"{key}.npz", lambda tmp: np.savez(tmp, **payload))
    _evict(directory)


def _evict(directory: Path) -> None:
    """Remove all but the KEEP_ENTRIES most recently used entries (each edit of the face code
    makes a new one), and temporary files a killed writer left over an hour ago."""
    import time

    models = sorted(directory.glob("*[0-9a-f].npz"), key=lambda p: p.stat().st_mtime, reverse=True)
    old = [p for p in models if len(p.name) == 36][KEEP_ENTRIES:]
    for p in old:
        for q in (p, p.with_name(p.name[:-4] + ".rig.arrays"), p.with_name(p.name[:-4] + ".rig.npz")):
            try:
                q.unlink()
            except OSError:
                pass
    heads = sorted(directory.glob("head-*[0-9a-f].npz"), key=lambda p: p.stat().st_mtime, reverse=True)
    old = heads[KEEP_ENTRIES:]
    for prefix in ("implicit", *KEPT_KINDS):  # (.npz: an earlier version's entries)
        steppers = sorted([*directory.glob(f"{prefix}-*[0-9a-f].arrays"), *directory.glob(f"{prefix}-*[0-9a-f].npz")],
                          key=lambda p: p.stat().st_mtime, reverse=True)
        old += steppers[KEEP_STEPPERS:]
    for p in old:
        try:
            p.unlink()
        except OSError:
            pass
    for tmp in directory.glob(".*.tmp.npz"):
        try:
            if time.time() - tmp.stat().st_mtime > 3600:
                tmp.unlink()
        except OSError:
            pass


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    """Every member of an uncompressed npz, each checked against its stored size before reading."""
    if not path.is_file():
        raise CacheEntryError("missing")
    if path.stat().st_size > MAX_ENTRY_BYTES or not zipfile.is_zipfile(path):
        raise CacheEntryError("not an entry")
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            with zf.open(info) as fh:
                fmt = np.lib.format
                major, _ = fmt.read_magic(fh)
                read_header = fmt.read_array_header_1_0 if major == 1 else fmt.read_array_header_2_0
                shape, _, dtype = read_header(fh)
                if dtype.hasobject or int(np.prod(shape, dtype=np.int64)) * dtype.itemsize > info.file_size:
                    raise CacheEntryError(f"member {info.filename} claims more than it holds")
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


def _check_model(arrays: dict[str, np.ndarray], meta: dict[str, Any], rig: Any) -> None:
    """Shapes, index ranges and finiteness against the rig: what the kernels index must be safe."""
    n = len(rig.mesh.vertices)
    a = {k[2:]: v for k, v in arrays.items() if k.startswith("a_")}
    springs = a["spring_indices"]
    s = len(springs)
    shapes = {"rest": (n, 3), "triangles": rig.mesh.triangles.shape, "spring_indices": (s, 2),
              "rest_normal": (n, 3), "rest_offset": (n, 3), "weight": (n, 3), "jaw_pivot": (3,), "jaw_axis": (3,), "gravity": (3,)}
    for name in ("spring_rest_length", "spring_k_low", "spring_k_high", "spring_damping"):
        shapes[name] = (s,)
    for name in ("area", "mass", "damping", "rest_stiffness", "support_stiffness", "held", "jaw_weight"):
        shapes[name] = (n,)
    k = len(a["eye_contact"])
    shapes.update(eye_contact=(k,), eye_contact_eye=(k,))
    if set(a) != set(shapes):
        raise CacheEntryError("unexpected arrays")
    for name, want in shapes.items():
        arr = a[name]
        if arr.shape != tuple(want) or arr.dtype.kind not in "fiub":
            raise CacheEntryError(f"array {name} has shape {arr.shape}")
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise CacheEntryError(f"array {name} is not finite")
    if not np.array_equal(a["triangles"], rig.mesh.triangles) or not np.array_equal(a["rest"], rig.mesh.vertices):
        raise CacheEntryError("geometry differs from the rig")
    for name, hi in (("spring_indices", n), ("eye_contact", n), ("eye_contact_eye", 2)):
        arr = a[name]
        if arr.dtype.kind not in "iu" or (arr.size and (arr.min() < 0 or arr.max() >= hi)):
            raise CacheEntryError(f"array {name} indexes out of range")
    if not np.all(a["mass"] > 0):
        raise CacheEntryError("non-positive masses")
    rows, cols = (int(x) for x in meta["mm_shape"])
    ind, ptr, data = arrays["mm_indices"], arrays["mm_indptr"], arrays["mm_data"]
    if ind.dtype not in (np.int32, np.int64) or ptr.dtype != ind.dtype or data.dtype != np.float64 \
            or ind.ndim != 1:
        raise CacheEntryError("muscle matrix has the wrong types")
    if rows != 3 * n or ptr.shape != (rows + 1,) or ind.shape != data.shape or ptr[0] != 0 \
            or ptr[-1] != len(ind) or np.any(np.diff(ptr) < 0) or (ind.size and (ind.min() < 0 or ind.max() >= cols)) \
            or not np.all(np.isfinite(data)):
        raise CacheEntryError("muscle matrix is inconsistent")


_SCALARS = {"n_edge_springs": int, "strain_threshold": float, "eye_contact_radius": float,
            "omega_max": float, "hash": str}


def _check_scalars(scalars: Any, n_springs: int) -> dict[str, Any]:
    if not isinstance(scalars, dict) or set(scalars) != set(_SCALARS):
        raise CacheEntryError("unexpected scalars")
    for name, kind in _SCALARS.items():
        val = scalars[name]
        ok = isinstance(val, str) if kind is str else (
            isinstance(val, (int, float)) and not isinstance(val, bool) and np.isfinite(val)
            and (kind is float or isinstance(val, int)))
        if not ok:
            raise CacheEntryError(f"scalar {name} is {type(val).__name__}")
    if not 0 <= scalars["n_edge_springs"] <= n_springs or not scalars["omega_max"] > 0:
        raise CacheEntryError("scalars out of range")
    return dict(scalars)


def load_entry(directory: Path, key: str, rig: Any | None) -> Any:
    """The FaceModel of the entry `key` (its own rig file when `rig` is None); CacheEntryError if
    the entry is missing or cannot be trusted."""
    from sim.build import FaceModel, SkinParams, _rig_digest
    from sim.channels import CHANNEL_SPECS
    from sim.csr import CsrArrays

    arrays = _read_npz(directory / f"{key}.npz")
    meta_arr = arrays.pop("meta", None)
    if meta_arr is None or meta_arr.dtype.kind != "U" or meta_arr.shape != ():
        raise CacheEntryError("no meta")
    try:
        meta = json.loads(str(meta_arr))
    except (ValueError, RecursionError) as err:
        raise CacheEntryError("meta is not JSON") from err
    if not isinstance(meta, dict) or meta.get("format") != FORMAT or meta.get("version") != VERSION \
            or meta.get("key") != key:
        raise CacheEntryError("foreign entry")
    if meta.get("arrays") != _array_digest(arrays):
        raise CacheEntryError("checksum mismatch")
    if rig is None:
        from puppet import mapped
        from sim.rig import rig_from_arrays

        rig_path = directory / f"{key}.rig.arrays"
        try:
            if rig_path.stat().st_size > MAX_ENTRY_BYTES \
                    or hashlib.sha256(rig_path.read_bytes()).hexdigest() != meta.get("rig_sha"):
                raise CacheEntryError("rig checksum mismatch")
            # its arrays mapped, not read from a compressed npz (119 members: 0.04-0.07 s of a start)
            rig = rig_from_arrays(mapped.read(rig_path), str(rig_path))
        except (OSError, ValueError, KeyError, TypeError) as err:
            raise CacheEntryError("rig missing or unreadable") from err
    try:
        params = SkinParams(**meta["params"])
        scalars = _check_scalars(meta["scalars"], len(arrays["a_spring_indices"]))
        _check_model(arrays, meta, rig)
        if _rig_digest(rig, params) != scalars.get("hash"):
            raise CacheEntryError("the entry was compiled from another rig")
        # plain CSR arrays, read as they are by the kernels (checked in _check_model); scipy's
        # matrix is made from them only if something asks for more. Writable like a built
        # scipy matrix's, so the kernels see the same types (one compiled signature, not two)
        mm = CsrArrays(arrays["mm_data"], arrays["mm_indices"], arrays["mm_indptr"],
                       tuple(int(x) for x in meta["mm_shape"]))
        if mm.shape[1] != len(CHANNEL_SPECS):
            raise CacheEntryError("channel count differs")
        fields = {}
        for name, arr in arrays.items():
            if name.startswith("a_"):
                arr.setflags(write=False)
                fields[name[2:]] = arr
        return FaceModel(rig=rig, mesh=rig.mesh, muscle_matrix=mm, params=params, **fields, **scalars)
    except CacheEntryError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise CacheEntryError(f"malformed entry ({type(err).__name__})") from err


def cached_model(what: bytes, build: Callable[[], Any], rig: Any | None = None) -> Any:
    """The compiled face for `what` from the cache, or `build()` it and store it. `rig` (a rig
    already loaded from the user's file) is used as is; without it the entry keeps its own rig."""
    directory = cache_dir()
    if directory is None:
        return build()
    key = entry_key(what)
    try:
        model = load_entry(directory, key, rig)
        try:
            os.utime(directory / f"{key}.npz")  # used now: kept by the eviction
        except OSError:
            pass
        return model
    except Exception:  # noqa: BLE001 - missing, damaged or foreign, however it fails: rebuild it
        pass
    model = build()
    try:
        save_entry(directory, key, model, with_rig=rig is None)
    except OSError as err:
        print(f"puppet: warning: cannot cache the compiled face in {directory} ({err.strerror or err}); "
              f"set {ENV} to a writable folder for faster starts", file=sys.stderr)
    return model


@lru_cache(maxsize=4)
def default_model(resolution: int = 0) -> Any:
    """The default face at a resolution, from the cache when it can be trusted (and its head
    shell, when something draws it, from the same folder: `HeadShellStore`)."""
    import sim.face
    from sim.face import head as face_head

    directory = cache_dir()
    if directory is not None:
        face_head.use_store(HeadShellStore(directory))
    use_stepper_store()
    return cached_model(f"default-face:{resolution}".encode(), lambda: sim.face.default_model(resolution))


def scan_model(weights: Any = None, bound_forehead: bool = True) -> Any:
    """The scanned head (`sim.face.scan`) of an identity (None: the generic head; else up to 100
    identity weights), compiled, from the cache when it can be trusted: a build takes ~8 s (the
    rig transfer and two eigenvalue solves), a start from the cache well under one.
    bound_forehead False: its skin as before the forehead's bound layer (takes recorded then)."""
    import numpy as np

    from sim.build import compile_model
    from sim.face.scan.rig import THIN_FOREHEAD_KEY, scan_params, scan_rig

    use_stepper_store()
    w = None if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    what = b"scan-face:ict:" + (b"generic" if w is None else hashlib.sha256(w.tobytes()).digest())
    if not bound_forehead:
        what += THIN_FOREHEAD_KEY
    return cached_model(what, lambda: compile_model(scan_rig(w), scan_params(bound_forehead)))


_SHELL_ARRAYS = ("vertices", "triangles", "hair", "hair_coords", "ring", "ring_mask", "moving", "col_mask",
                 "col_rest", "col_w")


class HeadShellStore:
    """sim.face.head's ShellStore in the cache folder: `head-<key>.npz`, written atomically, read
    back with the same bounded reader and checksums as the faces (anything else: None, rebuilt)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    def path(self, mask_key: bytes) -> Path:
        return self.directory / f"head-{entry_key(b'head-shell:' + mask_key)}.npz"

    def load(self, mask_key: bytes) -> Any:
        from sim.face.head import HeadShell

        path = self.path(mask_key)
        try:
            arrays = _read_npz(path)
            meta = json.loads(str(arrays.pop("meta")))
            if not isinstance(meta, dict) or meta.get("format") != FORMAT or meta.get("version") != VERSION \
                    or meta.get("arrays") != _array_digest(arrays) or set(arrays) != set(_SHELL_ARRAYS):
                return None
            head_triangles = meta.get("head_triangles")
            if not isinstance(head_triangles, int) or isinstance(head_triangles, bool):
                return None
            try:
                os.utime(path)  # used now: kept by the eviction
            except OSError:
                pass
            return HeadShell(head_triangles=head_triangles, **arrays)
        except Exception:  # noqa: BLE001 - missing, damaged or foreign: built again
            return None

    def save(self, mask_key: bytes, shell: Any) -> None:
        arrays = {name: np.asarray(getattr(shell, name)) for name in _SHELL_ARRAYS}
        meta = {"format": FORMAT, "version": VERSION, "head_triangles": int(shell.head_triangles),
                "arrays": _array_digest(arrays)}
        self.directory.mkdir(parents=True, exist_ok=True)
        _write_atomic(self.path(mask_key), lambda tmp: np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays))
        _evict(self.directory)


class StepperStore:
    """sim.prepared's store in the cache folder: `implicit-<key>.arrays` (and `KIND-<key>.arrays` for
    the arrays kept with them), written atomically in the mapped format (`puppet.mapped`: one
    file, one checksum) and read back as views of a private mapping of it: no parsing or copying of
    its ~25 MB (the npz it was read from before took 0.05-0.1 s of CPU at each start); anything
    damaged, foreign or another version's is None (made again)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory

    def path(self, key: str) -> Path:
        """`implicit-<key>.arrays` for the prepared arrays; `KIND-<key>.arrays` for other arrays
        kept with them (`sim.prepared.kept`, a key `KIND:digest`: the jaw's grid)."""
        kind, sep, _ = key.partition(":")
        prefix = kind if sep and kind in KEPT_KINDS else "implicit"
        return self.directory / f"{prefix}-{entry_key(b'implicit:' + key.encode())}.arrays"

    def load(self, key: str) -> dict[str, np.ndarray] | None:
        from puppet import mapped

        path = self.path(key)
        try:
            if not path.is_file() or path.stat().st_size > MAX_ENTRY_BYTES:
                return None
            arrays = mapped.read(path)  # (the checksum over every array's bytes)
            meta = json.loads(str(arrays.pop("meta")))
            if not isinstance(meta, dict) or meta.get("format") != FORMAT or meta.get("version") != VERSION \
                    or meta.get("inputs") != key:
                return None
            try:
                os.utime(path)  # used now: kept by the eviction
            except OSError:
                pass
            return arrays
        except Exception:  # noqa: BLE001 - missing, damaged or foreign: made again
            return None

    def save(self, key: str, arrays: dict[str, np.ndarray]) -> None:
        from puppet import mapped

        meta = {"format": FORMAT, "version": VERSION, "inputs": key}
        self.directory.mkdir(parents=True, exist_ok=True)

        def write(tmp: str) -> None:
            with open(tmp, "wb") as fh:
                mapped.dump(fh, {"meta": np.array(json.dumps(meta)), **arrays})

        _write_atomic(self.path(key), write)
        _evict(self.directory)


def use_stepper_store() -> None:
    """Keep the implicit integrator's prepared arrays in the cache folder (`StepperStore`)."""
    from sim import prepared

    directory = cache_dir()
    store = StepperStore(directory) if directory is not None else None
    wrapper = prepared._STORE
    if hasattr(wrapper, "inner"):  # a store over the cache (`puppet.batch.shared`): it stays in front
        wrapper.inner = store  # type: ignore[union-attr]
    else:
        prepared.use_store(store)


def rig_model(rig: Any, rig_bytes: bytes, build: Callable[[], Any] | None = None, variant: bytes = b"") -> Any:
    """The compiled face of a rig loaded from a file whose bytes are `rig_bytes`; `build` compiles
    it on a cache miss (default: `sim.compile_model(rig)`); `variant` names other parameters
    `build` compiles it with (part of the key)."""
    import sim.face

    use_stepper_store()
    return cached_model(b"rig-file:" + hashlib.sha256(rig_bytes).digest() + variant,
                        build or (lambda: sim.compile_model(rig)), rig)
