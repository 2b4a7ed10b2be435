"""Bad input raises a ValueError that names the offending argument."""

import math

import numpy as np
import pytest
from conftest import sc_sphere
from refusals import refuses

from itr_fv import Materials, Microstructure, homogenize, resolve_solver

K = {"matrix": 1.0, "filler": 10.0}
R = {("filler", "matrix"): 1e-3}


def ok_labels(n=6):
    mid = np.zeros((n, n, n), np.int32)
    mid[1:3, 1:3, 1:3] = 1
    return mid, mid.copy()


@pytest.mark.parametrize("build, name", [
    (lambda: Materials({"matrix": math.nan, "filler": 10.0}, R, "matrix"), "conductivity"),
    (lambda: Materials({"matrix": -1.0, "filler": 10.0}, R, "matrix"), "conductivity"),
    (lambda: Materials({"matrix": 0.0, "filler": 10.0}, R, "matrix"), "conductivity"),
    (lambda: Materials({"matrix": math.inf, "filler": 10.0}, R, "matrix"), "conductivity"),
    (lambda: Materials(K, {("filler", "matrix"): -1e-8}, "matrix"), "resistance"),
    (lambda: Materials(K, {("filler", "matrix"): math.nan}, "matrix"), "resistance"),
    (lambda: Materials(K, {("filler", "glass"): 1e-8}, "matrix"), "resistance"),
    (lambda: Materials(K, {("filler",): 1e-8}, "matrix"), "resistance"),
    (lambda: Materials(K, R, "epoxy"), "matrix"),
    (lambda: Materials({}, R, "matrix"), "conductivity"),
])
def test_bad_materials(build, name):
    with pytest.raises(ValueError, match=name):
        build()


@pytest.mark.parametrize("build, name", [
    (lambda: Microstructure.from_labels(*ok_labels(), voxel_m=0.0, names=("matrix", "filler")),
     "voxel_m"),
    (lambda: Microstructure.from_labels(*ok_labels(), voxel_m=math.nan, names=("matrix", "filler")),
     "voxel_m"),
    (lambda: Microstructure.from_labels(ok_labels()[0].astype(float), ok_labels()[1], 1e-6,
                                        ("matrix", "filler")), "material_ids"),
    (lambda: Microstructure.from_labels(ok_labels()[0], ok_labels(7)[1], 1e-6,
                                        ("matrix", "filler")), "particle_ids"),
    (lambda: Microstructure.from_labels(ok_labels()[0][0], ok_labels()[1][0], 1e-6,
                                        ("matrix", "filler")), "material_ids"),
    (lambda: Microstructure.from_labels(np.zeros((0, 4, 4), np.int32),
                                        np.zeros((0, 4, 4), np.int32), 1e-6, ("matrix",)),
     "material_ids"),
    (lambda: Microstructure.from_labels(*ok_labels(), voxel_m=1e-6, names=("matrix",)),
     "material_ids"),
    (lambda: Microstructure.from_labels(ok_labels()[0], np.zeros((6, 6, 6), np.int32), 1e-6,
                                        ("matrix", "filler")), "particle_ids"),
    (lambda: Microstructure.from_labels(-ok_labels()[0], ok_labels()[1], 1e-6,
                                        ("matrix", "filler")), "material_ids"),
    (lambda: Microstructure.from_spheres(np.zeros((1, 3)), np.array([0.1]), "filler",
                                         box_m=1.0, shape=(10, 10, 12)), "box_m/shape"),
    (lambda: Microstructure.from_spheres(np.zeros((1, 3)), np.array([0.6]), "filler",
                                         box_m=1.0, shape=10), "radii_m"),
    (lambda: Microstructure.from_spheres(np.zeros((1, 3)), np.array([-0.1]), "filler",
                                         box_m=1.0, shape=10), "radii_m"),
    (lambda: Microstructure.from_spheres(np.zeros((2, 2)), np.array([0.1, 0.1]), "filler",
                                         box_m=1.0, shape=10), "centers_m"),
    (lambda: Microstructure.from_spheres(np.full((1, 3), np.nan), np.array([0.1]), "filler",
                                         box_m=1.0, shape=10), "centers_m"),
    (lambda: Microstructure.from_spheres(np.zeros((1, 3)), np.array([0.1]), "filler",
                                         box_m=1.0, shape=0), "shape"),
    (lambda: Microstructure.from_spheres(np.zeros((1, 3)), np.array([0.1]), "filler",
                                         box_m=-1.0, shape=10), "box_m"),
    (lambda: Microstructure.from_spheres(np.zeros((1, 3)), np.array([0.1]), ["a", "b"],
                                         box_m=1.0, shape=10), "materials"),
])
def test_bad_microstructures(build, name):
    with pytest.raises(ValueError, match=name):
        build()


