"""Every stage of a solve where the backend's arrays live.

The load vector, ``A theta``, the face fluxes, the mean flux, the energy tensor
(:mod:`itr_fv.discrete.operator`) and the cluster projection
(:class:`itr_fv.discrete.connectivity.ClusterProjection`) are written once in array-API
code. Here they run under NumPy and under ``array-api-strict`` (which refuses anything
outside the standard) and are checked against independent host references: the sparse
matrix of the pyamg backend, the numba load kernel, sums over explicit face index lists
and ``np.bincount``. The driver brings no field-sized array back to the host unless the
fields are asked for.
"""

from __future__ import annotations

import functools

import array_api_strict
import numpy as np
import pytest
from refusals import refuses

from itr_fft import _kernels as K
from itr_fft.array_api_backend import ArrayAPIBackend, _Prepared, to_numpy
from itr_fv import homogenize
from itr_fv.discrete.connectivity import ClusterProjection
from itr_fv.discrete.operator import (
    apply_operator,
    effective_tensors,
    energy_tensor,
    face_fluxes,
    load_vector,
    mean_flux,
)
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.solvers.amg import assemble_operator
from itr_fv.solvers.backends import backend_for
from itr_fv.solvers.driver import device_arrays
from validation.gallery import build

NAMESPACES = ["numpy", "array_api_strict"]


def _xp(name: str):
    if name == "array_api_strict":
        return array_api_strict
    import array_api_compat.numpy as xp
    return xp


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


@functools.cache
def _system(case: str, n: int):
    """(voxel edge m, face conductances, cluster labels) of a common-set case."""
    ms, mat = build(case, n)
    system = DiscreteProblem.for_materials(ms, mat).system(mat)
    return ms.voxel_m, system.g, system.labels


def _fields(shape, count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.standard_normal(shape) for _ in range(count)]


def _neighbours(shape, axis: int) -> np.ndarray:
    """Flat index of voxel p + e_axis (periodic) for every voxel p, by index arithmetic."""
    idx = np.indices(shape)
    idx[axis] = (idx[axis] + 1) % shape[axis]
    return np.ravel_multi_index(tuple(idx), shape).ravel()


def _drops(theta: np.ndarray, axis: int, h: float, E_axis: float) -> np.ndarray:
    """T_p - T_{p+e_axis} over the explicit face list (no roll), flat."""
    t = theta.ravel()
    return t - t[_neighbours(theta.shape, axis)] + h * E_axis


def _reference_tensors(g, thetas, h, directions):
    """Flux average and energy estimate as sums over the explicit face list."""
    n = g[0].size
    flux = np.full((3, 3), np.nan)
    energy = np.full((3, 3), np.nan)
    for a, i in enumerate(directions):
        flux[:, i] = [np.sum(g[d].ravel() * _drops(thetas[a], d, h, d == i)) / n
                      for d in range(3)]
        for b, j in enumerate(directions):
            energy[i, j] = sum(np.sum(g[d].ravel() * _drops(thetas[a], d, h, d == i)
                                      * _drops(thetas[b], d, h, d == j))
                               for d in range(3)) / (n * h)
    return flux, energy


@pytest.mark.parametrize("namespace", NAMESPACES)
def test_operator_is_the_sparse_matrix(namespace):
    xp = _xp(namespace)
    _, g, _ = _system("random30_Rinf", 16)
    (theta,) = _fields(g.shape[1:], 1, seed=1)
    expected = (assemble_operator(g) @ theta.ravel()).reshape(theta.shape)
    got = apply_operator(xp.asarray(g), xp.asarray(theta))
    assert type(got).__module__.split(".")[0] == namespace
    assert _rel(to_numpy(got), expected) <= 1e-13
    out = xp.zeros(theta.shape, dtype=xp.float64)
    assert apply_operator(xp.asarray(g), xp.asarray(theta), out) is out
    assert _rel(to_numpy(out), expected) <= 1e-13


