"""FFT-preconditioned conjugate gradients on the discrete model of :mod:`itr_fv.model`.

The operator is exactly the one ``itr_fv`` assembles (same face conductances, imported from
``itr_fv.model``), applied matrix-free by a fused numba stencil kernel. The preconditioner
is the exact inverse of the constant-coefficient periodic 7-point operator with face
conductance ``g_ref`` (W/(m^2 K)), i.e. of ``k_ref / h^2 * sum_d 4 sin^2(pi xi_d / n_d)``
times the voxel volume per face area h with ``k_ref = g_ref h``, zero mode removed, applied
with real FFTs (``scipy.fft.rfftn`` / ``irfftn``).

Choice of ``g_ref``: preconditioned CG is invariant under a constant rescaling of the
preconditioner (z -> z / c rescales alpha by c and leaves beta, the iterates and the
residuals unchanged), so ``g_ref`` does not change the iteration count; it only sets the
units/magnitude of the preconditioned residual. The default is the geometric mean of the
positive face conductances (measured: min / geometric / arithmetic / max give the same
iteration counts, see ``validation/results/bench_solvers.md``). The iteration count is
governed by the spread of the face conductances, roughly ``sqrt(max g / min g)`` for the
worst case, and by the interface resistance relative to the voxel: a resistive interface
of ``R >> h / k_m`` adds small eigenvalues ~ ``h / (R k)`` that grow the count under grid
refinement.

Memory: the float64 conductances (3 N), the CG vectors x, r, p, q (4 N), and per
iteration the rfftn half spectrum (~N) and the irfftn output z (N), where N = n1 n2 n3.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence

import numba
import numpy as np
import scipy.fft

from itr_fv import resources
from itr_fv.materials import Materials
from itr_fv.microstructure import Microstructure
from itr_fv.model import FaceGeometry
from itr_fv.problem import DiscreteProblem
from itr_fv.result import HomogenizationResult
from itr_fv.solver_common import (
    Callback,
    SolveRecord,
    as_problem,
    build_result,
    check_solver_args,
    check_x0,
)

from . import _kernels as K

__all__ = ["homogenize", "reference_conductance", "FLOAT32_MIN_TOL", "float32_min_tol"]

#: Smallest relative residual accepted with ``dtype=np.float32``: the rounding of a float32
#: theta alone leaves a relative residual of a few 1e-7 (it grows with the grid size).
FLOAT32_MIN_TOL = 1e-6


def float32_min_tol(shape: Sequence[int]) -> float:
    """Smallest tol accepted with float32 vectors on a grid of this shape.

    The rounding of a float32 theta leaves a residual floor that grows like n^2 (the
    operator amplifies the rounding noise of neighbouring voxels): measured on the dense
    60 % Al2O3 RVE, CG stalls at 9e-6 on 256^3. The floor used, ``max(1e-6, 2.5e-10 n^2)``
    (n the largest grid dimension), keeps a margin of ~2x above the stall.
    """
    return max(FLOAT32_MIN_TOL, 2.5e-10 * float(max(shape)) ** 2)

_MAX_RESTARTS = 5

#: Grids with fewer voxels than this run single-threaded by default.
SERIAL_BELOW = 40 ** 3


def reference_conductance(g: np.ndarray, reference: str | float = "geometric") -> float:
    """Face conductance g_ref of the constant-coefficient preconditioner, W/(m^2 K).

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances (faces with g = 0 are ignored).
    reference : {"geometric", "arithmetic", "harmonic", "min", "max"} or float
        Mean of the positive face conductances to use, or a value in W/(m^2 K).

    Returns
    -------
    float
    """
    if not isinstance(reference, str):
        v = float(reference)
        if not math.isfinite(v) or v <= 0:
            raise ValueError(f"reference: expected a positive conductance, got {reference!r}")
        return v
    if reference == "geometric":
        s, c = K.log_sum_positive(g)
        return float(math.exp(s / c)) if c else 1.0
    pos = g[g > 0]
    if pos.size == 0:
        return 1.0
    if reference == "arithmetic":
        return float(pos.mean())
    if reference == "harmonic":
        return float(pos.size / np.sum(1.0 / pos))
    if reference == "min":
        return float(pos.min())
    if reference == "max":
        return float(pos.max())
    raise ValueError(f"reference: unknown choice {reference!r} (geometric, arithmetic, "
                     "harmonic, min, max or a number)")


class _Preconditioner:
    """z = P (g_ref L)^+ P r with real FFTs; P removes cluster means when there are several."""

    def __init__(self, shape: tuple[int, int, int], g_ref: float, workers: int,
                 labels_flat: np.ndarray | None, counts: np.ndarray | None,
                 fft_dtype: np.dtype) -> None:
        self.shape = shape
        self.fft_dtype = fft_dtype
        self.s = [K.laplacian_symbol(n) for n in shape]
        self.inv_gref = 1.0 / g_ref
        self.workers = workers
        self.labels_flat = labels_flat
        self.counts = counts

    def __call__(self, r: np.ndarray) -> tuple[np.ndarray, float]:
        r_in = r if r.dtype == self.fft_dtype else r.astype(self.fft_dtype)
        rhat = scipy.fft.rfftn(r_in, workers=self.workers)
        del r_in
        rz = K.spectral_solve(rhat, self.s[0], self.s[1], self.s[2], self.shape[2],
                              self.inv_gref)
        z = scipy.fft.irfftn(rhat, s=self.shape, workers=self.workers, overwrite_x=True)
        del rhat
        if self.labels_flat is not None:
            K.project_clusters(z, self.labels_flat, self.counts)
        return z, rz


def _pcg(g: np.ndarray, d: int, h: float, x: np.ndarray, M: _Preconditioner, tol: float,
         maxiter: int, callback: Callback | None, labels_flat: np.ndarray | None,
         counts: np.ndarray | None) -> tuple[int, list[float], float, int]:
    """Solve A x = b(e_d) in place from the start x.

    Returns (iterations, residual history, final true residual, restarts).

    The recursive residual drives the iteration; whenever it reaches ``tol`` the true
    residual ||b - A x|| / ||b|| (float64) is checked and CG restarts from x if it is above.
    """
    r = np.empty_like(x)
    q = np.empty_like(x)
    normb = math.sqrt(K.load_into(g, d, h, r))
    if normb == 0.0:  # no heterogeneity along e_d: theta = 0 solves it exactly
        x[...] = 0.0
        return 0, [0.0], 0.0, 0
    history: list[float] = []
    it = 0
    restarts = 0
    if np.any(x):
        # energy-optimal scaling of the warm start: c = (b . x0) / (x0 . A x0) minimises the
        # A-norm error along x0 (never worse than x0 itself, cheap: one matvec)
        xax = K.matvec_dot(g, x, q)
        if xax > 0.0:
            c = K.dot(r, x) / xax
            x *= x.dtype.type(c)
    true_res = math.sqrt(K.residual_norm2(g, x, d, h)) / normb
    history.append(true_res)
    while true_res > tol and it < maxiter and restarts <= _MAX_RESTARTS:
        # (re)start: r = b - A x
        if it > 0 or np.any(x):
            K.load_into(g, d, h, r)
            K.matvec_dot(g, x, q)
            K.sub_into(r, q)
        if labels_flat is not None:
            K.project_clusters(r, labels_flat, counts)
        z, rz = M(r)
        p = z.astype(x.dtype)  # the search direction keeps the CG precision
        del z
        rec = true_res
        while it < maxiter:
            pq = K.matvec_dot(g, p, q)
            if not pq > 0.0 or not rz > 0.0:
                break  # breakdown: exact solution in the Krylov space or loss of SPD
            alpha = rz / pq
            rr = K.cg_update(x, r, p, q, alpha)
            it += 1
            if labels_flat is not None:
                K.project_clusters(r, labels_flat, counts)
                rr = K.dot(r, r)
            rec = math.sqrt(rr) / normb
            history.append(rec)
            if callback is not None:
                callback(d, it, rec)
            if rec <= tol:
                break
            z, rz_new = M(r)
            beta = rz_new / rz
            rz = rz_new
            K.direction_update(p, z, beta)
            del z
        del p
        true_res = math.sqrt(K.residual_norm2(g, x, d, h)) / normb
        if true_res > tol and rec <= tol:
            restarts += 1
        elif true_res > tol and it < maxiter:
            restarts += 1  # breakdown above tolerance: restart from x
    if history:
        history[-1] = true_res
    return it, history, true_res, restarts


def homogenize(ms: Microstructure | DiscreteProblem, mat: Materials, tol: float = 1e-8,
               maxiter: int | None = None, directions: Sequence[int] = (0, 1, 2),
               staircase: bool = True, callback: Callback | None = None,
               x0: np.ndarray | None = None, strict: bool = True, store_fields: bool = True,
               geometry: FaceGeometry | None = None, *, dtype: type = np.float64,
               workers: int | None = None, reference: str | float = "geometric",
               fft_dtype: type = np.float32, check_memory: bool = True) -> HomogenizationResult:
    """Effective conductivity tensor by FFT-preconditioned CG (same system as itr_fv).

    Parameters
    ----------
    ms : Microstructure or DiscreteProblem
        Voxel image with particle ids, or its :class:`~itr_fv.problem.DiscreteProblem`
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
    dtype : np.float64 or np.float32
        Storage precision of the CG vectors and FFTs (reductions, conductances and the
        final residual stay float64). float32 halves vector memory and FFT time and needs
        ``tol >= float32_min_tol(ms.shape)`` (1e-6 up to 63^3, growing like n^2); at
        tol = 3e-6 k_eff agrees with float64 to
        ~3e-7 of max |K| (diagonal ~3e-8; off-diagonals are first order in the residual).
    workers : int, optional
        Threads for the FFTs and the numba kernels (default: 1 below 40^3 voxels, else
        all threads numba may use).
    reference : str or float
        Reference face conductance of the preconditioner (see
        :func:`reference_conductance`); does not change the iteration count.
    fft_dtype : np.float32 or np.float64
        Precision of the preconditioner's FFTs only. The preconditioner is an approximation
        of A^-1 anyway: applying the exact Laplacian inverse in float32 leaves the CG
        vectors, the operator, the residual check and hence the converged answer in
        ``dtype``, gives the same iteration counts (measured to tol = 1e-10) and costs
        2.6x less FFT time at 128^3. Use float64 to apply it to double precision.
    check_memory : bool
        Estimate the peak memory first (:mod:`itr_fv.resources`) and raise
        :class:`~itr_fv.resources.InsufficientMemoryError` if it exceeds the available
        memory; False skips the check.

    Returns
    -------
    HomogenizationResult
        ``solver == "itr_fft"``; ``info`` holds ``g_ref`` (W/(m^2 K)), ``dtype``,
        ``workers``, ``restarts`` (CG restarts per load case), ``contact`` (the contact
        model) and face counts.
    """
    t0 = time.perf_counter()
    problem = ms if isinstance(ms, DiscreteProblem) else None
    ms = problem.microstructure if problem is not None else ms
    tol, maxiter, dirs = check_solver_args(ms, mat, tol, maxiter, directions, callback, 3000)
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float64), np.dtype(np.float32)):
        raise ValueError(f"dtype: expected numpy.float64 or numpy.float32, got {dtype!r}")
    if dt == np.float32 and tol < float32_min_tol(ms.shape):
        raise ValueError(f"tol: {tol:.1e} is below what float32 vectors can reach on this "
                         f"grid ({float32_min_tol(ms.shape):.1e}); use dtype=numpy.float64")
    if workers is None:  # threads do not pay below ~40^3 (and suffer from busy machines)
        workers = 1 if math.prod(ms.shape) < SERIAL_BELOW else numba.config.NUMBA_NUM_THREADS
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ValueError(f"workers: expected a positive integer, got {workers!r}")
    workers = int(min(workers, numba.config.NUMBA_NUM_THREADS, os.cpu_count() or 1))
    x0 = check_x0(x0, ms.shape, dirs)
    if check_memory:
        resources.check_memory(ms.shape, "itr_fft", dtype=dt.name, store_fields=store_fields,
                               load_cases=len(dirs))
    problem = as_problem(problem or ms, mat, staircase, geometry)
    geometry = problem.geometry
    system = problem.system(mat)
    g, floating, labels = system.g, system.floating, system.labels
    labels_flat = counts = None
    if labels is not None:
        labels_flat = np.ascontiguousarray(labels.ravel(), dtype=np.int32)
        counts = np.bincount(labels_flat).astype(np.float64)
    g_ref = reference_conductance(g, reference)
    fdt = np.dtype(fft_dtype)
    if fdt not in (np.dtype(np.float64), np.dtype(np.float32)):
        raise ValueError(f"fft_dtype: expected numpy.float64 or numpy.float32, got {fft_dtype!r}")
    if dt == np.float32:
        fdt = dt
    M = _Preconditioner(ms.shape, g_ref, workers, labels_flat, counts, fdt)
    h = ms.voxel_m
    setup = time.perf_counter() - t0
    records = []
    restarts = []
    old_threads = numba.get_num_threads()
    numba.set_num_threads(workers)
    try:
        for c, d in enumerate(dirs):
            t1 = time.perf_counter()
            x = np.zeros(ms.shape, dtype=dt) if x0 is None else x0[c].astype(dt, copy=True)
            it, history, res, rs = _pcg(g, d, h, x, M, tol, maxiter, callback, labels_flat,
                                        counts)
            restarts.append(rs)
            theta = x if dt == np.float64 else x.astype(np.float64)
            records.append(SolveRecord(d, theta, it, history, res, time.perf_counter() - t1))
    finally:
        numba.set_num_threads(old_threads)
    info = {"g_ref": g_ref, "k_ref": g_ref * h, "dtype": dt.name, "fft_dtype": fdt.name,
            "workers": workers, "restarts": restarts,
            "unknowns": int(np.prod(ms.shape)),
            "interface_faces": geometry.n_interface_faces,
            "contact_faces": geometry.n_contact_faces, "contact": problem.contact,
            "staircase": geometry.staircase}
    return build_result(ms, g, records, labels=labels, floating=floating, tol=tol,
                        setup_time=setup, wall_time=time.perf_counter() - t0, solver="itr_fft",
                        store_fields=store_fields, strict=strict, info=info)
