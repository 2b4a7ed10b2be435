"""The device-neutral array-API backend (issue 27): the same FFT-PCG on any array library.

On the CPU it runs under NumPy and under ``array-api-strict`` (the standard's reference
implementation, which refuses anything outside the standard) and must equal the numba
backend on the common RVE set; on a GPU (CuPy) the same test runs where one exists.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import itr_fft
from itr_fft.array_api_backend import ArrayAPIBackend, _cuda_available, resolve_device
from itr_fv.solvers.driver import homogenize
from itr_fv.solvers.choice import solver_backend, worker_resources
from validation.gallery import build, rve_cases

CASES = [c.name for c in rve_cases()]
TOL = 1e-12


def _reference(case):
    ms, mat = build(case, "ci")
    ref = homogenize(ms, mat, backend=itr_fft.NumbaFFTBackend(fft_dtype=np.float64,
                                                              preconditioner="fft"),
                     tol=TOL, store_fields=False)
    return ms, mat, ref


@pytest.mark.parametrize("namespace", ["numpy", "array_api_strict"])
@pytest.mark.parametrize("case", CASES)
def test_equals_the_numba_backend_on_the_common_set(case, namespace):
    ms, mat, ref = _reference(case)
    res = homogenize(ms, mat, backend=ArrayAPIBackend(device="cpu", namespace=namespace),
                     tol=TOL, store_fields=False)
    assert res.solver == "array_api" and res.info["namespace"] == namespace
    assert np.abs(res.k_eff - ref.k_eff).max() <= 1e-10 * np.abs(ref.k_eff).max()
    assert res.converged and max(res.residuals) <= TOL


def test_float32_vectors_under_the_strict_namespace():
    ms, mat, ref = _reference("al2o3_60")
    res = homogenize(ms, mat, backend=ArrayAPIBackend(device="cpu", namespace="array_api_strict",
                                                      dtype=np.float32),
                     tol=4e-6, store_fields=False)
    assert np.abs(res.k_eff - ref.k_eff).max() <= 1e-5 * np.abs(ref.k_eff).max()
    with pytest.raises(ValueError, match="tol"):
        homogenize(ms, mat, backend=ArrayAPIBackend(device="cpu", dtype=np.float32),
                   tol=1e-9)


def test_registered_by_name_and_warm_start():
    ms, mat, ref = _reference("fcc_R1e-6")
    res = homogenize(ms, mat, backend="array_api", tol=TOL)
    warm = homogenize(ms, mat, backend="array_api", tol=TOL, x0=np.stack(res.theta))
    assert max(warm.iterations) <= 2
    assert np.abs(warm.k_eff - ref.k_eff).max() <= 1e-10 * np.abs(ref.k_eff).max()


def test_device_choices_are_checked():
    with pytest.raises(ValueError, match="device"):
        ArrayAPIBackend(device="tpu")
    with pytest.raises(ValueError, match="namespace"):
        ArrayAPIBackend(device="cpu", namespace="jax")
    with pytest.raises(ValueError, match="namespace"):
        ArrayAPIBackend(device="cpu", namespace="cupy")
    with pytest.raises(ValueError, match="dtype"):
        ArrayAPIBackend(device="cpu", dtype=np.float16)
    if _cuda_available() is None:
        assert resolve_device("auto") == ("cpu", "numpy")
        with pytest.raises(ValueError, match="device: 'cuda'"):
            ArrayAPIBackend(device="cuda")


def test_solver_choices_for_the_campaign_engine():
    assert worker_resources("gpu") == {"GPU": 1}
    assert worker_resources("fft") is None and worker_resources("mg") is None
    mg = solver_backend("mg", threads=1)
    assert mg.name == "itr_fft" and mg.preconditioner == "multigrid" and mg.workers == 1
    with pytest.raises(ValueError, match="solver"):
        worker_resources("quantum")


@pytest.mark.skipif(importlib.util.find_spec("cupy") is None,
                    reason="CuPy is not installed (the [gpu] extra): GPU unverified here")
@pytest.mark.parametrize("case", ["al2o3_60", "aln_60", "random30_Rinf"])
def test_equals_the_numba_backend_on_a_gpu(case):
    if _cuda_available() != "cupy":
        pytest.skip("no CUDA device visible to CuPy: GPU unverified here")
    ms, mat, ref = _reference(case)
    res = homogenize(ms, mat, backend=ArrayAPIBackend(device="cuda", namespace="cupy"),
                     tol=TOL, store_fields=False)
    assert res.info["device"] == "cuda"
    assert np.abs(res.k_eff - ref.k_eff).max() <= 1e-10 * np.abs(ref.k_eff).max()
