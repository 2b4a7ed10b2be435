"""``itr_fv.homogenize``: the reference solver's entry point (the ``"itr_fv"`` backend of
:mod:`itr_fv.solvers.amg` on the driver :func:`itr_fv.solvers.driver.homogenize`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..discrete.model import FaceGeometry
from ..discrete.problem import DiscreteProblem
from ..materials.properties import Materials
from ..rve.microstructure import Microstructure
from .amg import AMGBackend
from .driver import Callback
from .driver import homogenize as _drive
from .result import HomogenizationResult

__all__ = ["homogenize"]


def homogenize(ms: Microstructure | DiscreteProblem, mat: Materials, tol: float = 1e-8,
               maxiter: int | None = None, directions: Sequence[int] = (0, 1, 2),
               staircase: bool = True, callback: Callback | None = None,
               x0: np.ndarray | None = None, strict: bool = True, store_fields: bool = True,
               geometry: FaceGeometry | None = None, amg: str = "classical", *,
               check_memory: bool = True) -> HomogenizationResult:
    """Effective conductivity tensor by the reference finite-volume solver.

    Assembles the sparse operator of :mod:`itr_fv.discrete.model`, builds one pyamg hierarchy
    (classical or smoothed aggregation) and uses it as the CG preconditioner for every
    load case. The same as :func:`itr_fv.solvers.driver.homogenize` with
    ``backend=AMGBackend(amg)``.

    Parameters
    ----------
    ms : Microstructure or DiscreteProblem
        Voxel image with particle ids, or its :class:`~itr_fv.discrete.problem.DiscreteProblem`
        (geometry built once, reused for many parameter sets).
    mat : Materials
        Conductivities (W/(m K)) and interface resistances (m^2 K/W).
    tol : float
        Relative residual ||b - A theta|| / ||b|| to reach, in (0, 1).
    maxiter : int, optional
        CG iterations per load case (default 500).
    directions : sequence of int
        Load cases E = e_d to solve (0, 1, 2 = x, y, z).
    staircase : bool
        Staircase correction s = |n_x|+|n_y|+|n_z| of interface resistances.
    callback : callable, optional
        ``callback(direction, iteration, relative_residual)`` after every CG iteration.
    x0 : ndarray, optional
        Warm start, shape (len(directions), n1, n2, n3): theta of a neighbouring solve.
    strict : bool
        Raise :class:`~itr_fv.ConvergenceError` on non-convergence (else warn and flag).
    store_fields : bool
        Keep temperature, theta and face fluxes in the result.
    geometry : FaceGeometry, optional
        Precomputed ``face_geometry(ms, staircase)`` to reuse across parameter sets.
    amg : {"classical", "smoothed_aggregation"}
        pyamg hierarchy used as the preconditioner (see :class:`~itr_fv.solvers.amg.AMGBackend`).
    check_memory : bool
        Estimate the peak memory first (:mod:`itr_fv.solvers.resources`) and raise
        :class:`~itr_fv.solvers.resources.InsufficientMemoryError` if it exceeds the available
        memory; False skips the check.

    Returns
    -------
    HomogenizationResult
        ``k_eff`` in W/(m K), iterations, residuals, fields, times; ``info`` holds the AMG
        hierarchy's levels and complexity, ``restarts`` (CG restarts per load case),
        ``contact`` (the contact model) and face counts.
    """
    return _drive(ms, mat, backend=AMGBackend(amg), tol=tol, maxiter=maxiter,
                  directions=directions, x0=x0, callback=callback, strict=strict,
                  store_fields=store_fields, check_memory=check_memory, staircase=staircase,
                  geometry=geometry)
