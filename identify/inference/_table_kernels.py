"""Compiled (multi)linear interpolation of the joint likelihood's forward-model tables.

The joint posterior evaluates every formulation's table at every point, millions of times
in a run (the chain, the importance draws, the Rao-Blackwell grids). NumPy's version of
the interpolation gathers each corner into a temporary (3, F, N) array; these loops make
one pass with the same arithmetic in the same order, so each number is NumPy's to the last
bit (tested), about four times faster. They release the GIL: the chunked evaluations
(:mod:`.chunked`) run them side by side.
"""

from __future__ import annotations

import numpy as np

from itr_fv.numba_cache import njit

__all__ = ["linear_1d", "linear_2d"]


@njit(nogil=True)
def _place(x: float, lo: float, step: float, last: float) -> tuple[int, float]:
    """The cell and the weight of ``x`` on an axis from ``lo`` by ``step`` (clipped into
    ``[0, last]`` as :func:`numpy.clip` does)."""
    t = (x - lo) / step
    if t < 0.0 or np.isnan(t):
        t = 0.0
    elif t > last:
        t = last
    i = int(t)
    return i, t - i


@njit(nogil=True)
def linear_1d(values: np.ndarray, x: np.ndarray, lo: float, step: float,
              last: float) -> np.ndarray:
    """``values`` (C, F, G) on the axis ``lo + step * g`` interpolated linearly at ``x``
    (F, N), each row ``f`` in its own table; returns (C, F, N)."""
    n_c, n_f = values.shape[0], values.shape[1]
    n = x.shape[1]
    out = np.empty((n_c, n_f, n))
    for f in range(n_f):
        for k in range(n):
            i, w = _place(x[f, k], lo, step, last)
            for c in range(n_c):
                out[c, f, k] = values[c, f, i] * (1 - w) + values[c, f, i + 1] * w
    return out


@njit(nogil=True)
def linear_2d(values: np.ndarray, x: np.ndarray, y: np.ndarray, lo: np.ndarray,
              step: np.ndarray, last: np.ndarray) -> np.ndarray:
    """``values`` (C, F, G1, G2) on two regular axes (``lo``, ``step``, ``last`` per axis)
    interpolated bilinearly at (``x``, ``y``), each (F, N); returns (C, F, N)."""
    n_c, n_f = values.shape[0], values.shape[1]
    n = x.shape[1]
    out = np.empty((n_c, n_f, n))
    for f in range(n_f):
        for k in range(n):
            i, a = _place(x[f, k], lo[0], step[0], last[0])
            j, b = _place(y[f, k], lo[1], step[1], last[1])
            for c in range(n_c):
                out[c, f, k] = ((1 - a) * (1 - b) * values[c, f, i, j]
                                + a * (1 - b) * values[c, f, i + 1, j]
                                + (1 - a) * b * values[c, f, i, j + 1]
                                + a * b * values[c, f, i + 1, j + 1])
    return out
