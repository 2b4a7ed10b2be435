"""A vectorised function over many points, in chunks on the process's cores.

The posterior's large evaluations (the importance draws of :func:`~itr_identify.inference.
joint.refine`, the conditional grids of :func:`~itr_identify.inference.marginal.
rao_blackwell`) are NumPy array work that releases the GIL, so chunks evaluated on threads
run side by side. The chunks are cut and their results joined in the same order whatever
the threads, so every number is the one a serial pass gives, bit for bit. The thread count
is the one the solvers use: numba's ``NUMBA_NUM_THREADS`` (the machine's cores unless set),
at most the machine's cores.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["map_chunks", "threads"]


def threads() -> int:
    """Threads for the chunked evaluations (module notes)."""
    import numba

    return int(max(1, min(numba.config.NUMBA_NUM_THREADS, os.cpu_count() or 1)))


def map_chunks(fn: Callable[[np.ndarray], np.ndarray], points: np.ndarray, *, chunk: int,
               workers: int | None = None) -> Iterator[np.ndarray]:
    """``fn`` of each ``chunk`` rows of ``points`` (N, D), in order, on ``workers`` threads
    (default :func:`threads`); ``fn`` must not change shared state."""
    if chunk < 1:
        raise ValueError(f"chunk: expected a whole number >= 1, got {chunk!r}")
    parts = [points[i:i + chunk] for i in range(0, points.shape[0], chunk)]
    n = min(workers or threads(), len(parts))
    if n <= 1:
        yield from map(fn, parts)
        return
    with ThreadPoolExecutor(n) as pool:
        yield from pool.map(fn, parts)
