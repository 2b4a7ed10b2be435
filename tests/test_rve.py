"""Dense periodic RVE generator: fractions, no overlap, sizes, reproducibility, bad input."""

import math
import warnings

import numpy as np
import pytest
from refusals import refuses
from scipy.spatial import cKDTree

from itr_fv.rve import FillerSpec, RVESpec, generate_rve, generate_rve_with_report, packing_limit
from itr_fv.rve.packing import check_overlaps, pack_spheres, pairs_within_gap

# small distributions so that small boxes are representative (default runs stay fast)
SMALL = dict(mu=0.0, sigma=0.3)        # D ~ 1 um
SMALL_WIDE = dict(mu=-0.3, sigma=0.45)  # wider, tail still fits a 12 um box


def _overlaps_kdtree(c_um, r_um, box_um, min_gap=0.0):
    """Independent exact check with scipy's periodic KD-tree (all pairs within 2 r_max)."""
    tree = cKDTree(np.mod(c_um, box_um), boxsize=box_um)
    pairs = tree.query_pairs(2 * r_um.max() + min_gap, output_type="ndarray")
    d = c_um[pairs[:, 0]] - c_um[pairs[:, 1]]
    d -= box_um * np.round(d / box_um)
    gap = np.linalg.norm(d, axis=1) - r_um[pairs[:, 0]] - r_um[pairs[:, 1]]
    return int(np.count_nonzero(gap < min_gap)), gap


def _table_um(ms):
    return ms.particles.centers_m * 1e6, ms.particles.radii_m * 1e6, ms.box_m[0] * 1e6


def test_single_filler_dense_no_overlap():
    ms, rep = generate_rve_with_report(RVESpec(10.0, 0.125, max_diameter_box_ratio=1 / 3),
                                       FillerSpec("Al2O3", volume_fraction=0.62, **SMALL), 3)
    c, r, L = _table_um(ms)
    n_bad, gap = _overlaps_kdtree(c, r, L)
    assert n_bad == 0 and rep.n_overlaps == 0
    assert rep.smallest_gap_um == pytest.approx(gap.min(), abs=1e-12)
    f = rep.fillers[0]
    assert f.analytic_fraction == pytest.approx(0.62, abs=1e-12)
    assert 4 / 3 * math.pi * np.sum(r ** 3) / L ** 3 == pytest.approx(0.62, abs=1e-12)
    assert abs(f.voxel_fraction - 0.62) < 0.01
    assert ms.volume_fractions()["Al2O3"] == pytest.approx(f.voxel_fraction)
    assert ms.names == ("silicone", "Al2O3") and ms.shape == (80, 80, 80)
    assert ms.n_particles == len(ms.particles) == f.n_particles
    # dense packing: many near contacts, touching voxels of different particles
    assert rep.coordination_number > 2.0
    assert rep.voxel_face_contacts > 0
    assert abs(f.mu_fit - SMALL["mu"]) < 0.05 and abs(f.sigma_fit - SMALL["sigma"]) < 0.05
    assert 0.0 <= f.ks_pvalue <= 1.0 and f.ks_statistic < 0.05
    assert rep.seconds["total"] > 0 and "pack" in rep.seconds


def test_table1_al2o3_in_30um_box():
    ms, rep = generate_rve_with_report(RVESpec(30.0, 0.3125, max_diameter_box_ratio=1 / 3),
                                       [FillerSpec.from_table1("Al2O3", 0.60)], 1)
    f = rep.fillers[0]
    assert rep.n_overlaps == 0
    c, r, L = _table_um(ms)
    assert _overlaps_kdtree(c, r, L)[0] == 0
    assert abs(f.analytic_fraction - 0.60) < 1e-9 and abs(f.voxel_fraction - 0.60) < 0.01
    assert abs(f.mu_fit - 1.02) < 0.05 and abs(f.sigma_fit - 0.35) < 0.05
    assert 2 * r.max() <= 10.0 + 1e-9 and 2 * r.min() >= 2 * 0.3125 - 1e-9
    assert not rep.warnings  # the 30 um box does not cut the Al2O3 tail noticeably
    assert f.cut_volume_high < 0.01
    assert rep.phi_rcp_estimate == pytest.approx(0.68, abs=0.005)


