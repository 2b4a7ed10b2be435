"""Touching particles meet at the stated film, whatever their size and box (issue 47).

The packer leaves touching spheres a clearance of inflate/2 .. inflate times (R_i + R_j):
1.5-5 nm in the cheap 12 um AlN RVE, up to 22 nm for the largest pairs of the 64 um box. The
contact geometry must read none of it as a film: the film at the closest point of every
touching pair is the stated one, to 0.01 nm.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from refusals import refuses

from itr_fv.discrete import _geometry_kernels as K
from itr_fv.discrete.contact_zones import zone_table
from itr_fv.discrete.face_geometry import face_geometry
from itr_fv.rve import FillerSpec, build_rve
from itr_fv.rve.contact_film import ContactFilm, clearance
from itr_fv.rve.packing import pairs_within_gap
from itr_fv.rve.spec import RVESpec

TOL_M = 1e-11  # 0.01 nm


def packed(box_um: float, film_nm: float = 0.0):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ms, _ = build_rve(RVESpec(box_um=box_um, voxel_um=0.25, seed=3,
                                  min_gap_um=film_nm * 1e-3),
                          [FillerSpec.from_table1("AlN", 0.6)], 0, matrix="silicone")
    return ms


def touching_pairs(ms):
    """The pairs the packer left touching: gap within inflate * (r_i + r_j) of min_gap
    (from the packer's own settings: inflate 1e-3 is generate_rve's default)."""
    t = ms.particles
    gap, inflate = t.contact.packing_gap_m, 1e-3
    box = ms.box_m[0]
    i, j, g = pairs_within_gap(t.centers_m, t.radii_m, box,
                               gap + 2.0 * inflate * (2.0 * t.radii_m.max() + gap))
    touch = g - gap <= inflate * (t.radii_m[i] + t.radii_m[j] + gap)
    return i[touch], j[touch], g[touch]


@pytest.fixture(scope="module")
def cheap():
    return packed(12.0)


@pytest.fixture(scope="module")
def converged_box():
    return packed(64.0)


def test_clearance_is_one_formula_for_numpy_and_the_kernels():
    rng = np.random.default_rng(0)
    gap0 = rng.uniform(-1e-9, 4e-8, 500)
    ra, rb = rng.uniform(5e-7, 1.5e-5, (2, 500))
    for args in [(0.0, 1e-3, 0.0), (2e-9, 1e-3, 2e-9), (0.0, 1e-3, 5e-9), (0.0, 0.0, 0.0)]:
        ref = clearance(gap0, ra, rb, *args)
        compiled = np.array([K._clearance(g, a, b, *args) for g, a, b in zip(gap0, ra, rb)])
        np.testing.assert_array_equal(compiled, ref)
    # by hand: a pair at 3 nm of 2 um + 3 um spheres (tolerance 5 nm) touches, at 6 nm not
    assert clearance(3e-9, 2e-6, 3e-6, 0.0, 1e-3, 0.0) == pytest.approx(3e-9)
    assert clearance(3e-9, 2e-6, 3e-6, 0.0, 1e-3, 1e-9) == pytest.approx(2e-9)
    assert clearance(6e-9, 2e-6, 3e-6, 0.0, 1e-3, 0.0) == 0.0


@pytest.mark.parametrize("which", ["cheap", "converged_box"])
@pytest.mark.parametrize("film_nm", [0.0, 2.0, 5.0])
def test_touching_pairs_meet_at_the_stated_film(which, film_nm, request):
    """Small and large pairs, the 12 um RVE and the 64 um box: the film at the closest
    point of every touching pair is the stated film to 0.01 nm, though the packed
    clearances grow with the pair's size."""
    ms = request.getfixturevalue(which).with_film(film_nm * 1e-9)
    i, j, g = touching_pairs(ms)
    size = ms.particles.radii_m[i] + ms.particles.radii_m[j]
    large = size >= np.median(size)
    assert large.sum() >= 10 and (~large).sum() >= 10
    # the clearance the packer left grows with size: the removal has work to do
    assert np.median(g[large]) > 1.3 * np.median(g[~large]) and g.max() > 3e-9
    zt = zone_table(ms, ms.voxel_m, 0.0)
    got = {}
    for a, b, gap in zip(zt.a, zt.b, zt.gap):
        got.setdefault((min(a, b), max(a, b)), []).append(gap)
    for sel in (large, ~large):
        films = np.array([min(got[(min(a, b), max(a, b))], key=lambda x: abs(x - film_nm * 1e-9))
                          for a, b in zip(i[sel], j[sel])])
        np.testing.assert_allclose(films, film_nm * 1e-9, rtol=0, atol=TOL_M)


