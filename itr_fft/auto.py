"""Pick the cheaper solver for a grid (placeholder crossover, set from the benchmark)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["choose_solver", "homogenize_auto", "CROSSOVER_VOXELS"]

#: Grids with fewer voxels than this are solved by itr_fv (measured crossover).
CROSSOVER_VOXELS = 0


def choose_solver(shape: int | Sequence[int]) -> str:
    """``"itr_fv"`` or ``"itr_fft"``, whichever the benchmark found cheaper for this grid."""
    n = int(np.prod(shape)) if not isinstance(shape, (int, np.integer)) else int(shape) ** 3
    return "itr_fv" if n < CROSSOVER_VOXELS else "itr_fft"


def homogenize_auto(ms, mat, **kwargs):
    """Dispatch to :func:`itr_fv.homogenize` or :func:`itr_fft.homogenize` by grid size."""
    if choose_solver(ms.shape) == "itr_fv":
        import itr_fv
        kwargs.pop("dtype", None)
        kwargs.pop("workers", None)
        kwargs.pop("reference", None)
        return itr_fv.homogenize(ms, mat, **kwargs)
    from .solver import homogenize
    return homogenize(ms, mat, **kwargs)