def test_hybrid_fractions_per_filler():
    specs = [FillerSpec("Al2O3", volume_fraction=0.32, **SMALL),
             FillerSpec("AlN", volume_fraction=0.32, **SMALL_WIDE)]
    ms, rep = generate_rve_with_report(RVESpec(12.0, 0.125, max_diameter_box_ratio=1 / 3), specs, 5)
    assert not rep.warnings
    c, r, L = _table_um(ms)
    assert _overlaps_kdtree(c, r, L)[0] == 0
    vf = ms.volume_fractions()
    for f, s in zip(rep.fillers, specs):
        assert f.material == s.material
        assert f.analytic_fraction == pytest.approx(0.32, abs=1e-12)
        assert abs(vf[s.material] - 0.32) < 0.01
        assert abs(f.voxel_fraction - vf[s.material]) < 1e-12
    mats = ms.particles.material
    assert set(mats) == {"Al2O3", "AlN"}
    # material ids follow the particle table
    pid = ms.particle_ids
    mid = ms.material_ids
    some = np.flatnonzero(pid.ravel())[:1000]
    names = np.array(ms.names)[mid.ravel()[some]]
    assert np.all(names == mats[pid.ravel()[some] - 1])


def test_same_seed_same_table_and_different_seeds_differ():
    spec = FillerSpec("Al2O3", volume_fraction=0.55, **SMALL)
    a = generate_rve(RVESpec(8.0, 0.125, max_diameter_box_ratio=1 / 3), spec, 11)
    b = generate_rve(RVESpec(8.0, 0.125, max_diameter_box_ratio=1 / 3), spec, 11)
    c = generate_rve(RVESpec(8.0, 0.125, max_diameter_box_ratio=1 / 3), spec, 12)
    assert a.particles.centers_m.tobytes() == b.particles.centers_m.tobytes()
    assert a.particles.radii_m.tobytes() == b.particles.radii_m.tobytes()
    assert np.array_equal(a.particle_ids, b.particle_ids)
    assert (a.particles.radii_m.shape != c.particles.radii_m.shape
            or not np.array_equal(a.particles.radii_m, c.particles.radii_m))
    assert not np.array_equal(a.particles.centers_m[:10], c.particles.centers_m[:10])


def test_min_gap_respected():
    gap = 0.05
    ms, rep = generate_rve_with_report(
        RVESpec(8.0, 0.125, min_gap_um=gap, max_diameter_box_ratio=1 / 3),
        FillerSpec("Al2O3", volume_fraction=0.5, **SMALL), 2)
    c, r, L = _table_um(ms)
    n_bad, g = _overlaps_kdtree(c, r, L, min_gap=gap)
    assert n_bad == 0 and g.min() >= gap
    assert rep.smallest_gap_um >= gap
    # the reported gap distribution is the one of the table (independent cKDTree count)
    assert rep.gap_counts["<0.02 um"] == 0
    assert rep.gap_counts["<0.1 um"] == int(np.count_nonzero(g < 0.1))
    assert rep.gap_counts["<0.5 um"] == int(np.count_nonzero(g < 0.5))


def test_gap_distribution_without_a_film_shows_the_packers_nanometre_gaps():
    ms, rep = generate_rve_with_report(RVESpec(8.0, 0.125, max_diameter_box_ratio=1 / 3),
                                       FillerSpec("Al2O3", volume_fraction=0.5, **SMALL), 2)
    c, r, L = _table_um(ms)
    _, g = _overlaps_kdtree(c, r, L)
    counts = list(rep.gap_counts.values())
    assert counts == sorted(counts)  # cumulative
    assert rep.gap_counts["<0.002 um"] == int(np.count_nonzero(g < 0.002)) > 0
    assert "pairs with a gap <0.002 um" in rep.summary()


def test_alN_box_cut_warns_and_reports_truncation():
    with pytest.warns(UserWarning, match="removes"):
        ms, rep = generate_rve_with_report(RVESpec(18.0, 0.5, max_diameter_box_ratio=1 / 3),
                                           FillerSpec.from_table1("AlN", 0.30), 0)
    f = rep.fillers[0]
    assert f.d_hi_um == pytest.approx(6.0) and f.d_max_drawn_um <= 6.0 + 1e-9
    assert f.cut_volume_high > 0.5 and rep.warnings
    assert f.d_lo_um >= 1.0 - 1e-12  # two voxels


