"""The solve driver: one code path from a discrete problem to a result, for every backend.

:func:`homogenize` checks the arguments, refuses a solve that cannot fit in memory before
any work, builds the discrete system once, hands each load case's load vector to the
backend (:mod:`itr_fv.solvers.backends`), fixes the gauge and builds the
:class:`~itr_fv.solvers.result.HomogenizationResult` (tensor, fields, convergence verdict) once.
It is ``itr_fv.homogenize``, the package's one door to a solve::

    from itr_fv import homogenize
    from itr_fv.solvers.choice import resolve_solver
    res = homogenize(problem, mat, solver="fft", tol=1e-8)
    res = homogenize(problem, mat, solver=resolve_solver("fft", dtype=np.float32), tol=2e-6)

Every stage runs where the backend's arrays live: the load vector is built on the prepared
system's conductances ``g``, the solution stays where the backend left it, and the cluster
means, the mean flux and the energy tensor are computed there by the array-API functions
of :mod:`itr_fv.discrete.operator`; only the 3x3 tensors and, with ``store_fields=True``, the
fields come back to the host (through the prepared system's ``to_host``). For the NumPy
backends all of this is host NumPy.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..discrete.connectivity import ClusterProjection
from ..discrete.model import FaceGeometry
from ..discrete.operator import cell_centres, effective_tensors, face_fluxes, load_vector
from ..discrete.problem import DiscreteProblem, DiscreteSystem
from ..materials.properties import Materials
from ..rve.microstructure import Microstructure
from . import resources
from .backends import Backend, PreparedSystem
from .choice import Solver, as_solver
from .result import ConvergenceError, FloatingClusters, HomogenizationResult

__all__ = ["homogenize", "check_solver_args", "check_x0", "as_problem", "SolveRecord",
           "build_result", "remove_cluster_means", "device_arrays"]

Callback = Callable[[int, int, float], None]


def check_solver_args(ms: Microstructure, mat: Materials, tol: float, maxiter: int | None,
                      directions: Sequence[int], callback: Callback | None,
                      default_maxiter: int) -> tuple[float, int, tuple[int, ...]]:
    """Validate the common solver arguments; returns (tol, maxiter, directions)."""
    if not isinstance(ms, Microstructure):
        raise ValueError(f"ms: expected a Microstructure, got {type(ms).__name__}")
    if not isinstance(mat, Materials):
        raise ValueError(f"materials: expected a Materials object, got "
                         f"{type(mat).__name__}")
    if ms.names[0] != mat.matrix:
        raise ValueError(f"materials: matrix phase {mat.matrix!r} differs from the microstructure's "
                         f"matrix {ms.names[0]!r}")
    try:
        tol = float(tol)
    except (TypeError, ValueError):
        raise ValueError(f"tol: not a number: {tol!r}") from None
    if not math.isfinite(tol) or tol <= 0.0 or tol >= 1.0:
        raise ValueError(f"tol: relative residual tolerance must be in (0, 1), got {tol!r}")
    if maxiter is None:
        maxiter = default_maxiter
    if isinstance(maxiter, bool) or not isinstance(maxiter, (int, np.integer)) or maxiter < 1:
        raise ValueError(f"maxiter: expected a positive integer, got {maxiter!r}")
    try:
        dirs = tuple(int(d) for d in directions)
    except (TypeError, ValueError):
        raise ValueError(f"directions: expected a sequence of axes 0, 1, 2, got {directions!r}") \
            from None
    if not dirs or len(set(dirs)) != len(dirs) or any(d not in (0, 1, 2) for d in dirs):
        raise ValueError(f"directions: expected distinct axes among 0, 1, 2, got {directions!r}")
    if callback is not None and not callable(callback):
        raise ValueError("callback: expected a callable callback(direction, iteration, residual)")
    return tol, int(maxiter), dirs


def check_x0(x0: np.ndarray | None, shape: tuple[int, int, int],
             directions: tuple[int, ...]) -> np.ndarray | None:
    """Validate a warm start: shape (len(directions), n1, n2, n3), finite."""
    if x0 is None:
        return None
    x0 = np.asarray(x0, dtype=np.float64)
    want = (len(directions),) + tuple(shape)
    if x0.shape == tuple(shape) and len(directions) == 1:
        x0 = x0[None]
    if x0.shape != want:
        raise ValueError(f"x0: expected shape {want} (one theta per load case), got {x0.shape}")
    if not np.all(np.isfinite(x0)):
        raise ValueError("x0: contains NaN or inf")
    return x0


def as_problem(ms: Microstructure | DiscreteProblem, mat: Materials, staircase: bool,
               geometry: FaceGeometry | None) -> DiscreteProblem:
    """The :class:`DiscreteProblem` a solver works on: ``ms`` itself if it is one (then
    ``geometry`` must be None and its contact model that of ``mat``), else built here."""
    if isinstance(ms, DiscreteProblem):
        if geometry is not None:
            raise ValueError("geometry: a DiscreteProblem already holds its geometry")
        return ms
    return DiscreteProblem.for_materials(ms, mat, staircase, geometry)


def remove_cluster_means(theta: Any, labels: np.ndarray | None) -> Any:
    """Fix the gauge: zero mean of theta on every connected cluster (in place), where
    theta lives (:class:`~itr_fv.discrete.connectivity.ClusterProjection`)."""
    return ClusterProjection(labels, like=theta).project(theta)


def device_arrays(prepared: PreparedSystem, system: DiscreteSystem
                  ) -> tuple[Any, ClusterProjection]:
    """The face conductances and the cluster projection where the prepared system's arrays
    live: its own, or the system's host ones for a backend that keeps none."""
    g = system.g if prepared.g is None else prepared.g
    clusters = prepared.clusters
    if clusters is None:
        clusters = ClusterProjection(system.labels, like=g)
    return g, clusters


