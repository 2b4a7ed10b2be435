"""The load cases solved as one block, and mixed precision (issue 50).

- :func:`itr_fv.solvers.krylov.block_conjugate_gradients` runs the CG of
  :func:`~itr_fv.solvers.krylov.conjugate_gradients` for every load case in lockstep, with
  one operator pass per iteration for all of them; its iterates are those of the single
  solves. Checked on a dense SPD system (cases that converge at different iterations), and
  on the common RVE set for the numba backend (block against one load case at a time) and
  the array-API backend on NumPy and array_api_strict (``solve_block`` against ``solve``);
  the CUDA simulator's check of the fused block kernel is in ``test_fused_kernels.py``.
- ``precision="mixed"`` of the numba backend: the tolerance it is given holds on the
  float64 residual computed here with the model's own operator, its k equals the double
  precision k to 1e-6, and it refuses what it is not measured to reach.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from conftest import fast_few
from refusals import refuses

import itr_fft  # noqa: F401  (registers the backends)
from itr_fft.numba_backend import MIXED_MIN_TOL, NumbaFFTBackend
from itr_fv import homogenize
from itr_fv.discrete.operator import apply_operator, load_vector
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.solvers.backends import backend_for
from itr_fv.solvers.krylov import block_conjugate_gradients, conjugate_gradients
from validation.gallery import build, rve_cases

CASES = [c.name for c in rve_cases()]


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return float(np.abs(a - b).max() / np.abs(b).max())


class _Dense:
    """A dense SPD operator that counts its passes (single and block)."""

    def __init__(self, a: np.ndarray) -> None:
        self.a = a
        self.passes = 0

    def apply(self, x, out):
        self.passes += 1
        out[...] = self.a @ x

    def apply_dot_block(self, xs, outs):
        self.passes += 1
        for x, out in zip(xs, outs):
            out[...] = self.a @ x
        return [float(x @ out) for x, out in zip(xs, outs)]


class _Jacobi:
    def __init__(self, d):
        self.d = d

    def apply(self, r):
        return r / self.d


def test_block_cg_has_the_iterates_of_single_solves_and_one_pass_per_iteration():
    rng = np.random.default_rng(50)
    q, _ = np.linalg.qr(rng.standard_normal((60, 60)))
    a = q @ np.diag(np.geomspace(1.0, 1e4, 60)) @ q.T
    # load cases that converge after different numbers of iterations: one is an
    # eigenvector (one iteration), the others mixes
    loads = [q[:, 7].copy(), q[:, :5] @ rng.standard_normal(5), rng.standard_normal(60)]
    pre = _Jacobi(np.ones(60))
    single, passes = [], 0
    for b in loads:
        x = np.zeros(60)
        op = _Dense(a)
        out = conjugate_gradients(op, b, x, tol=1e-10, maxiter=500, preconditioner=pre)
        single.append((x, out))
        passes = max(passes, op.passes)
    op = _Dense(a)
    xs = [np.zeros(60) for _ in loads]
    seen = []
    outs = block_conjugate_gradients(op, loads, xs, tol=1e-10, maxiter=500,
                                     preconditioner=pre,
                                     callback=lambda c, it, res: seen.append(c))
    for (x1, o1), x, o in zip(single, xs, outs):
        assert o.iterations == o1.iterations
        assert o.history == o1.history
        assert np.array_equal(x, x1)
        assert np.linalg.norm(loads[0] - a @ xs[0]) <= 1e-10 * np.linalg.norm(loads[0])
    its = [o.iterations for o in outs]
    assert its[0] <= 2 < min(its[1:])  # the first drops out early
    # one pass per lockstep iteration, plus each case's first and last true residuals
    # (and one per restart)
    assert op.passes <= max(its) + 2 * len(loads) + sum(o.restarts for o in outs)
    assert op.passes < 0.85 * sum(its)
    assert sorted(set(seen)) == [0, 1, 2]
    with refuses(ValueError, "starts"):
        block_conjugate_gradients(op, loads, xs[:2], tol=1e-8, maxiter=5, preconditioner=pre)


@functools.cache
def _problem(case: str):
    ms, mat = build(case, "ci")
    return DiscreteProblem.for_materials(ms, mat), mat


@pytest.mark.parametrize("case", fast_few(CASES, "sc_R5e-5"))
def test_numba_block_equals_one_load_case_at_a_time_on_the_common_set(case):
    problem, mat = _problem(case)
    one = homogenize(problem, mat, solver=backend_for("itr_fft", block=False), tol=1e-10,
                     store_fields=True)
    block = homogenize(problem, mat, solver=backend_for("itr_fft", block=True), tol=1e-10,
                       store_fields=True)
    assert block.info["block"] and not one.info["block"]
    assert block.iterations == one.iterations
    assert _rel(block.k_eff, one.k_eff) <= 1e-10
    assert _rel(block.theta, one.theta) <= 1e-10


@pytest.mark.parametrize("namespace", ["numpy", "array_api_strict"])
@pytest.mark.parametrize("case", fast_few(["sc_R5e-5", "random30_Rinf", "al2o3_60",
                                           "hybrid_30_30"], "sc_R5e-5"))
def test_array_api_block_equals_single_solves(case, namespace):
    pytest.importorskip(namespace)
    problem, mat = _problem(case)
    backend = backend_for("array_api", device="cpu", namespace=namespace)
    xp, dev = backend.array_namespace()
    system = problem.system(mat, xp=xp, device=dev)
    prepared = backend.prepare(system, problem.microstructure.voxel_m)
    try:
        h = problem.microstructure.voxel_m
        loads = [load_vector(prepared.g, h, tuple(float(k == d) for k in range(3)))
                 for d in range(3)]
        block = prepared.solve_block(loads, [None] * 3, 1e-10, 2000)
        for b, sol in zip(loads, block):
            one = prepared.solve(b, None, 1e-10, 2000)
            assert sol.iterations == one.iterations
            assert _rel(prepared.to_host(sol.x), prepared.to_host(one.x)) <= 1e-10
            assert sol.residual <= 1e-10
    finally:
        prepared.close()


@pytest.mark.parametrize("case", fast_few(CASES, "sc_R5e-5"))
def test_mixed_precision_meets_its_tolerance_on_the_float64_residual(case):
    problem, mat = _problem(case)
    tol = 1e-8
    double = homogenize(problem, mat, solver="itr_fft", tol=tol, store_fields=True)
    mixed = homogenize(problem, mat, solver=backend_for("itr_fft", precision="mixed"),
                       tol=tol, store_fields=True)
    assert mixed.info["precision"] == "mixed" and mixed.converged
    g = problem.system(mat).g
    h = problem.microstructure.voxel_m
    for c, d in enumerate(mixed.directions):
        b = load_vector(g, h, tuple(float(k == d) for k in range(3)))
        res = np.linalg.norm(b - apply_operator(g, mixed.theta[c]))
        assert res <= tol * np.linalg.norm(b), (d, res)  # b = 0: theta = 0 exactly
    assert _rel(mixed.k_eff, double.k_eff) <= 1e-6


def test_mixed_precision_refuses_what_it_cannot_reach():
    problem, mat = _problem("sc_R0")
    with refuses(ValueError, "tol"):
        homogenize(problem, mat, solver=backend_for("itr_fft", precision="mixed"),
                   tol=MIXED_MIN_TOL / 10)
    with refuses(ValueError, "precision"):
        NumbaFFTBackend(precision="mixed", dtype=np.float32)
    with refuses(ValueError, "precision"):
        NumbaFFTBackend(precision="half")
    with refuses(ValueError, "block"):
        NumbaFFTBackend(block="yes")
