"""The fused CUDA kernels of :mod:`itr_fft.fused_kernels` against the NumPy paths.

The kernels run on numba's CUDA simulator, which must be switched on before ``numba.cuda``
is first imported; this pytest process may already have imported it, so the checks run in
one subprocess (this file run as a script with ``NUMBA_ENABLE_CUDASIM=1``) that prints the
measured differences as JSON, and the tests assert on them. References: the model's
:func:`itr_fv.discrete.operator.apply_operator`, the array-API backend's operator and CG on
NumPy, and plain NumPy expressions.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from refusals import refuses

ROOT = Path(__file__).resolve().parents[1]
SHAPES = ((5, 6, 7), (8, 8, 8))
#: The simulator runs one Python thread per GPU thread: few threads, grid-stride loops.
LAUNCH = {"threads_per_block": 8, "max_blocks": 4}
#: Common-set RVEs of the block CG check (at 6^3: the simulator is slow).
BLOCK_CASES = ("bcc_R1e-8",)


def _rel(a: Any, ref: Any) -> float:
    """max |a - ref| / max |ref|."""
    a, ref = np.asarray(a, dtype=np.float64), np.asarray(ref, dtype=np.float64)
    return float(np.max(np.abs(a - ref)) / np.max(np.abs(ref)))


# ------------------------------------------------------------- checks, run in the subprocess

def _xp() -> Any:
    from itr_fft.array_api_backend import _namespace
    return _namespace("numpy")


def _operator_case(rng: np.random.Generator, shape: tuple[int, ...], dtype: Any,
                   **launch: int) -> dict[str, float]:
    """Fused ``A x`` and ``x . A x`` against apply_operator and the array-API operator."""
    from itr_fft.array_api_backend import _Operator
    from itr_fft.fused_kernels import FusedOperator
    from itr_fv.discrete.operator import apply_operator
    g = rng.uniform(0.2, 5.0, (3,) + shape).astype(dtype)
    x = rng.standard_normal(shape).astype(dtype)
    out, api = np.empty_like(x), np.empty_like(x)
    op = FusedOperator(g, **launch)
    op.apply(x, out)
    _Operator(_xp(), g).apply(x, api)
    ref = apply_operator(g.astype(np.float64), x.astype(np.float64))
    xax = op.apply_dot(x, np.empty_like(x))
    return {"model": _rel(out, ref), "array_api": _rel(out, api),
            "dot": abs(xax - math.fsum(x.astype(np.float64).ravel() * ref.ravel()))
            / abs(float(np.dot(x.ravel(), ref.ravel()))),
            "same_dtype": float(out.dtype == dtype)}


def _operator_checks(rng: np.random.Generator) -> dict[str, Any]:
    cases = {f"{'x'.join(map(str, s))}_float64": _operator_case(rng, s, np.float64, **LAUNCH)
             for s in SHAPES}
    cases["5x6x7_float32"] = _operator_case(rng, SHAPES[0], np.float32, **LAUNCH)
    cases["8x8x8_default_launch"] = _operator_case(rng, SHAPES[1], np.float64)
    return cases


def _block_check(rng: np.random.Generator) -> dict[str, float]:
    """Three fields at once against three single applications and the model."""
    from itr_fft.fused_kernels import FusedOperator
    from itr_fv.discrete.operator import apply_operator
    shape = SHAPES[0]
    g = rng.uniform(0.2, 5.0, (3,) + shape)
    x = rng.standard_normal((3,) + shape)
    op = FusedOperator(g, **LAUNCH)
    block, single = np.empty_like(x), np.empty_like(x)
    op.apply_block(x, block)
    for f in range(3):
        op.apply(x[f], single[f])
    ref = np.stack([apply_operator(g, x[f]) for f in range(3)])
    return {"single": _rel(block, single), "model": _rel(block, ref)}


def _update_case(rng: np.random.Generator, dtype: Any) -> dict[str, float]:
    """update, direction, dot and residual against NumPy expressions."""
    from itr_fft.fused_kernels import FusedOperator, FusedOps
    from itr_fv.discrete.operator import apply_operator
    shape = SHAPES[0]
    x, r, p, q, z, b = (rng.standard_normal(shape).astype(dtype) for _ in range(6))
    alpha, beta = dtype(0.37), dtype(0.81)
    x_ref, r_ref, p_ref = x + alpha * p, r - alpha * q, z + beta * p
    ops = FusedOps(**LAUNCH)
    rr = ops.update(x, r, p, q, 0.37)
    ops.direction(p, z, 0.81)
    g = rng.uniform(0.2, 5.0, (3,) + shape).astype(dtype)
    out = np.empty_like(x)
    res = ops.residual(FusedOperator(g, **LAUNCH), b, x, out)
    res_ref = b.astype(np.float64) - apply_operator(g.astype(np.float64), x.astype(np.float64))
    r64 = r_ref.astype(np.float64).ravel()
    return {"x": _rel(x, x_ref), "r": _rel(r, r_ref), "p": _rel(p, p_ref),
            "rr": abs(rr - math.fsum(r64 * r64)) / math.fsum(r64 * r64),
            "dot": abs(ops.dot(x, z) - math.fsum(x.astype(np.float64).ravel() * z.ravel()))
            / math.fsum(np.abs(x.astype(np.float64).ravel() * z.ravel())),
            "residual": _rel(out, res_ref),
            "residual_norm": abs(res - float(np.sum(res_ref**2))) / float(np.sum(res_ref**2))}


def _two_phase_g(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Face conductances (h = 1 m) of a random two-phase grid, k = 1 and 10 W/(m K)."""
    k = np.where(rng.random(shape) < 0.35, 10.0, 1.0)
    return np.stack([2.0 * k * np.roll(k, -1, axis=d) / (k + np.roll(k, -1, axis=d))
                     for d in range(3)])


