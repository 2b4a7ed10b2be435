"""The constant-coefficient periodic Laplacian in Fourier space and its reference face
conductance: the one place each is written, for every FFT preconditioner (numba,
array-API, plain SciPy).

On an n1 x n2 x n3 periodic grid the 7-point Laplacian with face conductance ``g_ref``
(W/(m^2 K)) has the eigenvalues ``g_ref * sum_d 4 sin^2(pi xi_d / n_d)`` (per unit voxel
area: the voxel edge cancels between the operator and the load), ``xi_d = 0 .. n_d - 1``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["laplacian_symbol", "inverse_laplacian", "reference_conductance", "REFERENCES"]

#: The means of the positive face conductances a reference conductance may be.
REFERENCES = ("geometric", "arithmetic", "harmonic", "min", "max")


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


def reference_conductance(g: Any, reference: str | float = "geometric") -> float:
    """Face conductance g_ref of the constant-coefficient preconditioner, W/(m^2 K).

    Array-API code: ``g`` may live on any device (NumPy, CuPy, ...); one axis at a time, so
    the temporaries are a third of ``g``; sums in float64.

    Parameters
    ----------
    g : array, shape (3, n1, n2, n3)
        Face conductances (faces with g = 0 are ignored).
    reference : {"geometric", "arithmetic", "harmonic", "min", "max"} or float
        Mean of the positive face conductances to use, or a value in W/(m^2 K).

    Returns
    -------
    float
        1.0 where no face conducts.
    """
    if not isinstance(reference, str):
        v = float(reference)
        if not math.isfinite(v) or v <= 0:
            raise ValueError(f"reference: expected a positive conductance, got {reference!r}")
        return v
    if reference not in REFERENCES:
        raise ValueError(f"reference: unknown choice {reference!r} (geometric, arithmetic, "
                         "harmonic, min, max or a number)")
    import array_api_compat

    xp = array_api_compat.array_namespace(g)
    count, total, low, high = 0, 0.0, math.inf, 0.0
    for d in range(3):
        gd = xp.astype(g[d, ...], xp.float64)
        positive = gd > 0
        safe = xp.where(positive, gd, xp.ones_like(gd))
        count += int(xp.sum(xp.astype(positive, xp.int64)))
        if reference == "geometric":
            total += float(xp.sum(xp.where(positive, xp.log(safe), xp.zeros_like(gd))))
        elif reference == "arithmetic":
            total += float(xp.sum(gd))
        elif reference == "harmonic":
            total += float(xp.sum(xp.where(positive, 1.0 / safe, xp.zeros_like(gd))))
        elif reference == "min":
            low = min(low, float(xp.min(xp.where(positive, gd, xp.full_like(gd, math.inf)))))
        else:
            high = max(high, float(xp.max(gd)))
    if count == 0:
        return 1.0
    return {"geometric": lambda: math.exp(total / count), "arithmetic": lambda: total / count,
            "harmonic": lambda: count / total, "min": lambda: low,
            "max": lambda: high}[reference]()
