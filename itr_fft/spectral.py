"""The constant-coefficient periodic Laplacian in Fourier space: the one place its symbol is
written, for every FFT preconditioner (numba, array-API, plain SciPy).

On an n1 x n2 x n3 periodic grid the 7-point Laplacian with face conductance ``g_ref``
(W/(m^2 K)) has the eigenvalues ``g_ref * sum_d 4 sin^2(pi xi_d / n_d)`` (per unit voxel
area: the voxel edge cancels between the operator and the load), ``xi_d = 0 .. n_d - 1``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["laplacian_symbol", "inverse_laplacian"]


def laplacian_symbol(n: int) -> np.ndarray:
    """``4 sin^2(pi xi / n)`` for ``xi = 0 .. n-1``: the periodic 1-D second difference's
    eigenvalues (float64, dimensionless)."""
    return 4.0 * np.sin(np.pi * np.arange(n) / n) ** 2


def inverse_laplacian(shape: tuple[int, int, int], g_ref: float) -> np.ndarray:
    """``1 / (g_ref * lambda)`` on the half spectrum of a real FFT (last axis
    ``n3 // 2 + 1``), 0 at the zero mode (the constant null space), m^2 K/W.

    Parameters
    ----------
    shape : tuple of 3 ints
        The voxel grid.
    g_ref : float
        Reference face conductance, W/(m^2 K) (> 0).
    """
    s = [laplacian_symbol(n) for n in shape]
    lam = s[0][:, None, None] + s[1][None, :, None] + s[2][None, None, : shape[2] // 2 + 1]
    with np.errstate(divide="ignore"):
        return np.where(lam > 0, 1.0 / (g_ref * lam), 0.0)