def _cg_check(rng: np.random.Generator) -> dict[str, float]:
    """One FFT-preconditioned CG solve by the fused kernels and by the array-API path."""
    from itr_fft.array_api_backend import ArrayAPIOps, _FFTPreconditioner, _Operator
    from itr_fft.fused_kernels import FusedOperator, FusedOps
    from itr_fft.spectral import reference_conductance
    from itr_fv.discrete.operator import apply_operator, load_vector
    from itr_fv.solvers.krylov import conjugate_gradients
    shape, xp = SHAPES[1], _xp()
    g = _two_phase_g(rng, shape)
    b = load_vector(g, 1.0, np.array([1.0, 0.0, 0.0]))
    pre = _FFTPreconditioner(xp, None, shape, reference_conductance(g), xp.float64, None)
    solves = {}
    for name, op, ops in (("api", _Operator(xp, g), ArrayAPIOps(xp)),
                          ("fused", FusedOperator(g, **LAUNCH), FusedOps(**LAUNCH))):
        x = np.zeros(shape)
        out = conjugate_gradients(op, b, x, tol=1e-10, maxiter=200, preconditioner=pre,
                                  ops=ops)
        solves[name] = (x, out)
    (xa, oa), (xf, of) = solves["api"], solves["fused"]
    return {"iterations_api": oa.iterations, "iterations_fused": of.iterations,
            "solution": _rel(xf, xa),
            "true_residual": float(np.linalg.norm(b - apply_operator(g, xf))
                                   / np.linalg.norm(b)),
            "restarts_fused": of.restarts}


def _block_cg_check() -> dict[str, float]:
    """Three load cases of a common-set RVE (small grid) by the block CG with the fused
    block kernel, against three single CG solves with the fused kernels."""
    from itr_fft.array_api_backend import _FFTPreconditioner
    from itr_fft.fused_kernels import FusedOperator, FusedOps
    from itr_fft.spectral import reference_conductance
    from itr_fv.discrete.operator import load_vector
    from itr_fv.discrete.problem import DiscreteProblem
    from itr_fv.solvers.krylov import block_conjugate_gradients, conjugate_gradients
    from validation.gallery import build
    out: dict[str, float] = {}
    for case in BLOCK_CASES:  # the simulator takes ~1 s per CG iteration at 6^3
        ms, mat = build(case, 6)
        g = DiscreteProblem.for_materials(ms, mat).system(mat).g
        shape, h = g.shape[1:], ms.voxel_m
        loads = [load_vector(g, h, tuple(float(k == d) for k in range(3))) for d in range(3)]
        pre = _FFTPreconditioner(_xp(), None, shape, reference_conductance(g), np.float64,
                                 None)
        op, ops = FusedOperator(g, **LAUNCH), FusedOps(**LAUNCH)
        xs = [np.zeros(shape) for _ in loads]
        block = block_conjugate_gradients(op, loads, xs, tol=1e-10, maxiter=300,
                                          preconditioner=pre, ops=ops)
        diff, same = 0.0, 1.0
        for b, x, o in zip(loads, xs, block):
            x1 = np.zeros(shape)
            o1 = conjugate_gradients(op, b, x1, tol=1e-10, maxiter=300, preconditioner=pre,
                                     ops=ops)
            diff = max(diff, _rel(x, x1))
            same = min(same, float(o.iterations == o1.iterations and o.residual <= 1e-10))
        out[f"{case}_solution"] = diff
        out[f"{case}_same_iterations"] = same
    return out


def _main() -> None:
    from itr_fft.fused_kernels import fused_available
    rng = np.random.default_rng(20261126)
    results = {"available": fused_available(), "operator": _operator_checks(rng),
               "block": _block_check(rng),
               "update": {"float64": _update_case(rng, np.float64),
                          "float32": _update_case(rng, np.float32)},
               "cg": _cg_check(rng), "block_cg": _block_cg_check()}
    print(json.dumps(results))


