"""A compressed-sparse-row matrix held as its three plain arrays, without importing scipy.

The live loop's kernels read a sparse matrix only through `indptr`, `indices` and `data`
(`sim.integrator._constant_forces`), so a face loaded from the cache (`puppet.face_cache`) carries
its muscle matrix as a `CsrArrays`: the start of a show does not pay for importing scipy.sparse
(~0.3 s). Anything else asked of it (products, slicing, `toarray`, ...) is answered by the
equivalent `scipy.sparse.csr_matrix`, built from the same arrays on first use, so code written
against scipy keeps working."""

from __future__ import annotations

from typing import Any

import numpy as np


class CsrArrays:
    """CSR matrix of `shape` (rows, cols): row r's entries are data[indptr[r]:indptr[r+1]] in the
    columns indices[indptr[r]:indptr[r+1]]. The arrays are used as given (not copied)."""

    __slots__ = ("data", "indices", "indptr", "shape", "_scipy")

    def __init__(self, data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, shape: tuple[int, int]) -> None:
        self.data, self.indices, self.indptr = data, indices, indptr
        self.shape = (int(shape[0]), int(shape[1]))
        self._scipy: Any = None

    @property
    def nnz(self) -> int:
        return int(self.indptr[-1])

    @property
    def dtype(self) -> np.dtype:  # type: ignore[type-arg]
        return self.data.dtype

    def tocsr(self) -> Any:
        """The same matrix as a scipy.sparse.csr_matrix (sharing the arrays; made once)."""
        if self._scipy is None:
            import scipy.sparse as sp

            self._scipy = sp.csr_matrix((self.data, self.indices, self.indptr), shape=self.shape)
        return self._scipy

    def toarray(self) -> np.ndarray:
        out = np.zeros(self.shape, dtype=self.data.dtype)
        rows = np.repeat(np.arange(self.shape[0]), np.diff(self.indptr))
        np.add.at(out, (rows, self.indices), self.data)
        return out

    def __matmul__(self, other: Any) -> Any:
        return self.tocsr() @ other

    def __rmatmul__(self, other: Any) -> Any:
        return other @ self.tocsr()

    def __getitem__(self, key: Any) -> Any:
        return self.tocsr()[key]

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.tocsr(), name)

    def __repr__(self) -> str:
        return f"CsrArrays(shape={self.shape}, nnz={self.nnz})"
