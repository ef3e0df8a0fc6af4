"""The fit's displacement basis and expression templates, built by the simulator and cached.

Building them settles the face ~47 times (~20 s for the default face). The cache file is keyed by
the model's hash (rig geometry, muscles and skin parameters: a retuned face gets a new basis), a
digest of the simulator's source files (a changed force term too) and the basis settings, so a
stale basis is never used. Files are npz without pickle, checked on load (a damaged or foreign
file is rebuilt, never trusted), and written to a temporary file renamed into place, so two
processes building at once cannot leave a half-written file.

Location: $FACEPUPPET_CACHE, else $XDG_CACHE_HOME/facepuppet, else ~/.cache/facepuppet."""

from __future__ import annotations

import hashlib
import os
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

FORMAT_VERSION = 1
_SIM_SOURCES = ("build.py", "integrator.py", "implicit.py", "springs.py", "muscles.py", "state.py",
                "channels.py", "facs.py", "fit/basis.py")


def cache_dir() -> Path:
    env = os.environ.get("FACEPUPPET_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "facepuppet"


def _key(model: Any) -> str:
    import sim
    from sim.fit.basis import DEFAULT_AMPLITUDE, SETTLE_SECONDS, TEMPLATE_WEIGHTS

    h = hashlib.sha256()
    from sim.facs import preset_face

    presets = preset_face(getattr(model, "rig", None)) or ""  # the templates are the face's own presets
    h.update(f"{FORMAT_VERSION}:{model.hash}:{DEFAULT_AMPLITUDE}:{TEMPLATE_WEIGHTS}:{SETTLE_SECONDS}:{presets}".encode())
    root = Path(sim.__file__).parent
    for name in _SIM_SOURCES:
        try:
            h.update((root / name).read_bytes())
        except OSError:
            h.update(name.encode())
    h.update(np.__version__.encode())
    return h.hexdigest()[:20]


def _load(path: Path, model: Any) -> tuple[Any, Any] | None:
    from sim.fit.basis import Basis, Templates, fit_channels

    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
        chans = tuple(str(c) for c in d["channels"])
        names = tuple(str(c) for c in d["names"])
        n = model.n_vertices
        ok = (chans == fit_channels() and d["columns"].shape == (len(chans), n, 3)
              and d["rest"].shape == (n, 3) and d["fields"].shape[0] == len(names)
              and d["fields"].shape[2:] == (n, 3) and d["activations"].shape == (len(names), len(chans))
              and all(np.all(np.isfinite(d[k])) for k in ("columns", "rest", "fields", "hi")))
        if not ok:
            return None
        basis = Basis(chans, d["hi"], d["rest"], d["columns"], float(d["amplitude"]), str(d["model_hash"]))
        tpl = Templates(names, tuple(float(w) for w in d["weights"]), d["fields"], chans, d["activations"])
        return basis, tpl
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None


def _save(path: Path, basis: Any, tpl: Any) -> None:
    """Write the cache entry atomically; a cache that cannot be written is only slower next time."""
    import safefile

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with safefile.atomic_write(path, "wb") as fh:
            np.savez(fh, channels=np.array(basis.channels), hi=basis.hi, rest=basis.rest, columns=basis.columns,
                     amplitude=basis.amplitude, model_hash=basis.model_hash, names=np.array(tpl.names),
                     weights=np.array(tpl.weights), fields=tpl.fields, activations=tpl.activations)
    except (OSError, ValueError):
        pass


def basis_for(model: Any, progress: Callable[[str, int, int], None] | None = None,
              use_cache: bool = True) -> tuple[Any, Any, Any]:
    """(settler, basis, templates) for a model: from the cache if a valid entry exists, else built
    and stored. The settler is always made (re-linearisation needs the live simulator)."""
    from sim.fit.basis import Settler, build_basis, build_templates

    settler = Settler(model)
    path = cache_dir() / f"fit-{_key(model)}.npz"
    if use_cache and path.is_file():
        got = _load(path, model)
        if got is not None:
            return settler, got[0], got[1]
    cb = (lambda what: (lambda i, n: progress(what, i, n))) if progress else (lambda what: None)
    basis = build_basis(settler, progress=cb("basis"))
    tpl = build_templates(settler, progress=cb("templates"))
    if use_cache:
        _save(path, basis, tpl)
    return settler, basis, tpl
