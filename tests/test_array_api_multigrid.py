"""The multigrid and particle-deflation preconditioners in array-API code (issue 27).

Checked against the numba code path that they mirror: one application equals
:class:`itr_fft.multigrid.AggregationMultigrid` and :class:`itr_fft.deflation.ParticleDeflation`
to round-off under NumPy and ``array-api-strict``, and CG with them (the one
``conjugate_gradients`` with the array-API operator and vector operations) takes the numba
backend's ``"multigrid"`` iterations and reaches its solution. Grids 15^3-20^3, odd ones
included (a box one cell wide on every coarse level).
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from conftest import fast_few
from refusals import refuses

from itr_fft.array_api_backend import ArrayAPIOps, _cuda_available, _Operator
from itr_fft.array_api_multigrid import (
    ArrayAPIDeflation,
    ArrayAPIMultigrid,
    ParticleMultigridPreconditioner,
    face_stencil,
)
from itr_fft.deflation import ParticleDeflation
from itr_fft.multigrid import AggregationMultigrid
from itr_fft.numba_backend import NumbaFFTBackend
from itr_fv.discrete.connectivity import ClusterProjection
from itr_fv.discrete.operator import load_vector
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.solvers.krylov import conjugate_gradients
from validation.gallery import build

#: (case, voxels per edge): high-contrast AlN (bulk contrast ~1100, R_fp = 5e-6), a
#: resistive interface (R = 5e-5 on an SC array, odd grid) and floating particles
#: (R = inf: clusters, so the cluster projection runs too).
CASES = [("aln_60", 20), ("sc_R5e-5", 17), ("random30_Rinf", 16)]
NAMESPACES = ["numpy", "array_api_strict"]


def _xp(name: str):
    if name == "array_api_strict":
        import array_api_strict
        return array_api_strict
    import array_api_compat.numpy as xp
    return xp


def _host(x) -> np.ndarray:
    return np.asarray(np.from_dlpack(x), dtype=np.float64)


def _system(case: str, n: int):
    ms, mat = build(case, n)
    return ms, DiscreteProblem.for_materials(ms, mat).system(mat)


def _residual(shape, seed: int = 1) -> np.ndarray:
    r = np.random.default_rng(seed).standard_normal(shape)
    return r - r.mean()


def _gauged(theta: np.ndarray, labels: np.ndarray | None) -> np.ndarray:
    """theta without the mean of every connected cluster (the whole grid without labels)."""
    ids = np.zeros(theta.size, dtype=np.int64) if labels is None else labels.ravel()
    means = np.bincount(ids, weights=theta.ravel()) / np.bincount(ids)
    return theta - means[ids].reshape(theta.shape)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("namespace", NAMESPACES)
def test_face_stencil_is_the_operator_of_the_backend(namespace):
    xp = _xp(namespace)
    _, system = _system("aln_60", 12)
    x = _residual(system.g.shape[1:], seed=2)
    s = np.abs(_residual(x.shape, seed=3))
    g = xp.asarray(system.g)
    out = xp.zeros(x.shape, dtype=xp.float64)
    _Operator(xp, g).apply(xp.asarray(x), out)
    got = face_stencil(xp, g, xp.asarray(x), xp.asarray(s))
    assert _relative(_host(got), _host(out) + s * x) <= 1e-14


@pytest.mark.parametrize("cycle", ["V", "W"])
@pytest.mark.parametrize("namespace", NAMESPACES)
@pytest.mark.parametrize("case,n", fast_few(CASES, "sc_R5e-5"))
def test_cycle_equals_the_numba_multigrid(case, n, namespace, cycle):
    xp = _xp(namespace)
    _, system = _system(case, n)
    g, ids = system.g, system.particle_ids
    r = _residual(g.shape[1:])
    # coarsest=40: four levels, odd shapes on the coarse ones
    ref = AggregationMultigrid(g, ids, dtype=np.float64, coarsest=40, cycle=cycle)
    mg = ArrayAPIMultigrid(xp, g, ids, dtype=np.float64, coarsest=40, cycle=cycle)
    assert mg.n_levels == ref.n_levels >= 3
    assert _relative(_host(mg.apply(xp.asarray(r))), ref.apply(r.copy())) <= 1e-12


@pytest.mark.parametrize("namespace", NAMESPACES)
def test_plain_boxes_without_particle_ids(namespace):
    xp = _xp(namespace)
    _, system = _system("aln_60", 15)
    r = _residual(system.g.shape[1:], seed=4)
    ref = AggregationMultigrid(system.g, None, dtype=np.float64, coarsest=40)
    pre = ParticleMultigridPreconditioner(xp, system.g, None, dtype=np.float64, coarsest=40)
    assert pre.deflation is None and pre.info["deflated_groups"] == 0
    z, rz = pre.apply_dot(xp.asarray(r))
    expected = ref.apply(r.copy())
    assert _relative(_host(z), expected) <= 1e-12
    assert abs(rz - float(r.ravel() @ expected.ravel())) <= 1e-12 * abs(rz)


@pytest.mark.parametrize("namespace", NAMESPACES)
@pytest.mark.parametrize("case,n", fast_few(CASES, "sc_R5e-5"))
def test_deflation_equals_the_particle_deflation(case, n, namespace):
    xp = _xp(namespace)
    _, system = _system(case, n)
    g, ids = system.g, system.particle_ids
    r = _residual(g.shape[1:], seed=5)
    ref = ParticleDeflation(g, ids, AggregationMultigrid(g, ids, dtype=np.float64))
    z_ref, rz_ref = ref.apply_dot(r.copy())
    gx = xp.asarray(g)
    mg = ArrayAPIMultigrid(xp, g, ids, dtype=np.float64, g_device=gx)
    dfl = ArrayAPIDeflation(xp, g, ids, mg, g64=gx)
    assert dfl.n_groups == ref.n_groups > 1
    z, rz = dfl.apply_dot(xp.asarray(r))
    assert _relative(_host(z), z_ref) <= 1e-12
    assert abs(rz - rz_ref) <= 1e-12 * abs(rz_ref)


def _numba_solve(system, b: np.ndarray, voxel_m: float, tol: float):
    prepared = NumbaFFTBackend(preconditioner="multigrid").prepare(system, voxel_m)
    try:
        return prepared.solve(b, None, tol, 3000)
    finally:
        prepared.close()


@pytest.mark.parametrize("namespace", NAMESPACES)
@pytest.mark.parametrize("case,n", fast_few(CASES, "sc_R5e-5"))
def test_cg_takes_the_numba_backends_iterations(case, n, namespace):
    """The float32 hierarchy (as the numba backend's), float64 CG vectors, tol 1e-8."""
    xp = _xp(namespace)
    ms, system = _system(case, n)
    tol = 1e-8
    g = xp.asarray(system.g)
    clusters = None if system.labels is None else ClusterProjection(system.labels, like=g)
    project = None if clusters is None else clusters.project
    pre = ParticleMultigridPreconditioner.from_system(xp, system, g_device=g, project=project)
    assert pre.deflation is not None
    for d in range(3):
        E = np.zeros(3)
        E[d] = 1.0
        b = load_vector(system.g, ms.voxel_m, E)
        ref = _numba_solve(system, b, ms.voxel_m, tol)
        x = xp.zeros(b.shape, dtype=xp.float64)
        out = conjugate_gradients(_Operator(xp, g), xp.asarray(b), x, tol=tol, maxiter=3000,
                                  preconditioner=pre, ops=ArrayAPIOps(xp), project=project)
        assert out.residual <= tol and ref.residual <= tol
        assert abs(out.iterations - ref.iterations) <= 1
        theta_ref = _gauged(np.asarray(_host(ref.x)), system.labels)
        assert _relative(_gauged(_host(x), system.labels), theta_ref) <= 1e-8


def test_bad_arguments_raise_naming_them():
    xp = _xp("numpy")
    g = np.ones((3, 4, 4, 4))
    ids = np.zeros((4, 4, 4), dtype=np.int32)
    ids[:2] = 1
    with refuses(ValueError, "dtype"):
        ArrayAPIMultigrid(xp, g, ids, dtype=np.float16)
    with refuses(ValueError, "groups"):
        ArrayAPIMultigrid(xp, g, ids[:3])
    with refuses(ValueError, "g_device"):
        ArrayAPIMultigrid(xp, g, ids, dtype=np.float32, g_device=xp.asarray(g))
    mg = ArrayAPIMultigrid(xp, g, ids)
    with refuses(ValueError, "r"):
        mg.apply(xp.zeros((4, 4, 3)))
    with refuses(ValueError, "groups"):
        ArrayAPIDeflation(xp, g, None, mg)
    with refuses(ValueError, "g64"):
        ArrayAPIDeflation(xp, g, ids, mg, g64=xp.asarray(g, dtype=xp.float32))


@pytest.mark.skipif(importlib.util.find_spec("cupy") is None or _cuda_available() != "cupy",
                    reason="needs CuPy and a CUDA device")
def test_on_the_gpu_with_cupy():
    import array_api_compat.cupy as xp
    import cupy

    _, system = _system("aln_60", 20)
    g, ids = system.g, system.particle_ids
    r = _residual(g.shape[1:])
    dev = cupy.cuda.Device()
    ref = ParticleDeflation(g, ids, AggregationMultigrid(g, ids, dtype=np.float64))
    pre = ParticleMultigridPreconditioner(xp, g, ids, device=dev, dtype=np.float64)
    z = pre.apply(xp.asarray(r, device=dev))
    assert _relative(z.get(), ref.apply(r.copy())) <= 1e-12
