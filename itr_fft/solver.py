"""``itr_fft.homogenize``: the FFT solver's entry point (the ``"itr_fft"`` backend of
:mod:`itr_fft.numba_backend` on the driver :func:`itr_fv.solvers.driver.homogenize`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from itr_fv.discrete.model import FaceGeometry
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.materials import Materials
from itr_fv.rve.microstructure import Microstructure
from itr_fv.solvers.driver import Callback
from itr_fv.solvers.driver import homogenize as _drive
from itr_fv.solvers.result import HomogenizationResult

from .numba_backend import NumbaFFTBackend

__all__ = ["homogenize"]


def homogenize(ms: Microstructure | DiscreteProblem, mat: Materials, tol: float = 1e-8,
               maxiter: int | None = None, directions: Sequence[int] = (0, 1, 2),
               staircase: bool = True, callback: Callback | None = None,
               x0: np.ndarray | None = None, strict: bool = True, store_fields: bool = True,
               geometry: FaceGeometry | None = None, *, dtype: type = np.float64,
               workers: int | None = None, reference: str | float = "geometric",
               fft_dtype: type = np.float32, check_memory: bool = True,
               preconditioner: str = "auto", fft: str = "scipy") -> HomogenizationResult:
    """Effective conductivity tensor by FFT-preconditioned CG (same system as itr_fv).

    The same as :func:`itr_fv.solvers.driver.homogenize` with
    ``backend=NumbaFFTBackend(dtype, workers, reference, fft_dtype, preconditioner, fft)``; the
    options are those of :class:`~itr_fft.numba_backend.NumbaFFTBackend`.

    Parameters
    ----------
    ms : Microstructure or DiscreteProblem
        Voxel image with particle ids, or its :class:`~itr_fv.discrete.problem.DiscreteProblem`
        (geometry built once, reused for many parameter sets).
    mat : Materials
        Conductivities (W/(m K)) and interface resistances (m^2 K/W).
    tol : float
        Relative residual ||b - A theta|| / ||b|| to reach, in (0, 1); checked on the true
        residual (float64) at the end.
    maxiter : int, optional
        CG iterations per load case (default 3000).
    directions : sequence of int
        Load cases E = e_d to solve (0, 1, 2 = x, y, z).
    staircase : bool
        Staircase correction s = |n_x|+|n_y|+|n_z| of interface resistances.
    callback : callable, optional
        ``callback(direction, iteration, relative_residual)`` after every CG iteration
        (recursive residual).
    x0 : ndarray, optional
        Warm start, shape (len(directions), n1, n2, n3): theta of a neighbouring solve
        (e.g. ``previous_result.theta``).
    strict : bool
        Raise :class:`~itr_fv.ConvergenceError` on non-convergence (else warn and flag).
    store_fields : bool
        Keep temperature, theta and face fluxes in the result.
    geometry : FaceGeometry, optional
        Precomputed ``face_geometry(ms, staircase)`` to reuse across parameter sets.
    dtype, workers, reference, fft_dtype, preconditioner, fft
        Options of :class:`~itr_fft.numba_backend.NumbaFFTBackend` (vector precision,
        threads, reference conductance of the FFT preconditioner, FFT precision, the
        preconditioner: ``"auto"``, ``"fft"`` or ``"multigrid"``, and its FFT pair:
        ``"scipy"`` or ``"fftw"``, the extra ``itr-composites[fft]``).
    check_memory : bool
        Estimate the peak memory first (:mod:`itr_fv.solvers.resources`) and raise
        :class:`~itr_fv.solvers.resources.InsufficientMemoryError` if it exceeds the available
        memory; False skips the check.

    Returns
    -------
    HomogenizationResult
        ``solver == "itr_fft"``; ``info`` holds ``g_ref`` (W/(m^2 K)), ``dtype``,
        ``workers``, ``restarts`` (CG restarts per load case), ``contact`` (the contact
        model) and face counts.
    """
    backend = NumbaFFTBackend(dtype=dtype, workers=workers, reference=reference,
                              fft_dtype=fft_dtype, preconditioner=preconditioner, fft=fft)
    return _drive(ms, mat, backend=backend, tol=tol, maxiter=maxiter, directions=directions,
                  x0=x0, callback=callback, strict=strict, store_fields=store_fields,
                  check_memory=check_memory, staircase=staircase, geometry=geometry)
