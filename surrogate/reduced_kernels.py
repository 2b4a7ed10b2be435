"""Compiled online stage of the reduced-basis model: many parameter sets, one small system each.

For every parameter set the reduced operator ``M = sum_t theta_t G_t`` (S x S) is assembled
(one matrix product per chunk of parameter sets), each load case's Galerkin block is solved
by Cholesky, and ``K = C^T M C`` is formed: one parallel loop over the parameter sets, each
iteration a serial helper (no reduction variable in the parallel body). Kernels are cached
on disk (:mod:`itr_fv.numba_cache`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from itr_fv.numba_cache import njit

__all__ = ["galerkin_tensors"]

_PAR = dict(parallel=True, fastmath=False, nogil=True)
_SER = dict(fastmath=False, nogil=True)


@njit(**_SER)
def _cholesky_solve(M, o, m, x):  # pragma: no cover - compiled
    """x = -(M[o+1:o+1+m, o+1:o+1+m])^-1 M[o+1:o+1+m, o] (SPD block), in place in x."""
    L = np.zeros((m, m))
    for j in range(m):
        s = M[o + 1 + j, o + 1 + j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if s <= 0.0:
            s = 1e-300
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, m):
            t = M[o + 1 + i, o + 1 + j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
    for i in range(m):  # forward: L y = -f
        t = -M[o + 1 + i, o]
        for k in range(i):
            t -= L[i, k] * x[k]
        x[i] = t / L[i, i]
    for i in range(m - 1, -1, -1):  # back: L^T x = y
        t = x[i]
        for k in range(i + 1, m):
            t -= L[k, i] * x[k]
        x[i] = t / L[i, i]


@njit(**_SER)
def _one_tensor(M, blocks, scale, out):  # pragma: no cover - compiled
    S = M.shape[0]
    C = np.zeros((S, 3))
    x = np.zeros(S)
    for i in range(3):
        o, m = blocks[i, 0], blocks[i, 1]
        C[o, i] = 1.0
        if m > 0:
            _cholesky_solve(M, o, m, x)
            for a in range(m):
                C[o + 1 + a, i] = x[a]
    MC = np.zeros((S, 3))
    for a in range(S):
        for b in range(S):
            mab = M[a, b]
            for j in range(3):
                MC[a, j] += mab * C[b, j]
    for i in range(3):
        for j in range(3):
            s = 0.0
            for a in range(S):
                s += C[a, i] * MC[a, j]
            out[i, j] = s
    for i in range(3):
        for j in range(i + 1, 3):
            v = 0.5 * (out[i, j] + out[j, i]) * scale
            out[i, j] = v
            out[j, i] = v
        out[i, i] *= scale


@njit(**_PAR)
def _tensors(M, blocks, scale, out):  # pragma: no cover - compiled
    for n in nb.prange(M.shape[0]):
        _one_tensor(M[n], blocks, scale, out[n])


def galerkin_tensors(theta: np.ndarray, gram: np.ndarray, blocks: np.ndarray,
                     scale: float, chunk: int = 1024) -> np.ndarray:
    """Galerkin effective tensors (n, 3, 3), W/(m K).

    Parameters
    ----------
    theta : ndarray (n, T)
        Coefficients of the operator terms per parameter set.
    gram : ndarray (T, S, S)
        Reduced matrices of the terms, columns ordered ``[l_0, basis of x, l_1, ...]``.
    blocks : ndarray of int64 (3, 2)
        Offset of ``l_i`` and the number of basis columns of load case i.
    scale : float
        ``1 / (N h)``, 1/m.
    """
    n, S = theta.shape[0], gram.shape[1]
    flat = np.ascontiguousarray(gram).reshape(gram.shape[0], S * S)
    blocks = np.ascontiguousarray(blocks, dtype=np.int64)
    out = np.empty((n, 3, 3))
    for s in range(0, n, chunk):  # assembly by BLAS, a cache-sized chunk at a time
        M = (theta[s:s + chunk] @ flat).reshape(-1, S, S)
        _tensors(M, blocks, float(scale), out[s:s + chunk])
    return out