def test_the_face_kernels_read_the_stated_film(cheap):
    """The contact faces' films (numba kernels) meet at the stated film too, and a pair that
    does not touch keeps its geometric gap."""
    for film in (0.0, 3e-9):
        ms = cheap.with_film(film)
        geom = face_geometry(ms, contact="gap")
        t = ms.particles
        i, j, _ = touching_pairs(ms)
        touching = {(min(a, b) + 1, max(a, b) + 1) for a, b in zip(i, j)}
        rows = [tuple(p) for p in geom.pair_particles[:, :2]]
        at_touch = np.array([r in touching for r in rows])
        assert at_touch.sum() >= 20
        np.testing.assert_allclose(geom.pair_gap_m[at_touch], film, rtol=0, atol=TOL_M)
        # the rest: as packed (more than the tolerance apart)
        rest = np.flatnonzero(~at_touch)
        assert rest.size > 0
        for k in rest:
            a, b = rows[k][0] - 1, rows[k][1] - 1
            assert geom.pair_gap_m[k] > 1e-3 * (t.radii_m[a] + t.radii_m[b])
        films = np.concatenate([f[np.isfinite(f)] for f in geom.film])
        assert films.min() >= film - TOL_M


def test_a_stated_film_keeps_the_voxels_and_is_checked(cheap):
    thick = cheap.with_film(5e-9)
    assert thick.particle_ids is cheap.particle_ids
    assert thick.particles.contact == ContactFilm(5e-9, 0.0, 1e-3)
    assert cheap.particles.contact.film_m == 0.0
    with refuses(ValueError, "film_m"):
        cheap.with_film(-1e-9)
    with refuses(ValueError, "tolerance"):
        ContactFilm(tolerance=0.5)


def test_a_packed_film_is_the_stated_film():
    """Packed with min_gap_um = 2 nm, touching pairs meet at 2 nm exactly (not 2 nm plus the
    packer's clearance)."""
    ms = packed(12.0, film_nm=2.0)
    assert ms.particles.contact == ContactFilm(2e-9, 2e-9, 1e-3)
    i, j, g = touching_pairs(ms)
    assert g.min() > 2e-9 + 1e-10
    zt = zone_table(ms, ms.voxel_m, 0.0)
    near = zt.gap < 2e-9 + 5e-10
    assert near.sum() >= len(i)
    np.testing.assert_allclose(zt.gap[near], 2e-9, rtol=0, atol=TOL_M)


def test_the_film_raises_the_contact_resistance(cheap):
    """The same particles with thicker films conduct less, by the film's d/k_m added to
    every contact (k_iso falls monotonically, and a 5 nm film at R_b = 3e-8 moves it by
    more than the solver's tolerance)."""
    from itr_fv import homogenize
    from itr_fv.discrete.problem import DiscreteProblem
    from itr_fv.materials import Materials

    mat = Materials(conductivity={"silicone": 0.18, "AlN": 170.0},
                    resistance={("AlN", "silicone"): 3e-8}, matrix="silicone")
    k = []
    for film in (0.0, 1e-9, 2e-9, 5e-9):
        res = homogenize(DiscreteProblem(cheap.with_film(film), contact="gap"), mat, tol=1e-8)
        k.append(float(np.trace(res.k_eff)) / 3)
    assert k[0] > k[1] > k[2] > k[3]
    assert (k[0] - k[3]) / k[0] > 1e-3
