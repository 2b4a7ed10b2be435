"""Reference solver: sparse 7-point assembly, pyamg smoothed aggregation, preconditioned CG."""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
import pyamg
import pyamg.krylov
import scipy.sparse

from . import resources
from .materials import Materials
from .microstructure import Microstructure
from .model import FaceGeometry, load_vector
from .problem import DiscreteProblem
from .result import HomogenizationResult
from .solver_common import (
    Callback,
    SolveRecord,
    as_problem,
    build_result,
    check_solver_args,
    check_x0,
)

__all__ = ["homogenize", "assemble_operator"]


def assemble_operator(g: np.ndarray) -> scipy.sparse.csr_array:
    """Sparse matrix A of the periodic 7-point operator (W/(m^2 K)), no Python voxel loop.

    ``(A theta)_p = sum over faces of g (theta_p - theta_q)``; symmetric, positive
    semi-definite, constants in its null space (one per connected cluster).

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances from :mod:`itr_fv.model`.

    Returns
    -------
    scipy.sparse.csr_array, shape (N, N), N = n1 n2 n3 (C order)
    """
    shape = g.shape[1:]
    N = int(np.prod(shape))
    ids = np.arange(N, dtype=np.int64).reshape(shape)
    diag = np.zeros(shape)
    rows, cols, vals = [], [], []
    for d in range(3):
        if shape[d] == 1:  # a face between a voxel and its own image carries no theta coupling
            continue
        diag += g[d]
        diag += np.roll(g[d], 1, axis=d)
        nb = np.roll(ids, -1, axis=d).ravel()
        gd = g[d].ravel()
        rows += [ids.ravel(), nb]
        cols += [nb, ids.ravel()]
        vals += [-gd, -gd]
    rows.append(ids.ravel())
    cols.append(ids.ravel())
    vals.append(diag.ravel())
    A = scipy.sparse.coo_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                               shape=(N, N)).tocsr()
    A.sum_duplicates()
    A.eliminate_zeros()
    return A


def _pin(A: scipy.sparse.csr_array, pins: np.ndarray) -> scipy.sparse.csr_array:
    """Replace row and column of each pinned voxel by the identity (exact gauge fix).

    Each cluster's equations sum to zero, so one equation per cluster is redundant; fixing
    theta = 0 there and dropping that equation leaves the other values unchanged and makes
    the matrix symmetric positive definite.
    """
    keep = np.ones(A.shape[0])
    keep[pins] = 0.0
    P = scipy.sparse.diags_array(keep)
    Ap = (P @ A @ P).tocsr()
    # the pinned row keeps its own diagonal (not 1): a drift of theta there then weighs in
    # the residual as it would in the original equations
    diag = A.diagonal()
    scale = np.where(diag[pins] > 0, diag[pins], 1.0)
    fix = np.zeros(A.shape[0])
    fix[pins] = scale
    Ap = Ap + scipy.sparse.diags_array(fix)
    Ap = scipy.sparse.csr_array(Ap)
    Ap.eliminate_zeros()
    return Ap


_AMG = ("classical", "smoothed_aggregation")


def _amg_hierarchy(A: scipy.sparse.csr_array, amg: str) -> pyamg.multilevel.MultilevelSolver:
    """pyamg hierarchy of the pinned (SPD) operator."""
    if amg == "classical":
        return pyamg.ruge_stuben_solver(scipy.sparse.csr_matrix(A), max_coarse=400)
    return pyamg.smoothed_aggregation_solver(scipy.sparse.csr_matrix(A), B=np.ones((A.shape[0], 1)),
                                             symmetry="symmetric", max_coarse=400)


