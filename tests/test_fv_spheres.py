"""Sphere arrays against exact values; tensor symmetry and isotropy of a random RVE."""

import numpy as np
import pytest
from conftest import random_spheres, sc_sphere

from itr_fv import Materials, homogenize

# the slow tier (.ci/run runs it after the fast tier): 64^3 sphere arrays; the fast tier checks the
# finite-volume solver on exact cases in test_fv_exact.py
pytestmark = pytest.mark.slow

# Rayleigh multipole values for the simple-cubic array, f = 0.3, k_p/k_m = 10
SC_PERFECT = 1.88774
SC_ALPHA_05 = 1.17292


def sc_materials(k_ratio: float, R: float) -> Materials:
    return Materials({"matrix": 1.0, "filler": k_ratio}, {("filler", "matrix"): R},
                     matrix="matrix")


def radius(f: float) -> float:
    return (3.0 * f / (4.0 * np.pi)) ** (1.0 / 3.0)


@pytest.mark.parametrize("k_ratio", [10.0, 170.0])
def test_neutral_inclusion_is_invisible(k_ratio):
    """R k_m / a = 1 - k_m / k_p makes the coated sphere invisible: k_eff = k_m."""
    f = 0.3
    R = (1.0 - 1.0 / k_ratio) * radius(f)
    res = homogenize(sc_sphere(64, f), sc_materials(k_ratio, R), solver="fv", tol=1e-10,
                     directions=(0,))
    assert res.k_eff[0, 0] == pytest.approx(1.0, rel=0.01)
    # and without the correction the same sphere is clearly visible (resistance too low)
    off = homogenize(sc_sphere(64, f), sc_materials(k_ratio, R), solver="fv", tol=1e-10,
                     directions=(0,), staircase=False)
    assert off.k_eff[0, 0] > 1.03


def test_sc_perfect_interface_matches_rayleigh():
    res = homogenize(sc_sphere(64, 0.3), sc_materials(10.0, 0.0), solver="fv", tol=1e-10)
    np.testing.assert_allclose(np.diag(res.k_eff), SC_PERFECT, rtol=0.005)
    # cubic symmetry of the array: isotropic, no off-diagonal
    assert np.ptp(np.diag(res.k_eff)) < 1e-8
    assert np.abs(res.k_eff - np.diag(np.diag(res.k_eff))).max() < 1e-8


def test_sc_interface_resistance_needs_staircase_correction():
    f = 0.3
    mat = sc_materials(10.0, 0.5 * radius(f))
    ms = sc_sphere(96, f)
    on = homogenize(ms, mat, solver="fv", tol=1e-10, directions=(0,))
    off = homogenize(ms, mat, solver="fv", tol=1e-10, directions=(0,), staircase=False)
    err_on = abs(on.k_eff[0, 0] / SC_ALPHA_05 - 1.0)
    err_off = abs(off.k_eff[0, 0] / SC_ALPHA_05 - 1.0)
    assert err_on < 0.01
    assert err_off > 0.05
    # without it the interface looks too conductive: the voxel stair has more area
    assert off.k_eff[0, 0] > on.k_eff[0, 0]


def test_random_polydisperse_tensor_symmetric_and_isotropic():
    """Symmetric to solver tolerance; diagonal spread within the seed-to-seed scatter."""
    mat = Materials({"matrix": 0.18, "A": 30.0, "B": 200.0},
                    {("A", "matrix"): 0.02, ("B", "matrix"): 0.01, ("A", "B"): 0.05,
                     ("A", "A"): 0.1, ("B", "B"): 0.1}, matrix="matrix")
    means, spreads = [], []
    for seed in range(3):
        res = homogenize(random_spheres(48, 0.2, seed, r_range=(0.06, 0.11)), mat, solver="fv",
                         tol=1e-10)
        assert res.symmetry_error < 1e-8
        np.testing.assert_allclose(res.k_eff, res.k_eff_energy, rtol=1e-8, atol=1e-10)
        diag = np.diag(res.k_eff)
        means.append(diag.mean())
        spreads.append(np.abs(diag - diag.mean()).max() / diag.mean())
        off = res.k_eff - np.diag(diag)
        assert np.abs(off).max() < 0.05 * diag.mean()
    scatter = np.std(means) / np.mean(means)
    # anisotropy of one RVE is of the order of the sample-to-sample scatter, and small
    assert max(spreads) < max(4 * scatter, 0.02)
    assert max(spreads) < 0.1
    # and well above the matrix: the fillers conduct
    assert min(means) > 0.18 * 1.3


def test_label_image_staircase_estimate_close_to_analytic_normals():
    """Without a particle table the normals come from the smoothed image (documented)."""
    from itr_fv import Microstructure
    f = 0.3
    ms = sc_sphere(48, f)
    labels = Microstructure.from_labels(ms.material_ids, ms.particle_ids, ms.voxel_m, ms.names)
    mat = sc_materials(10.0, 0.5 * radius(f))
    analytic = homogenize(ms, mat, solver="fv", tol=1e-10, directions=(0,)).k_eff[0, 0]
    image = homogenize(labels, mat, solver="fv", tol=1e-10, directions=(0,))
    assert image.info["staircase"] == "image"
    assert image.k_eff[0, 0] == pytest.approx(analytic, rel=0.005)
    assert image.k_eff[0, 0] == pytest.approx(SC_ALPHA_05, rel=0.01)


def test_sphere_touching_its_own_image_gets_contact_resistance():
    """One-sphere SC cell at f = 0.5 on a coarse grid: the voxelized sphere bridges the
    0.015 L gap to its own periodic image. That bridge is a contact between two spheres
    and must carry R(p, p), exactly as in the 2 x 2 x 2 supercell with 8 distinct ids."""
    from itr_fv import Microstructure
    f, L = 0.5, 1.0
    a = radius(f) * L
    mat = Materials({"matrix": 1.0, "filler": 170.0},
                    {("filler", "matrix"): 2.0 * a, ("filler", "filler"): 2.0 * a}, "matrix")
    one = Microstructure.from_spheres(np.full((1, 3), 0.5 * L), np.array([a]), "filler",
                                      box_m=L, shape=24, matrix="matrix")
    c = np.array([[i, j, k] for i in range(2) for j in range(2) for k in range(2)]) * L + 0.5 * L
    eight = Microstructure.from_spheres(c, np.full(8, a), "filler", box_m=2 * L, shape=48,
                                        matrix="matrix")
    np.testing.assert_array_equal(eight.material_ids[:24, :24, :24], one.material_ids)
    k1 = homogenize(one, mat, solver="fv", tol=1e-10, directions=(0,)).k_eff[0, 0]
    k8 = homogenize(eight, mat, solver="fv", tol=1e-10, directions=(0,)).k_eff[0, 0]
    assert k1 == pytest.approx(k8, rel=1e-7)
    # the resistive bridges keep it near the multipole value 0.72252 (alpha = 2), far from
    # the perfectly conducting bridge (several times larger)
    assert k1 < 1.0
