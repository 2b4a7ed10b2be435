"""Pick the cheaper solver for a grid, from the measured crossover (the campaign layer's
choice: ``itr_fft`` knows nothing of ``itr_fv``'s solver).

Measured (validation/results/crossval.md, bench_solvers.md; shared 2-core machine):
itr_fft was faster than itr_fv at every size tried -- 24^3 (0.1-0.3 s vs 0.6-20 s),
64^3 (1-7 s vs 21-32 s for the sphere arrays, 3 s vs FV for the dense 60 % RVE) and
128^3 -- because pyamg's set-up alone costs more than the whole FFT solve. There is no
crossover in the measured range, so ``CROSSOVER_VOXELS = 0``: always itr_fft. itr_fv stays
the reference (and the fallback a caller can force).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["choose_solver", "homogenize_auto", "CROSSOVER_VOXELS"]

#: Grids with fewer voxels than this are solved by itr_fv (measured: none, see above).
CROSSOVER_VOXELS = 0


def choose_solver(shape: int | Sequence[int]) -> str:
    """``"itr_fv"`` or ``"itr_fft"``, whichever the benchmark found cheaper for this grid."""
    n = int(np.prod(shape)) if not isinstance(shape, (int, np.integer)) else int(shape) ** 3
    return "itr_fv" if n < CROSSOVER_VOXELS else "itr_fft"


def homogenize_auto(ms, mat, **kwargs):
    """Dispatch to :func:`itr_fv.homogenize` or :func:`itr_fft.homogenize` by grid size.

    ``ms`` may be a Microstructure or a DiscreteProblem; the FFT solver's own options
    (``dtype``, ``workers``, ``reference``, ``fft_dtype``) are dropped for itr_fv.
    """
    if choose_solver(ms.shape) == "itr_fv":
        import itr_fv
        for option in ("dtype", "workers", "reference", "fft_dtype"):
            kwargs.pop(option, None)
        return itr_fv.homogenize(ms, mat, **kwargs)
    import itr_fft
    return itr_fft.homogenize(ms, mat, **kwargs)