def homogenize(ms: Microstructure | DiscreteProblem, mat: Materials, tol: float = 1e-8,
               maxiter: int | None = None, directions: Sequence[int] = (0, 1, 2),
               staircase: bool = True, callback: Callback | None = None,
               x0: np.ndarray | None = None, strict: bool = True, store_fields: bool = True,
               geometry: FaceGeometry | None = None, amg: str = "classical", *,
               check_memory: bool = True) -> HomogenizationResult:
    """Effective conductivity tensor by the reference finite-volume solver.

    Assembles the sparse operator of :mod:`itr_fv.model`, builds one pyamg hierarchy
    (classical or smoothed aggregation) and uses it as the CG preconditioner for every
    load case.

    Parameters
    ----------
    ms : Microstructure or DiscreteProblem
        Voxel image with particle ids, or its :class:`~itr_fv.problem.DiscreteProblem`
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
        pyamg hierarchy used as the preconditioner: Ruge-Stueben classical AMG (default;
        on these M-matrices with jumping conductances it needs 3-4x fewer CG iterations
        than smoothed aggregation, see validation/results/bench_fv.md) or smoothed
        aggregation.
    check_memory : bool
        Estimate the peak memory first (:mod:`itr_fv.resources`) and raise
        :class:`~itr_fv.resources.InsufficientMemoryError` if it exceeds the available
        memory; False skips the check.

    Returns
    -------
    HomogenizationResult
        ``k_eff`` in W/(m K), iterations, residuals, fields, times; ``info`` holds the AMG
        hierarchy's levels and complexity, ``restarts`` (CG restarts per load case),
        ``contact`` (the contact model) and face counts.
    """
    t0 = time.perf_counter()
    problem = ms if isinstance(ms, DiscreteProblem) else None
    ms = problem.microstructure if problem is not None else ms
    tol, maxiter, dirs = check_solver_args(ms, mat, tol, maxiter, directions, callback, 500)
    if amg not in _AMG:
        raise ValueError(f"amg: expected one of {sorted(_AMG)}, got {amg!r}")
    x0 = check_x0(x0, ms.shape, dirs)
    if check_memory:
        resources.check_memory(ms.shape, "itr_fv", store_fields=store_fields,
                               load_cases=len(dirs))
    problem = as_problem(problem or ms, mat, staircase, geometry)
    geometry = problem.geometry
    system = problem.system(mat)
    g, floating, labels = system.g, system.floating, system.labels
    if labels is None:
        pins = np.array([0])
    else:
        pins = np.unique(labels.ravel(), return_index=True)[1]
    A = assemble_operator(g)
    Ap = _pin(A, pins)
    ml = _amg_hierarchy(Ap, amg)
    M = ml.aspreconditioner(cycle="V")
    setup = time.perf_counter() - t0
    records = []
    restarts = []
    for c, d in enumerate(dirs):
        t1 = time.perf_counter()
        E = np.zeros(3)
        E[d] = 1.0
        b = load_vector(g, ms.voxel_m, E).ravel()
        b[pins] = 0.0
        normb = float(np.linalg.norm(b))
        if normb == 0.0:
            theta = np.zeros(ms.shape)
            records.append(SolveRecord(d, theta, 0, [0.0], 0.0, time.perf_counter() - t1))
            restarts.append(0)
            continue
        start = np.zeros_like(b) if x0 is None else x0[c].ravel().copy()
        start[pins] = 0.0
        history: list[float] = [float(np.linalg.norm(b - Ap @ start)) / normb]
        raw: list[float] = []

        def _cb(xk, _d=d):
            history.append(raw[-1] / normb)
            if callback is not None:
                callback(_d, len(history) - 1, history[-1])

        x, res = start, history[0]
        # CG's recursive residual can drift below the true one near round-off: restart
        # from the current iterate (at most 3 times) until the true residual meets tol.
        runs = 0
        for _restart in range(4):
            if res <= tol or len(history) - 1 >= maxiter:
                break
            runs += 1
            x, _info = pyamg.krylov.cg(Ap, b, x0=x, tol=tol, maxiter=maxiter - len(history) + 1,
                                       M=M, callback=_cb, residuals=raw)
            res = float(np.linalg.norm(b - Ap @ x)) / normb
        records.append(SolveRecord(d, x.reshape(ms.shape), len(history) - 1, history, res,
                                   time.perf_counter() - t1))
        restarts.append(max(runs - 1, 0))
    info = {"amg": amg, "amg_levels": len(ml.levels),
            "operator_complexity": float(ml.operator_complexity()),
            "unknowns": int(A.shape[0]), "interface_faces": geometry.n_interface_faces,
            "contact_faces": geometry.n_contact_faces, "contact": problem.contact,
            "staircase": geometry.staircase, "restarts": restarts}
    return build_result(ms, g, records, labels=labels, floating=floating, tol=tol,
                        setup_time=setup, wall_time=time.perf_counter() - t0, solver="itr_fv",
                        store_fields=store_fields, strict=strict, info=info)
