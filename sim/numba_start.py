"""A cheaper first numba dispatch: numba's BLAS check without importing all of scipy.linalg.

The first call of any numba kernel, even one loaded from numba's on-disk cache, initialises numba's
CPU target, and that imports `numba.np.arraymath`, whose module-level BLAS check runs
`import scipy.linalg.cython_blas`. Importing that submodule the normal way first executes
`scipy/linalg/__init__.py`, which pulls in scipy's array-API layer and, through it, `numpy.f2py`:
0.15-0.3 s of a warm `puppet live` start, for a check whose only use is to see that the BLAS
extension loads. `prepare_blas_check()` loads that one extension module directly from scipy's
folder and registers it under its full name, so numba's import finds it and the rest of
scipy.linalg is not imported until something really uses it (it then imports normally, reusing
this module object).

Nothing changes if scipy.linalg or numba's target is already loaded, or if scipy's layout is not
the expected one: numba then does its own import, exactly as before.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from pathlib import Path

NAME = "scipy.linalg.cython_blas"


def prepare_blas_check() -> bool:
    """Load scipy's cython_blas extension on its own, unless it (or scipy.linalg, or numba's array
    maths) is loaded already. Returns whether it is in sys.modules afterwards."""
    if NAME in sys.modules:
        return True
    if "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules:
        return False
    try:
        spec = importlib.util.find_spec("scipy")
        if spec is None or not spec.submodule_search_locations:
            return False
        folder = Path(next(iter(spec.submodule_search_locations))) / "linalg"
        path = next((folder / f"cython_blas{suffix}" for suffix in importlib.machinery.EXTENSION_SUFFIXES
                     if (folder / f"cython_blas{suffix}").is_file()), None)
        if path is None:
            return False
        import scipy  # noqa: F401  (the parent package, light; the extension imports scipy's helpers)

        loader = importlib.machinery.ExtensionFileLoader(NAME, str(path))
        ext_spec = importlib.util.spec_from_file_location(NAME, str(path), loader=loader)
        if ext_spec is None:
            return False
        module = importlib.util.module_from_spec(ext_spec)
        sys.modules[NAME] = module
        try:
            loader.exec_module(module)
        except BaseException:
            sys.modules.pop(NAME, None)
            raise
        return True
    except Exception:  # any surprise: numba imports it the usual way
        return False