def _unit_load(direction: int) -> tuple[float, float, float]:
    """E = e_direction, K/m."""
    return tuple(1.0 if d == direction else 0.0 for d in range(3))


def _host_float64(a: np.ndarray) -> np.ndarray:
    """A host field in float64 (itself when it already is)."""
    return np.asarray(a, dtype=np.float64)


class SolveRecord:
    """What a solver hands over per load case: theta (where the backend's arrays live),
    iterations and residuals."""

    def __init__(self, direction: int, theta: Any, iterations: int,
                 history: Sequence[float], residual: float, seconds: float) -> None:
        self.direction = direction
        self.theta = theta
        self.iterations = iterations
        self.history = np.asarray(history, dtype=np.float64)
        self.residual = residual
        self.seconds = seconds


def build_result(ms: Microstructure, g: Any, records: list[SolveRecord], *,
                 clusters: ClusterProjection, floating: FloatingClusters, tol: float,
                 setup_time: float, wall_time: float, solver: str, store_fields: bool,
                 strict: bool, info: dict | None = None,
                 to_host: Callable[[Any], np.ndarray] = np.asarray) -> HomogenizationResult:
    """Turn per-load-case fields into a :class:`HomogenizationResult`.

    The gauge, the mean flux and the energy tensor are computed where ``g`` and the
    records' theta live; fields come back through ``to_host`` only when ``store_fields``.

    Parameters
    ----------
    ms : Microstructure
        The voxel image (grid, voxel edge).
    g : array, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K), where the thetas live.
    records : list of SolveRecord
        One per load case; their theta is gauge-fixed in place.
    clusters : ClusterProjection
        The cluster-mean projection next to ``g``.
    to_host : callable
        ``to_host(array) -> ndarray``: the prepared system's way to bring a field back.

    Raises
    ------
    ConvergenceError
        If ``strict`` and a load case did not reach ``tol``; otherwise a RuntimeWarning.
    """
    h = ms.voxel_m
    temps, thetas, fluxes = [], [], []
    for rec in records:
        E = _unit_load(rec.direction)
        clusters.project(rec.theta)
        if store_fields:
            theta = _host_float64(to_host(rec.theta))
            thetas.append(theta)
            temps.append(theta - cell_centres(ms.shape, h, rec.direction))
            fluxes.append(_host_float64(to_host(face_fluxes(g, rec.theta, h, E))))
    converged = all(rec.residual <= tol for rec in records)
    K, K_energy = effective_tensors(g, [rec.theta for rec in records], h,
                                    tuple(rec.direction for rec in records))
    result = HomogenizationResult(
        k_eff=K,
        k_eff_energy=K_energy,
        directions=tuple(rec.direction for rec in records),
        iterations=[rec.iterations for rec in records],
        residuals=[rec.residual for rec in records],
        residual_history=[rec.history for rec in records],
        converged=converged,
        temperature=np.stack(temps) if store_fields else None,
        theta=np.stack(thetas) if store_fields else None,
        fluxes=np.stack(fluxes) if store_fields else None,
        setup_time=setup_time,
        solve_times=[rec.seconds for rec in records],
        wall_time=wall_time,
        floating=floating,
        solver=solver,
        tol=tol,
        microstructure=ms,
        info=dict(info or {}),
    )
    if not converged:
        bad = [f"e{rec.direction + 1}: {rec.residual:.2e} after {rec.iterations} iterations"
               for rec in records if rec.residual > tol]
        msg = (f"{solver}: not converged to tol={tol:.1e} ({'; '.join(bad)}); raise maxiter, "
               "or pass strict=False to accept the partial result")
        if strict:
            raise ConvergenceError(msg, result)
        warnings.warn(msg, RuntimeWarning, stacklevel=3)
    return result