@pytest.mark.parametrize("namespace", NAMESPACES)
def test_load_vector_is_the_numba_kernel(namespace):
    xp = _xp(namespace)
    h, g, _ = _system("al2o3_60", 16)
    E = (0.3, -1.2, 2.0)
    expected = np.zeros(g.shape[1:])
    for d in range(3):
        part = np.zeros(g.shape[1:])
        K.load_into(g, d, h * E[d], part)
        expected += part
    got = load_vector(xp.asarray(g), h, E)
    assert type(got).__module__.split(".")[0] == namespace and got.dtype == xp.float64
    assert _rel(to_numpy(got), expected) <= 1e-13
    with refuses(ValueError, "E"):
        load_vector(xp.asarray(g), h, (1.0, 0.0))


@pytest.mark.parametrize("namespace", NAMESPACES)
def test_fluxes_and_tensors_are_the_face_sums(namespace):
    """Mean flux, face fluxes, energy tensor and the fused pair equal sums over an explicit
    face list (a grid with insulating faces, fields that are not solutions)."""
    xp = _xp(namespace)
    h, g, _ = _system("random30_Rinf", 16)
    thetas = _fields(g.shape[1:], 2, seed=2)
    directions = (2, 0)
    ref_flux, ref_energy = _reference_tensors(g, thetas, h, directions)
    gx = xp.asarray(g)
    tx = [xp.asarray(t) for t in thetas]
    flux, energy = effective_tensors(gx, tx, h, directions)
    assert isinstance(flux, np.ndarray) and np.isnan(flux[:, 1]).all()
    assert np.isnan(energy[1]).all() and np.isnan(energy[:, 1]).all()
    cols = list(directions)
    assert _rel(flux[:, cols], ref_flux[:, cols]) <= 1e-13
    assert _rel(energy[np.ix_(cols, cols)], ref_energy[np.ix_(cols, cols)]) <= 1e-13
    assert _rel(energy_tensor(gx, tx, h, directions)[np.ix_(cols, cols)],
                ref_energy[np.ix_(cols, cols)]) <= 1e-13
    E = (0.0, 0.0, 1.0)
    assert _rel(mean_flux(gx, tx[0], h, E), ref_flux[:, 2]) <= 1e-13
    q = to_numpy(face_fluxes(gx, tx[0], h, E))
    for d in range(3):
        assert _rel(q[d].ravel(), g[d].ravel() * _drops(thetas[0], d, h, E[d])) <= 1e-13
    with refuses(ValueError, "directions"):
        effective_tensors(gx, tx, h, (0,))


@pytest.mark.parametrize("namespace", NAMESPACES)
def test_float32_arrays_are_summed_in_float64(namespace):
    """float32 conductances and fields (a float32 device solve): the tensors equal the
    float64 sums of the same rounded values (float32 sums would be off by ~1e-6)."""
    xp = _xp(namespace)
    h, g, _ = _system("al2o3_60", 16)
    g32 = g.astype(np.float32)
    thetas = [t.astype(np.float32) for t in _fields(g.shape[1:], 3, seed=3)]
    ref_flux, ref_energy = _reference_tensors(g32.astype(np.float64),
                                              [t.astype(np.float64) for t in thetas], h,
                                              (0, 1, 2))
    flux, energy = effective_tensors(xp.asarray(g32), [xp.asarray(t) for t in thetas], h,
                                     (0, 1, 2))
    assert _rel(flux, ref_flux) <= 1e-12
    assert _rel(energy, ref_energy) <= 1e-12


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("namespace", NAMESPACES)
def test_cluster_projection_removes_every_cluster_mean(namespace, dtype):
    xp = _xp(namespace)
    _, g, labels = _system("random30_Rinf", 16)
    assert labels is not None and labels.max() > 5  # floating particles
    (v,) = _fields(labels.shape, 1, seed=4)
    v = (v + 3.0 * labels).astype(dtype)  # a different level on every cluster
    like = xp.asarray(g)
    projection = ClusterProjection(labels, like=like)
    assert projection.n_clusters == labels.max() + 1
    vx = xp.asarray(v.copy())
    assert projection.project(vx) is vx
    got = to_numpy(vx).astype(np.float64)
    counts = np.bincount(labels.ravel())
    means = np.bincount(labels.ravel(), weights=got.ravel()) / counts
    tol = 1e-12 if dtype == np.float64 else 1e-5
    assert np.abs(means).max() <= tol * np.abs(v).max()
    shift = v.astype(np.float64) - got  # a constant on each cluster
    per_cluster = np.bincount(labels.ravel(), weights=shift.ravel()) / counts
    assert np.abs(shift - per_cluster[labels]).max() <= tol * np.abs(v).max()
    connected = xp.asarray(v.copy())
    ClusterProjection(None, like=like).project(connected)
    assert abs(float(np.mean(to_numpy(connected), dtype=np.float64))) <= tol * np.abs(v).max()
    with refuses(ValueError, "labels"):
        ClusterProjection(labels.astype(np.float64))
    with refuses(ValueError, "labels"):
        ClusterProjection(labels + 1)  # no voxel in cluster 0


