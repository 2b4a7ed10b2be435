"""Every solver path of one discrete model gives the same tensor (issue 61, acceptance 4):
on one RVE per contact model, the FV reference (pyamg) against the numba FFT backend with
each preconditioner, one load case at a time and in lockstep, in mixed precision, with
FFTW's transforms, the array-API backend on NumPy with each preconditioner, SciPy's FFT
backend, and a GPU choice whose grid the cost model sends to the CPU; every tensor within
1e-8 of the reference's largest entry (all solved to tol 1e-10). The fused CUDA kernels
are held to the array-API path under numba's CUDA simulator in tests/test_fused_kernels.py
(1e-16 per operation, the same CG iterations)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import itr_fft  # noqa: F401  (registers the backends)
from itr_fft.fft_pair import fftw_available
from itr_fv import homogenize
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.solvers.backends import backend_for
from itr_fv.solvers.choice import as_solver
from validation.gallery import build

PATHS = {
    "itr_fft fft": ("itr_fft", {"preconditioner": "fft"}),
    "itr_fft multigrid": ("itr_fft", {"preconditioner": "multigrid"}),
    "itr_fft block": ("itr_fft", {"block": True}),
    "itr_fft mixed": ("itr_fft", {"precision": "mixed"}),
    "itr_fft fftw": ("itr_fft", {"preconditioner": "fft", "fft": "fftw"}),
    "array_api fft": ("array_api", {"device": "cpu", "namespace": "numpy"}),
    "array_api multigrid": ("array_api", {"device": "cpu", "namespace": "numpy",
                                          "preconditioner": "multigrid"}),
    "scipy_fft": ("scipy_fft", {}),
}


@pytest.mark.parametrize("case, contact", [("al2o3_60", "gap"), ("aln_60", "area")])
def test_every_path_gives_the_reference_tensor_to_1e8(case, contact):
    ms, mat = build(case, 20, contact=contact)
    problem = DiscreteProblem.for_materials(ms, mat)
    ref = homogenize(problem, mat, solver="itr_fv", tol=1e-10, store_fields=False).k_eff
    scale = np.max(np.abs(ref))
    paths = dict(PATHS)
    if not fftw_available():
        paths.pop("itr_fft fftw")
    gpu_small = as_solver("gpu").backend(voxels=math.prod(ms.shape))  # the cost model: CPU
    assert gpu_small.name == "itr_fft"
    backends = {name: backend_for(b, **opts) for name, (b, opts) in paths.items()}
    backends["gpu choice, small grid"] = gpu_small
    for name, backend in backends.items():
        k = homogenize(problem, mat, solver=backend, tol=1e-10, store_fields=False).k_eff
        assert np.max(np.abs(k - ref)) <= 1e-8 * scale, name
