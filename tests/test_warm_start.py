"""Reduced-basis (Galerkin) warm starts for re-solving one geometry at new parameters."""

import warnings

import numpy as np
import pytest
from refusals import refuses

from itr_fv import Materials, homogenize
from itr_fv.discrete.model import apply_operator, face_geometry
from itr_fv.rve import FillerSpec, RVESpec, generate_rve
from itr_fv.solvers.warm_start import galerkin_start


@pytest.fixture(scope="module")
def dense():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        ms = generate_rve(RVESpec(32 * 0.3125, 0.3125, max_diameter_box_ratio=1 / 3),
                          [FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.6)], 3)
    return ms, face_geometry(ms)


def materials(r_fp: float) -> Materials:
    return Materials({"silicone": 0.18, "Al2O3": 30.0},
                     {("Al2O3", "silicone"): r_fp, ("Al2O3", "Al2O3"): 2e-7}, "silicone")


def energy_error(geometry, mat, x0, exact):
    g = geometry.conductances(mat)
    e = x0 - exact
    return float(np.sum(e * apply_operator(g, e)))


def test_galerkin_start_beats_nearest_snapshot(dense):
    ms, geo = dense
    snaps = {R: homogenize(ms, materials(R), solver="fft", tol=1e-10, directions=(0,),
                           geometry=geo).theta for R in (1e-8, 5e-8, 1e-7, 1e-6)}
    target = materials(5e-7)
    exact = homogenize(ms, target, solver="fft", tol=1e-12, directions=(0,), geometry=geo).theta
    nearest = snaps[1e-7]
    one = galerkin_start(geo, target, [nearest], directions=(0,))
    four = galerkin_start(geo, target, list(snaps.values()), directions=(0,))
    # energy-optimal over the span: never worse than the plain nearest field, and more
    # snapshots can only help
    e_near = energy_error(geo, target, nearest, exact)
    e_one = energy_error(geo, target, one, exact)
    e_four = energy_error(geo, target, four, exact)
    assert e_one <= e_near * (1 + 1e-9)
    assert e_four < 0.1 * e_one
    cold = homogenize(ms, target, solver="fft", tol=1e-8, directions=(0,), geometry=geo)
    warm = homogenize(ms, target, solver="fft", tol=1e-8, directions=(0,), geometry=geo, x0=four)
    assert warm.iterations[0] < 0.75 * cold.iterations[0]
    assert warm.k_eff[0, 0] == pytest.approx(cold.k_eff[0, 0], rel=1e-7)
    # the reference solver takes the same start
    fv = homogenize(ms, target, solver="fv", tol=1e-8, directions=(0,), geometry=geo, x0=four)
    assert fv.k_eff[0, 0] == pytest.approx(cold.k_eff[0, 0], rel=1e-7)


def test_galerkin_start_checks_its_input(dense):
    ms, geo = dense
    with refuses(ValueError, "snapshots"):
        galerkin_start(geo, materials(1e-7), [], directions=(0,))
    with refuses(ValueError, "snapshots"):
        galerkin_start(geo, materials(1e-7), [np.zeros((2,) + ms.shape)], directions=(0,))
    with refuses(ValueError, "geometry"):
        galerkin_start(ms, materials(1e-7), [np.zeros((1,) + ms.shape)], directions=(0,))