def _solver_backend(solver: Solver | str | Backend | None) -> Backend:
    """The backend object of ``solver``: a configured Backend as it is, else the Solver's
    (a name resolved by :func:`~itr_fv.solvers.choice.as_solver`). A grid goes where it
    is asked to: sending a GPU's small grids to the CPU is the plan's decision
    (:meth:`~itr_fv.solvers.choice.Solver.for_grid`), made by the callers that plan."""
    if isinstance(solver, Backend):
        return solver
    return as_solver(solver, "solver").backend()


def _solve_cases(prepared: PreparedSystem, g: Any, ms: Microstructure, dirs: tuple[int, ...],
                 x0: np.ndarray | None, tol: float, maxiter: int,
                 callback: Callback | None
                 ) -> tuple[list[SolveRecord], list[tuple[Any, Any]]]:
    """Solve the load cases E = e_d of ``dirs`` together on a prepared system; one record
    each (a case solved on its own keeps its time; cases solved together share theirs by
    their iterations); with each case's (restarts, replacements)."""
    t1 = time.perf_counter()
    loads = [load_vector(g, ms.voxel_m, _unit_load(d)) for d in dirs]
    step = None if callback is None else (lambda c, it, res: callback(dirs[c], it, res))
    sols = prepared.solve_block(loads, [None if x0 is None else x0[c]
                                        for c in range(len(dirs))], tol, maxiter, step)
    del loads
    seconds = time.perf_counter() - t1
    total = max(sum(sol.iterations for sol in sols), 1)
    return [SolveRecord(d, sol.x, sol.iterations, sol.history, sol.residual,
                        sol.seconds if sol.seconds is not None else
                        seconds * max(sol.iterations, 1) / total
                        if len(sols) > 1 else seconds)
            for d, sol in zip(dirs, sols)], [(sol.restarts, sol.replacements) for sol in sols]