def test_packing_kernel_and_pair_search_against_brute_force():
    rng = np.random.default_rng(0)
    L = 10.0
    r = rng.uniform(0.3, 1.2, 120)
    c = rng.uniform(0, L, (120, 3))
    i, j, g = pairs_within_gap(c, r, L, 0.2)
    d = c[:, None, :] - c[None, :, :]
    d -= L * np.round(d / L)
    gap = np.linalg.norm(d, axis=2) - r[:, None] - r[None, :]
    iu = np.triu_indices(120, 1)
    want = {(a, b) for a, b in zip(*iu) if gap[a, b] < 0.2}
    assert {(a, b) for a, b in zip(i, j)} == want
    np.testing.assert_allclose(g, gap[i, j], rtol=0, atol=1e-12)
    res = pack_spheres(r * 0.8, L, rng)
    assert res.converged and check_overlaps(res.centers, r * 0.8, L)[0] == 0


def test_packing_limit_estimate():
    phi, s = packing_limit([FillerSpec.from_table1("Al2O3", 0.3)])
    assert s == pytest.approx(0.35) and phi == pytest.approx(0.68, abs=0.005)
    phi, s = packing_limit([FillerSpec.from_table1("AlN", 0.3)])
    assert phi == pytest.approx(0.72, abs=0.01)


# ------------------------------------------------------------------ bad input
def test_fillerspec_validation():
    with pytest.raises(ValueError, match="sigma"):
        FillerSpec("Al2O3", 1.0, 0.0, 0.5)
    with pytest.raises(ValueError, match="sigma"):
        FillerSpec("Al2O3", 1.0, -0.2, 0.5)
    with pytest.raises(ValueError, match="sigma"):
        FillerSpec("Al2O3", 1.0, float("inf"), 0.5)
    with pytest.raises(ValueError, match="mu"):
        FillerSpec("Al2O3", float("nan"), 0.3, 0.5)
    for f in (0.0, 1.0, -0.1, 1.5):
        with pytest.raises(ValueError, match="volume_fraction"):
            FillerSpec("Al2O3", 1.0, 0.3, f)
    with refuses(ValueError, "material"):
        FillerSpec("", 1.0, 0.3, 0.5)
    with refuses(ValueError, "material"):
        FillerSpec(None, 1.0, 0.3, 0.5)
    with pytest.raises(ValueError, match="d_min_um"):
        FillerSpec("Al2O3", 1.0, 0.3, 0.5, d_min_um=0.0)
    with pytest.raises(ValueError, match="d_max_um"):
        FillerSpec("Al2O3", 1.0, 0.3, 0.5, d_max_um=-3.0)
    with refuses(ValueError, "material"):
        FillerSpec.from_table1("BN", 0.3)


def test_generate_rve_bad_input():
    ok = FillerSpec("Al2O3", volume_fraction=0.3, **SMALL)
    with refuses(ValueError, "box_um"):
        RVESpec(0.0, 0.1)
    with refuses(ValueError, "box_um"):
        RVESpec(-8.0, 0.1)
    with refuses(ValueError, "voxel_um"):
        RVESpec(8.0, 0.0)
    with refuses(ValueError, "box_um/voxel_um"):
        RVESpec(8.0, 0.3)  # 8 / 0.3 not an integer
    # voxel larger than the particles that matter (D ~ 1 um, 2-voxel minimum = 1 um)
    with refuses(ValueError, "voxel_um"):
        generate_rve(RVESpec(8.0, 0.5, max_diameter_box_ratio=1 / 3), ok, 0)
    with refuses(ValueError, "voxel_um"):
        generate_rve(RVESpec(40.0, 2.0, max_diameter_box_ratio=1 / 3),
                     FillerSpec.from_table1("Al2O3", 0.5), 0)
    with refuses(ValueError, "min_gap_um"):
        RVESpec(8.0, 0.125, min_gap_um=-0.1)
    with refuses(ValueError, "seed"):
        generate_rve(RVESpec(8.0, 0.125), ok, -1)
    with refuses(ValueError, "sampling"):
        RVESpec(8.0, 0.125, sampling="sobol")
    with refuses(ValueError, "max_sweeps"):
        RVESpec(8.0, 0.125, max_sweeps=0)
    with refuses(ValueError, "spec"):
        generate_rve(ok, RVESpec(8.0, 0.125), 0)
    with refuses(ValueError, "fillers"):
        generate_rve(RVESpec(8.0, 0.125), [], 0)
    # unknown material
    with refuses(ValueError, "fillers"):
        generate_rve(RVESpec(8.0, 0.125), FillerSpec("BN", volume_fraction=0.3, **SMALL), 0,
                     materials={"silicone", "Al2O3"})
    with refuses(ValueError, "matrix"):
        generate_rve(RVESpec(8.0, 0.125), ok, 0, matrix="epoxy", materials={"silicone", "Al2O3"})
    with refuses(ValueError, "fillers"):
        generate_rve(RVESpec(8.0, 0.125), FillerSpec("silicone", volume_fraction=0.3, **SMALL), 0)
    # box too small for an explicit largest particle
    with refuses(ValueError, "box_um"):
        generate_rve(RVESpec(8.0, 0.125, max_diameter_box_ratio=1 / 3),
                     FillerSpec("Al2O3", volume_fraction=0.3, d_max_um=4.0, **SMALL), 0)