# ------------------------------------------------------------------------------- the tests

@pytest.fixture(scope="module")
def simulated() -> dict[str, Any]:
    """The checks' results, from one subprocess with the CUDA simulator on."""
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1",
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT),
                                                        os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, __file__], env=env, cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-4000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_simulator_is_available(simulated):
    assert simulated["available"] is True


@pytest.mark.parametrize("case", ["5x6x7_float64", "8x8x8_float64", "8x8x8_default_launch"])
@pytest.mark.slow
def test_operator_matches_model_and_array_api(simulated, case):
    got = simulated["operator"][case]
    assert got["model"] < 1e-12
    # the same float64 operations in the same order (the simulator has no fused multiply-add)
    assert got["array_api"] == 0.0
    assert got["dot"] < 1e-12
    assert got["same_dtype"] == 1.0


@pytest.mark.slow
def test_operator_float32_sums_like_array_api(simulated):
    got = simulated["operator"]["5x6x7_float32"]
    assert got["same_dtype"] == 1.0
    assert got["array_api"] == 0.0  # same float32 operations in the same order
    assert got["model"] < 1e-5  # float32 against the float64 model


@pytest.mark.slow
def test_block_equals_three_single_applications(simulated):
    assert simulated["block"]["single"] == 0.0
    assert simulated["block"]["model"] < 1e-12


@pytest.mark.parametrize("dtype, tol", [("float64", 1e-12), ("float32", 1e-6)])
@pytest.mark.slow
def test_fused_updates_equal_numpy_expressions(simulated, dtype, tol):
    got = simulated["update"][dtype]
    for key in ("x", "r", "p", "residual", "residual_norm"):  # residual: against float64
        assert got[key] < tol, key
    for key in ("rr", "dot"):  # float64 accumulation of the same values in both dtypes
        assert got[key] < 1e-12, key


@pytest.mark.slow
def test_cg_with_fused_kernels_matches_array_api_cg(simulated):
    got = simulated["cg"]
    assert got["iterations_fused"] == got["iterations_api"]
    assert 5 < got["iterations_fused"] < 200
    assert got["solution"] < 1e-12
    assert got["true_residual"] < 1e-10
    assert got["restarts_fused"] == 0


@pytest.mark.parametrize("case", BLOCK_CASES)
@pytest.mark.slow
def test_block_cg_with_the_fused_block_kernel_equals_single_solves(simulated, case):
    got = simulated["block_cg"]
    assert got[f"{case}_same_iterations"] == 1.0
    assert got[f"{case}_solution"] <= 1e-10


def test_bad_input_is_named_without_a_device():
    from itr_fft.fused_kernels import FusedOperator, FusedOps
    with refuses(ValueError, "g"):
        FusedOperator(np.ones((2, 4, 4, 4)))
    with refuses(ValueError, "g"):
        FusedOperator(np.ones((3, 4, 4, 4), dtype=np.int64))
    with refuses(ValueError, "threads_per_block"):
        FusedOps(threads_per_block=6)


def test_clear_error_where_no_cuda():
    from itr_fft.fused_kernels import FusedOps, fused_available
    if fused_available():
        pytest.skip("this process sees a CUDA device or the simulator")
    with pytest.raises(RuntimeError, match="NUMBA_ENABLE_CUDASIM"):
        FusedOps()


if __name__ == "__main__":
    _main()


def test_auto_falls_back_to_the_portable_kernels_where_the_fused_ones_do_not_build(
        monkeypatch):
    """On the lent H200 (2026-11-26) numba's CUDA target failed to build its kernels with
    that NumPy (``numpy.row_stack`` gone): ``"auto"`` must then solve with the portable
    kernels, ``"fused"`` must say why it cannot."""
    import itr_fft.fused_kernels as fk
    from itr_fft.array_api_backend import _use_fused

    why = "AttributeError: module 'numpy' has no attribute 'row_stack'"
    monkeypatch.setattr(fk, "fused_available", lambda: True)
    monkeypatch.setattr(fk, "fused_failure", lambda xp: why)
    import itr_fft.array_api_backend as ab

    monkeypatch.setattr(ab, "_TOLD", set())
    with pytest.warns(RuntimeWarning, match="row_stack.*portable kernels, about 2.3x slower"):
        assert _use_fused("auto", "cuda", "cupy", np) is False
    with warnings.catch_warnings():  # said once: the second solve falls back silently
        warnings.simplefilter("error")
        assert _use_fused("auto", "cuda", "cupy", np) is False
    with refuses(ValueError, "kernels"):
        _use_fused("fused", "cuda", "cupy", np)
    assert _use_fused("portable", "cuda", "cupy", np) is False
    monkeypatch.setattr(fk, "fused_failure", lambda xp: None)
    assert _use_fused("auto", "cuda", "cupy", np) is True
    assert _use_fused("auto", "cpu", "numpy", np) is False  # auto: fused on CUDA only