def _count_conversions(monkeypatch, size: int) -> list[str]:
    """Record every field-sized array of the strict namespace that reaches NumPy, by
    ``to_host`` or by the library's own conversions (``__array__``, ``__dlpack__``)."""
    seen: list[str] = []
    Array = type(array_api_strict.ones(1))

    def counting(name, method, arg):
        def wrapper(*args, **kwargs):
            if getattr(args[arg], "size", 0) >= size:
                seen.append(name)
            return method(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(_Prepared, "to_host", counting("to_host", _Prepared.to_host, 1))
    for name in ("__array__", "__dlpack__"):
        monkeypatch.setattr(Array, name, counting(name, getattr(Array, name), 0))
    return seen


def test_no_field_comes_back_without_store_fields(monkeypatch):
    backend = backend_for("array_api", device="cpu", namespace="array_api_strict")
    ms, mat = build("al2o3_60", 12)
    seen = _count_conversions(monkeypatch, size=ms.material_ids.size)
    res = homogenize(ms, mat, solver=backend, tol=1e-10, store_fields=False)
    assert res.converged and seen == []  # conductances built there, nothing comes back
    ms, mat = build("random30_Rinf", 12)
    res = homogenize(ms, mat, solver=backend, tol=1e-10, store_fields=False)
    assert res.converged and np.isfinite(res.k_eff).all() and np.isfinite(res.k_eff_energy).all()
    # insulating faces: the conductances come to the host once, for the connected clusters
    assert seen == ["__dlpack__"]
    seen.clear()
    fields = homogenize(ms, mat, solver=backend, tol=1e-10, store_fields=True)
    # theta and the face fluxes of each load case, each by to_host (through DLPack), and
    # the conductances once for the clusters
    assert seen.count("to_host") == 6 and seen.count("__dlpack__") == 7
    assert "__array__" not in seen
    np.testing.assert_allclose(fields.k_eff, res.k_eff, rtol=1e-12, atol=0)


def test_host_backends_keep_the_host_arrays():
    """A NumPy backend states nothing: the driver takes the system's own conductances and
    a host cluster projection; the array backend hands over its device arrays."""
    ms, mat = build("random30_Rinf", 12)
    system = DiscreteProblem.for_materials(ms, mat).system(mat)
    for name in ("itr_fft", "scipy_fft", "itr_fv"):
        prepared = backend_for(name).prepare(system, ms.voxel_m)
        try:
            g, clusters = device_arrays(prepared, system)
            assert g is system.g and clusters.n_clusters == system.floating.count + 1
            assert prepared.to_host(g) is g
        finally:
            prepared.close()
    prepared = ArrayAPIBackend(device="cpu", namespace="array_api_strict").prepare(
        system, ms.voxel_m)
    g, clusters = device_arrays(prepared, system)
    assert g is prepared.g and clusters is prepared.clusters
    assert type(g).__module__.split(".")[0] == "array_api_strict"
    np.testing.assert_array_equal(prepared.to_host(g), system.g)