def homogenize(problem: Microstructure | DiscreteProblem, materials: Materials, *,
               solver: Solver | str | Backend | None = None, tol: float = 1e-8,
               maxiter: int | None = None, directions: Sequence[int] = (0, 1, 2),
               x0: np.ndarray | None = None, callback: Callback | None = None,
               strict: bool = True, store_fields: bool = True, check_memory: bool = True,
               staircase: bool = True, geometry: FaceGeometry | None = None
               ) -> HomogenizationResult:
    """Effective conductivity tensor of a microstructure or discrete problem: the package's
    one door to a solve, for every solver.

    Parameters
    ----------
    problem : DiscreteProblem or Microstructure
        The problem (geometry built once, reused for many parameter sets), or a voxel
        image whose problem is built here under the contact model of ``materials``.
    materials : Materials
        Conductivities (W/(m K)) and interface resistances (m^2 K/W).
    solver : Solver, str or Backend, optional
        A :class:`~itr_fv.solvers.choice.Solver` (:func:`~itr_fv.solvers.choice.resolve_solver`:
        a method, its options and its device), a name (``"fft"``, the default, ``"mg"``,
        ``"fv"`` the pyamg reference, ``"gpu"``, ``"auto"``, or a registered backend such
        as ``"scipy_fft"``), or a configured backend object
        (:func:`itr_fv.solvers.backends.backend_for`).
    tol : float
        Relative residual ||b - A theta|| / ||b|| to reach, in (0, 1), checked on the true
        residual.
    maxiter : int, optional
        CG iterations per load case (default: the backend's).
    directions : sequence of int
        Load cases E = e_d to solve (0, 1, 2 = x, y, z).
    x0 : ndarray, optional
        Warm start, shape (len(directions), n1, n2, n3): theta of a neighbouring solve, K.
    callback : callable, optional
        ``callback(direction, iteration, relative_residual)`` after every CG iteration.
    strict : bool
        Raise :class:`~itr_fv.ConvergenceError` (carrying the partial result) when a load
        case misses ``tol``; else warn and flag the result.
    store_fields : bool
        Keep temperature, theta and face fluxes in the result.
    check_memory : bool
        Refuse (:class:`~itr_fv.solvers.resources.InsufficientMemoryError`) a solve whose
        estimated peak exceeds the available memory, before any work.
    staircase, geometry
        How to build the problem from a Microstructure (staircase correction of interface
        resistances; a precomputed :class:`~itr_fv.discrete.model.FaceGeometry`); not allowed
        with a DiscreteProblem's own geometry.

    Returns
    -------
    HomogenizationResult
        ``k_eff`` in W/(m K); ``solver`` is the backend's name; ``info`` holds the
        backend's preparation facts, ``restarts`` per load case, the contact model and
        face counts.
    """
    t0 = time.perf_counter()
    given = problem if isinstance(problem, DiscreteProblem) else None
    ms = given.microstructure if given is not None else problem
    if not isinstance(ms, Microstructure):
        raise ValueError(f"problem: expected a Microstructure or a DiscreteProblem, got "
                         f"{type(problem).__name__}")
    backend = _solver_backend(solver)
    tol, maxiter, dirs = check_solver_args(ms, materials, tol, maxiter, directions, callback,
                                           backend.default_maxiter)
    backend.check(ms.shape, tol)
    x0 = check_x0(x0, ms.shape, dirs)
    if check_memory:
        resources.check_memory(ms.shape, backend, store_fields=store_fields,
                               load_cases=len(dirs))
    problem = as_problem(given or ms, materials, staircase, geometry)
    where = backend.array_namespace()
    system = (problem.system(materials) if where is None
              else problem.system(materials, xp=where[0], device=where[1]))
    prepared = backend.prepare(system, ms.voxel_m)
    try:
        g, clusters = device_arrays(prepared, system)
        setup = time.perf_counter() - t0
        records, counts = _solve_cases(prepared, g, ms, dirs, x0, tol, maxiter, callback)
        geometry = problem.geometry
        info = {**prepared.info, "restarts": [c[0] for c in counts],
                "replacements": [c[1] for c in counts],
                "unknowns": int(math.prod(ms.shape)),
                "interface_faces": geometry.n_interface_faces,
                "contact_faces": geometry.n_contact_faces, "contact": problem.contact,
                "staircase": geometry.staircase}
        return build_result(ms, g, records, clusters=clusters, floating=system.floating,
                            tol=tol, setup_time=setup, wall_time=time.perf_counter() - t0,
                            solver=backend.name, store_fields=store_fields, strict=strict,
                            info=info, to_host=prepared.to_host)
    finally:
        prepared.close()