@pytest.mark.parametrize("kwargs, name", [
    ({"tol": 0.0}, "tol"),
    ({"tol": -1e-8}, "tol"),
    ({"tol": math.nan}, "tol"),
    ({"maxiter": 0}, "maxiter"),
    ({"maxiter": 2.5}, "maxiter"),
    ({"directions": (0, 0)}, "directions"),
    ({"directions": (3,)}, "directions"),
    ({"directions": ()}, "directions"),
    ({"x0": np.zeros((3, 4, 4, 4))}, "x0"),
    ({"callback": 5}, "callback"),
    ({"solver": resolve_solver("fv", amg="gmres")}, "amg"),
])
def test_bad_solver_arguments(kwargs, name):
    ms = sc_sphere(8, 0.2)
    with refuses(ValueError, name):
        homogenize(ms, Materials(K, R, "matrix"), **{"solver": "fv", **kwargs})


def test_unknown_phase_and_missing_pair_are_named():
    ms = sc_sphere(8, 0.2)
    with pytest.raises(ValueError, match="'filler'"):
        homogenize(ms, Materials({"matrix": 1.0, "glass": 2.0}, {}, "matrix"), solver="fv")
    with pytest.raises(ValueError, match=r"resistance.*\('filler', 'matrix'\)"):
        homogenize(ms, Materials(K, {}, "matrix"), solver="fv")
    with refuses(ValueError, "materials"):
        homogenize(ms, Materials({"silicone": 1.0, "filler": 2.0}, {}, "silicone"), solver="fv")
    with refuses(ValueError, "materials"):
        homogenize(ms, {"matrix": 1.0}, solver="fv")
    with refuses(ValueError, "problem"):
        homogenize(np.zeros((4, 4, 4)), Materials(K, R, "matrix"), solver="fv")


def test_contact_pair_is_required_only_when_particles_touch():
    mid = np.zeros((8, 8, 8), np.int32)
    pid = np.zeros_like(mid)
    mid[1:3, 1:3, 1:3] = 1
    pid[1:3, 1:3, 1:3] = 1
    mid[3:5, 1:3, 1:3] = 1
    pid[3:5, 1:3, 1:3] = 2   # touches particle 1 across x = 3
    ms = Microstructure.from_labels(mid, pid, 1e-6, ("matrix", "filler"))
    with pytest.raises(ValueError, match=r"\('filler', 'filler'\)"):
        homogenize(ms, Materials(K, R, "matrix", contact="area"), solver="fv")
    pid[3:5, 1:3, 1:3] = 0
    mid[3:5, 1:3, 1:3] = 0
    ms = Microstructure.from_labels(mid, pid, 1e-6, ("matrix", "filler"))
    assert homogenize(ms, Materials(K, R, "matrix", contact="area"), solver="fv",
                      tol=1e-10).converged


def test_non_convergence_raises_and_can_be_accepted():
    from itr_fv import ConvergenceError
    ms = sc_sphere(16, 0.3)
    mat = Materials({"matrix": 1.0, "filler": 170.0}, {("filler", "matrix"): 0.0}, "matrix")
    with pytest.raises(ConvergenceError) as info:
        homogenize(ms, mat, solver="fv", tol=1e-12, maxiter=1)
    assert not info.value.result.converged
    with pytest.warns(RuntimeWarning, match="not converged"):
        res = homogenize(ms, mat, solver="fv", tol=1e-12, maxiter=1, strict=False)
    assert not res.converged and res.iterations[0] == 1 and res.residuals[0] > 1e-12
