"""The backend protocol: one driver, CG written once, backends found by name.

A new backend is one module plus its registration: ``scipy_fft`` (plain numpy/scipy, no
numba) is such a module, checked against the numba backend here; a Jacobi-preconditioned
backend written in this file shows that the protocol alone is enough to plug one in.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import fast_few
from refusals import refuses

import itr_fft  # noqa: F401 - registers the FFT backends
from itr_fv import Materials, homogenize, resolve_solver
from itr_fv.discrete.model import apply_operator
from itr_fv.solvers import resources
from itr_fv.solvers.backends import (
    Backend,
    LoadCaseSolution,
    PreparedSystem,
    available_backends,
    backend_for,
    register_backend,
)
from itr_fv.solvers.krylov import conjugate_gradients
from validation.gallery import build, rve_cases

CASES = [c.name for c in rve_cases()]


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("name", fast_few(CASES, "sc_R0"))
def test_scipy_backend_agrees_with_numba_backend_to_1e10(name):
    """The no-numba FFT-PCG backend and the numba one solve the same system: at tol 1e-12
    their tensors agree to 1e-10 of max |K| on the common RVE set (measured <= 7e-12)."""
    ms, mat = build(name, "ci")
    numba_res = homogenize(ms, mat, solver="itr_fft", tol=1e-12, store_fields=False)
    scipy_res = homogenize(ms, mat, solver="scipy_fft", tol=1e-12, store_fields=False)
    assert numba_res.converged and scipy_res.converged
    assert scipy_res.solver == "scipy_fft" and numba_res.solver == "itr_fft"
    assert _rel(scipy_res.k_eff, numba_res.k_eff) <= 1e-10
    assert scipy_res.floating.count == numba_res.floating.count


def test_registry_names_and_errors():
    assert {"itr_fv", "itr_fft", "scipy_fft"} <= set(available_backends())
    fft32 = backend_for("itr_fft", dtype=np.float32)
    assert fft32.name == "itr_fft" and fft32.options()["dtype"] == "float32"
    assert backend_for(fft32) is fft32
    with refuses(ValueError, "backend"):
        backend_for("cuda")
    with refuses(ValueError, "backend"):
        backend_for(fft32, dtype=np.float64)
    with refuses(ValueError, "amg"):
        backend_for("itr_fv", amg="bogus")
    with refuses(ValueError, "backend"):
        backend_for("scipy_fft", workers=2)
    with refuses(ValueError, "backend"):
        register_backend(int)
    ms, mat = build("sc_R0", 16)
    with pytest.raises(ValueError, match="solver: expected one of 'fft', 'mg', 'fv', 'gpu'"):
        homogenize(ms, mat, solver="nope")
    assert homogenize(ms, mat, solver="mg", tol=1e-8).info["preconditioner"] == "multigrid"


class _JacobiOperator:
    def __init__(self, g):
        self.g = g

    def apply(self, x, out):
        out[...] = apply_operator(self.g, x)


class _Jacobi:
    """z = r / diag(A): the simplest preconditioner with one ``apply``."""

    def __init__(self, g):
        diag = sum(g[d] + np.roll(g[d], 1, axis=d) for d in range(3))
        self.inv = np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0)

    def apply(self, r):
        return r * self.inv


class _PreparedJacobi(PreparedSystem):
    def __init__(self, system):
        assert system.labels is None  # enough for this test
        self.operator = _JacobiOperator(system.g)
        self.preconditioner = _Jacobi(system.g)
        self.info = {"preconditioner": "jacobi"}

    def solve(self, b, x0, tol, maxiter, callback=None):
        x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
        out = conjugate_gradients(self.operator, b, x, tol=tol, maxiter=maxiter,
                                  preconditioner=self.preconditioner, callback=callback)
        return LoadCaseSolution(x, out.iterations, out.history, out.residual, out.restarts)


class JacobiBackend(Backend):
    name = "test_jacobi"
    default_maxiter = 5000

    def bytes_per_voxel(self):
        return 200

    def prepare(self, system, voxel_m):
        return _PreparedJacobi(system)


def test_a_backend_written_against_the_protocol_plugs_in(monkeypatch):
    """Register a backend defined here; the driver runs it by name, with the common
    checks, result and memory guard, and it reproduces the reference solver."""
    register_backend(JacobiBackend)
    assert "test_jacobi" in available_backends()
    ms, mat = build("bcc_R1e-8", "ci")
    seen = []
    res = homogenize(ms, mat, solver="test_jacobi", tol=1e-10, directions=(0, 2),
                     callback=lambda *a: seen.append(a))
    ref = homogenize(ms, mat, solver="fv", tol=1e-10, directions=(0, 2), store_fields=False)
    assert res.solver == "test_jacobi" and res.converged
    assert res.info["preconditioner"] == "jacobi" and res.info["contact"] == mat.contact
    assert _rel(res.k_eff[:, [0, 2]], ref.k_eff[:, [0, 2]]) <= 1e-7
    assert {s[0] for s in seen} == {0, 2} and res.temperature.shape[0] == 2
    assert resources.estimate_peak_memory((10, 10, 10), "test_jacobi", store_fields=False) \
        == 200 * 1000
    monkeypatch.setattr(resources, "available_memory", lambda: 1000)
    with pytest.raises(resources.InsufficientMemoryError, match="test_jacobi"):
        homogenize(ms, mat, solver="test_jacobi")


def test_conjugate_gradients_on_a_dense_spd_system():
    rng = np.random.default_rng(3)
    Q = rng.standard_normal((40, 40))
    A = Q @ Q.T + 40 * np.eye(40)
    b = rng.standard_normal(40)
    exact = np.linalg.solve(A, b)

    class Dense:
        def apply(self, x, out):
            out[...] = A @ x

    class Diagonal:
        def apply(self, r):
            return r / np.diag(A)

    x = np.zeros(40)
    history: list[float] = []
    calls = []
    out = conjugate_gradients(Dense(), b, x, tol=1e-12, maxiter=200, preconditioner=Diagonal(),
                              residuals=history, callback=lambda it, r: calls.append(it))
    assert np.allclose(x, exact, rtol=0, atol=1e-10 * np.abs(exact).max())
    assert out.residual <= 1e-12 and out.residual == history[-1]
    assert np.linalg.norm(b - A @ x) / np.linalg.norm(b) == pytest.approx(out.residual, rel=1e-3)
    assert calls == list(range(1, out.iterations + 1)) and len(history) == out.iterations + 1
    # started from the solution: nothing to do
    again = conjugate_gradients(Dense(), b, exact.copy(), tol=1e-10, maxiter=5,
                                preconditioner=Diagonal())
    assert again.iterations == 0 and again.residual <= 1e-10
    # zero right-hand side: x = 0 exactly
    z = np.ones(40)
    zero = conjugate_gradients(Dense(), np.zeros(40), z, tol=1e-8, maxiter=5,
                               preconditioner=Diagonal())
    assert zero.iterations == 0 and not z.any()


def test_solver_names_and_options_reach_their_backend():
    """The solver "fft" and the backend name "itr_fft" are the same solve; "fv" with a
    backend option is the reference's backend so configured."""
    ms, mat = build("al2o3_55", "ci")
    a = homogenize(ms, mat, solver="fft", tol=1e-9, store_fields=False)
    b = homogenize(ms, mat, solver="itr_fft", tol=1e-9, store_fields=False)
    assert a.iterations == b.iterations and np.array_equal(a.k_eff, b.k_eff)
    c = homogenize(ms, mat, solver=resolve_solver("fv", amg="smoothed_aggregation"), tol=1e-9,
                   store_fields=False)
    assert c.solver == "itr_fv" and c.info["amg"] == "smoothed_aggregation"
    assert _rel(c.k_eff, a.k_eff) <= 1e-6
    mat_bad = Materials({"silicone": 0.18, "Al2O3": 30.0}, matrix="silicone")
    with refuses(ValueError, "tol"):
        homogenize(ms, mat_bad, solver="scipy_fft", tol=0.0)
