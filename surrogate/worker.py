"""The worker's side of a full solve: one discrete problem per RVE and contact model kept
in the process, and the solve itself.

A worker rebuilds an RVE's voxels from its particle table and keeps one
:class:`~itr_fv.discrete.problem.DiscreteProblem` per RVE and contact model (the geometry is
built once per RVE per worker, never once per solve). It writes no file: it gets plain data
and returns plain data (:mod:`surrogate.requests`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections import OrderedDict

import numpy as np

from itr_fv.discrete.problem import DiscreteProblem

from .requests import (
    RVEData,
    SolveRequest,
    SolveResult,
    request_of_payload,
    result_payload,
)

__all__ = ["run_request", "run_payload", "cached_problem", "geometry_builds",
           "clear_problem_cache", "PROBLEM_CACHE_BYTES", "PROBLEM_BYTES_PER_VOXEL"]


#: Discrete problems kept per process, keyed by (rve id, contact); the least recently used
#: goes when they would hold more than PROBLEM_CACHE_BYTES.
_PROBLEMS: OrderedDict[tuple[str, str], DiscreteProblem] = OrderedDict()
#: Budget of the per-process problem cache, bytes (a problem is counted as
#: PROBLEM_BYTES_PER_VOXEL per voxel: measured 2.1-2.2 MB at 48^3 for the geometry and
#: 0.9 MB for the voxel labels, i.e. ~55 bytes per voxel).
PROBLEM_CACHE_BYTES = 2 * 10**9
PROBLEM_BYTES_PER_VOXEL = 64
_BUILDS = {"count": 0}


def geometry_builds() -> int:
    """Discrete problems (face geometries) this process has built for the engine."""
    return _BUILDS["count"]


def clear_problem_cache() -> None:
    """Forget this process's discrete problems (the next solve of an RVE builds it again)."""
    _PROBLEMS.clear()


def cached_problem(rve: RVEData, contact: str) -> tuple[DiscreteProblem, bool]:
    """The RVE's discrete problem under ``contact`` from this process's cache (built on a
    miss); returns (problem, built_now)."""
    key = (rve.rve_id, contact)
    problem = _PROBLEMS.get(key)
    if problem is not None:
        _PROBLEMS.move_to_end(key)
        return problem, False
    problem = DiscreteProblem(rve.microstructure(), contact=contact)
    _BUILDS["count"] += 1
    _PROBLEMS[key] = problem
    size = PROBLEM_BYTES_PER_VOXEL * math.prod(rve.shape)
    while len(_PROBLEMS) > 1 and len(_PROBLEMS) * size > PROBLEM_CACHE_BYTES:
        _PROBLEMS.popitem(last=False)
    return problem, True


def run_request(request: SolveRequest, threads: int | None = None) -> SolveResult:
    """Solve one request in this process (the problem from the cache); ``threads`` of the
    FFT backend (None: its default for the grid; a Dask worker uses 1)."""
    from itr_fv import homogenize
    from itr_fv.checks import VoxelContactWarning

    problem, built = cached_problem(request.rve, request.contact)
    backend = request.solver.backend(threads, voxels=math.prod(problem.shape))
    t = time.perf_counter()
    with warnings.catch_warnings():
        # the per-area model is tied to its voxel on purpose; its reports say so
        warnings.simplefilter("ignore", VoxelContactWarning)
        res = homogenize(problem, request.materials, solver=backend, tol=request.tol,
                         store_fields=request.fields)
    return SolveResult(res.k_eff, res.k_eff_energy, list(res.iterations),
                       float(max(res.residuals)), time.perf_counter() - t,
                       np.stack(res.theta) if request.fields else None, False, built)


def run_payload(payload: dict) -> dict:
    """Dask task: a request in plain data in, a result in plain data out, on one thread."""
    return result_payload(run_request(request_of_payload(payload), threads=1))