def test_beyond_jamming_limit_states_estimate():
    with pytest.raises(ValueError, match=r"fillers: .*0\.69 exceeds .*limit 0\.6[78]"):
        generate_rve(RVESpec(40.0, 0.3125, max_diameter_box_ratio=1 / 3),
                     FillerSpec.from_table1("Al2O3", 0.69), 0)
    with refuses(ValueError, "fillers"), pytest.warns(UserWarning, match="AlN"):
        generate_rve(RVESpec(40.0, 0.3125, max_diameter_box_ratio=1 / 3),
                     [FillerSpec.from_table1("Al2O3", 0.40), FillerSpec.from_table1("AlN", 0.35)],
                     0)
    with refuses(ValueError, "fillers"):
        generate_rve(RVESpec(8.0, 0.125, max_diameter_box_ratio=1 / 3),
                     [FillerSpec("A", volume_fraction=0.6, **SMALL),
                      FillerSpec("B", volume_fraction=0.5, **SMALL)], 0)


def test_render_particles(tmp_path):
    from itr_fv.output.particle_render import render_particles
    ms = generate_rve(RVESpec(12.0, 0.125, max_diameter_box_ratio=1 / 3),
                      [FillerSpec("Al2O3", volume_fraction=0.3, **SMALL),
                       FillerSpec("AlN", volume_fraction=0.2, **SMALL_WIDE)], 1)
    out = render_particles(ms, str(tmp_path / "fig4.png"), window_size=(300, 300),
                           resolution=8)
    data = open(out, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 3000


# ------------------------------------------------------------------ acceptance (40 um box, ~12 s)
ACCEPTANCE = [
    ("Al2O3-55", [("Al2O3", 0.55)]),
    ("Al2O3-60", [("Al2O3", 0.60)]),
    ("Al2O3-65", [("Al2O3", 0.65)]),
    ("AlN-55", [("AlN", 0.55)]),
    ("AlN-62", [("AlN", 0.62)]),
    ("Al2O3-32.5-AlN-32.5", [("Al2O3", 0.325), ("AlN", 0.325)]),
]


@pytest.mark.parametrize("name, fill", ACCEPTANCE, ids=[a[0] for a in ACCEPTANCE])
def test_acceptance_40um(name, fill):
    specs = [FillerSpec.from_table1(m, f) for m, f in fill]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # AlN box cut, reported
        ms, rep = generate_rve_with_report(RVESpec(40.0, 0.3125, max_diameter_box_ratio=1 / 3),
                                           specs, 1)
    c, r, L = _table_um(ms)
    assert _overlaps_kdtree(c, r, L)[0] == 0 and rep.n_overlaps == 0
    for f in rep.fillers:
        assert abs(f.analytic_fraction - f.target_fraction) < 0.005
        assert abs(f.voxel_fraction - f.target_fraction) < 0.01
        assert abs(f.mu_fit - f.mu_target) < 0.05
        assert abs(f.sigma_fit - f.sigma_target) < 0.05
    again = generate_rve(RVESpec(40.0, 0.3125, max_diameter_box_ratio=1 / 3), specs, 1) \
        if name == "Al2O3-65" else None
    if again is not None:
        assert again.particles.centers_m.tobytes() == ms.particles.centers_m.tobytes()
