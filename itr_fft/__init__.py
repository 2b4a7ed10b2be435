"""itr_fft: FFT-preconditioned CG backends of the discrete model of :mod:`itr_fv.discrete.model`.

A solve goes through the package's one door, ``itr_fv.homogenize``, with a solver::

    from itr_fv import homogenize, resolve_solver
    res = homogenize(ms, mat, solver="fft", tol=1e-8)
    res = homogenize(ms, mat, solver=resolve_solver("fft", preconditioner="multigrid"))

(``itr_fft.homogenize(ms, mat, tol, **options)`` of earlier releases is gone: its options
are those of ``resolve_solver("fft", **options)``.)

Importing the package registers three backends of :func:`itr_fv.homogenize`:
``"itr_fft"`` (:mod:`itr_fft.numba_backend`, fused numba kernels, the fast one on a CPU;
its preconditioner is the FFT Laplacian inverse or, with ``preconditioner="multigrid"``,
particle deflation around an aggregation multigrid, :mod:`itr_fft.multigrid`,
:mod:`itr_fft.deflation`), ``"array_api"`` (:mod:`itr_fft.array_api_backend`, the same
FFT-PCG written once against the array API standard: NumPy, CuPy or PyTorch arrays, CPU or
GPU) and ``"scipy_fft"`` (:mod:`itr_fft.scipy_backend`, plain numpy/scipy). This package imports the
discrete problem, the driver and CG from ``itr_fv``, never its solver.

Importing the package sets ``OMP_WAIT_POLICY=PASSIVE`` unless the caller set it: numba's
OpenMP threads otherwise spin at every barrier, and on a machine shared with other jobs
(2 cores, load 4-6) that made two threads 5-10x slower than one; passive waiting made
them ~2x faster than one. It has to be in place before numba starts its thread pool.
"""

import os as _os

_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from .array_api_backend import ArrayAPIBackend, resolve_device
from .numba_backend import (
    FLOAT32_MIN_TOL,
    PRECONDITIONERS,
    NumbaFFTBackend,
    float32_min_tol,
    reference_conductance,
)
from .scipy_backend import ScipyFFTBackend

__all__ = ["reference_conductance", "FLOAT32_MIN_TOL", "float32_min_tol",
           "NumbaFFTBackend", "ScipyFFTBackend", "ArrayAPIBackend", "resolve_device",
           "PRECONDITIONERS"]


def __getattr__(name: str):
    """``itr_fft.homogenize`` of earlier releases is gone: one line saying where it went."""
    if name == "homogenize":
        raise AttributeError("itr_fft.homogenize was removed: every solve goes through "
                             "itr_fv.homogenize(ms, mat, solver=itr_fv.resolve_solver('fft', "
                             "**options), tol=...)")
    raise AttributeError(f"module 'itr_fft' has no attribute {name!r}")
