"""The four steepening candidates of the discrepancy workflow (film thinning, agglomeration,
size basis, interphase shell): each is the base RVE at its nominal value, repacks with the
base replica's seed where it changes the packing, and changes the physics it says."""

import math

import numpy as np
import pytest
from refusals import refuses

from itr_fv.materials.paper_data import TABLE1
from itr_fv.rve import FillerSpec
from itr_fv.rve.spec import RVESpec
from itr_identify.discrepancy.effects import by_key, default_effects
from itr_identify.discrepancy.settings import DiscrepancySettings
from itr_identify.discrepancy.steepening import (
    Agglomeration,
    FilmThinning,
    InterphaseShell,
    Repacker,
    SizeBasis,
    filler_fractions,
)
from itr_identify.discrepancy.tables import build_tables
from itr_identify.forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings, full_solve

SMALL = ForwardSettings(RVESpec(box_um=12.0, voxel_um=0.5, seed=3), replicas=2)
R = {"R_Al2O3_silicone": 2e-8}
FOUR = ["film", "agglomeration", "basis", "shell"]


def packed(filler, phi, settings=SMALL):
    m = ForwardModel(f"{filler}-{phi}", {filler: phi}, PARAMETRISATIONS["gap"], settings)
    return m, m.pack(0), Repacker.of(m, 0)


@pytest.fixture(scope="module")
def al55():
    return packed("Al2O3", 0.55)


@pytest.fixture(scope="module")
def al60():
    return packed("Al2O3", 0.60)


def smallest_gap_um(ms):
    t = ms.particles
    c, r, box = t.centers_m * 1e6, t.radii_m * 1e6, ms.box_m * 1e6
    d = c[:, None, :] - c[None, :, :]
    d -= box * np.round(d / box)
    gap = np.sqrt((d ** 2).sum(-1)) - r[:, None] - r[None, :]
    return float(gap[~np.eye(len(r), dtype=bool)].min())


def test_the_library_lists_the_four_after_the_seven():
    keys = [e.key for e in default_effects()]
    assert keys[-4:] == FOUR and len(keys) == 11
    four = by_key(FOUR)
    assert [type(e) for e in four] == [FilmThinning, Agglomeration, SizeBasis, InterphaseShell]
    assert [e.kind for e in four] == ["geometry", "geometry", "geometry", "material"]
    for e in four:
        assert e.nominal in e.values and len(e.values) >= 3 and e.signature and e.separate_by
        lo, hi = e.physical_range or (e.values[0], e.values[-1])
        assert e.values[0] <= lo < hi <= e.values[-1]
        f, voids = e.composition(0.6, e.values[-1])           # nominal composition
        assert f == pytest.approx(0.6) and voids == 0


def test_each_effect_at_nominal_is_the_base_rve_and_a_repack_is_the_same_draw(al55):
    m, ms, pack = al55
    mat = m.materials(R)
    again = pack()                               # the same seed, no change: the same RVE
    assert np.array_equal(again.material_ids, ms.material_ids)
    for e in by_key(FOUR):
        out = e.rebuild(pack, ms, e.nominal, seed=3)
        assert np.array_equal(out.material_ids, ms.material_ids)
        assert e.materials_in(out, mat, e.nominal).conductivity == mat.conductivity


def test_the_film_thins_as_the_fraction_rises(al55, al60):
    film = FilmThinning()
    d = film.film_um([0.5, 0.55, 0.6, 0.62, 0.65], 10.0)
    assert d[1] == pytest.approx(0.010)
    assert d[0] > d[1] > d[2] > d[3] == d[4] == 0      # squeezed out at the packing limit
    gaps = []
    for _, ms, pack in (al55, al60):
        rve = film.rebuild(pack, ms, 10.0, seed=3)
        phi = sum(filler_fractions(ms).values())
        g = smallest_gap_um(rve)
        assert g >= film.film_um(phi, 10.0) * (1 - 1e-6) > smallest_gap_um(ms)
        gaps.append(g)
    assert gaps[1] < gaps[0]
    assert film.size_equivalent(10.0, 2.0) == pytest.approx(5.0)   # a length


def test_agglomeration_keeps_the_fraction_and_empties_resin_pockets(al55):
    _, ms, pack = al55
    agg = Agglomeration()
    rve = agg.rebuild(pack, ms, 0.85, seed=3)
    phi = filler_fractions(ms)["Al2O3"]
    # the removal stops at the particle closest to the nominal fraction: within 1.5 vol%
    assert filler_fractions(rve)["Al2O3"] == pytest.approx(phi, abs=0.015)
    vox = 1 - rve.volume_fractions()["silicone"]
    assert vox == pytest.approx(1 - ms.volume_fractions()["silicone"], abs=0.015)
    # non-uniform: the voxels within 2 um of the pocket centres hold (almost) no filler
    h = rve.voxel_m
    x = (np.indices(rve.shape).reshape(3, -1).T + 0.5) * h
    near = np.zeros(len(x), dtype=bool)
    for c in agg.pocket_centres_m(rve.box_m):
        d = x - c
        d -= rve.box_m * np.round(d / rve.box_m)
        near |= np.sqrt((d ** 2).sum(1)) < 2e-6
    pocket = np.count_nonzero(rve.material_ids.ravel()[near]) / near.sum()
    base = np.count_nonzero(ms.material_ids.ravel()[near]) / near.sum()
    assert pocket < 0.1 < 0.4 < base
    assert agg.crowded_fraction(0.55, 0.85) == pytest.approx(0.62)      # capped
    assert agg.rebuild(pack, ms, 1.0, seed=3) is ms
    assert agg.size_equivalent(0.9, 2.0) == 0.9                       # scale-free


def test_the_volume_basis_shrinks_the_diameters_by_hatch_choate(al55):
    _, ms, pack = al55
    basis = SizeBasis()
    sigma = TABLE1["Al2O3"].sigma
    # theta = 1 is Table 1 read as volume-weighted (ForwardSettings.psd_basis="volume")
    spec = pack.fillers(median_scale={"Al2O3": basis.median_scale("Al2O3", 1.0)})[0]
    vol = FillerSpec.from_table1("Al2O3", 0.55, basis="volume")
    assert spec.psd.mu == pytest.approx(vol.psd.mu, abs=1e-12)
    # the number median falls by exp(3 sigma^2 theta): the particles get SMALLER
    rve = basis.rebuild(pack, ms, 0.9, seed=3)
    ratio = np.median(ms.particles.radii_m) / np.median(rve.particles.radii_m)
    assert ratio == pytest.approx(math.exp(3 * sigma ** 2 * 0.9), rel=0.1)
    assert filler_fractions(rve)["Al2O3"] == pytest.approx(0.55, abs=1e-9)


def test_a_conductive_shell_raises_k_more_at_the_higher_fraction(al55, al60):
    shell = InterphaseShell()
    gains, shares = [], []
    for m, ms, _ in (al55, al60):
        mat = m.materials(R)
        k0 = full_solve(ms, mat, 1e-8).mean()
        nominal = shell.materials_in(ms, mat, 1.0)
        if ms is al55[1]:                 # the shell at the matrix's conductivity is the base
            assert full_solve(ms, nominal, 1e-8).mean() == pytest.approx(k0, rel=1e-12)
        gains.append(full_solve(ms, shell.materials_in(ms, mat, 4.0), 1e-8).mean() / k0)
        shares.append(shell.shell_share(ms))
    assert 0 < shares[0] < shares[1] < 1
    assert 1 < gains[0] < gains[1]
    assert shell.size_equivalent(3.0, 2.0) == pytest.approx(2.0)     # excess (f - 1) / scale


def test_values_outside_the_domain_or_beyond_the_voxel_are_refused(al55):
    _, ms, pack = al55
    for key, value in (("film", -1.0), ("agglomeration", 1.1), ("agglomeration", 0.0),
                       ("basis", 1.5)):
        with pytest.raises(ValueError, match=f"of '{key}' lies outside"):
            by_key([key])[0].rebuild(pack, ms, value, seed=3)
    with refuses(ValueError, "value"):
        InterphaseShell().materials_in(ms, al55[0].materials(R), 0.0)
    # AlN read as volume-weighted: its fine particles are below two 0.5 um voxels
    _, aln, aln_pack = packed("AlN", 0.55)
    with pytest.raises(ValueError, match=r"^basis: .*\(voxel_um: "):  # the packer's reason
        SizeBasis().rebuild(aln_pack, aln, 0.9, seed=3)


@pytest.mark.parametrize("filler, fractions", [("Al2O3", (0.55, 0.58, 0.60, 0.65)),
                                               ("AlN", (0.55, 0.58, 0.60, 0.62))])
def test_every_grid_value_packs_for_table3_in_the_workflows_rve(filler, fractions):
    """Table 3's single-filler formulations, the workflow's RVE (12 um at 0.25 um) and
    packing seed: every value of the three repacking grids packs (ValueError otherwise)."""
    settings = DiscrepancySettings().forward
    for phi in fractions:
        m, ms, pack = packed(filler, phi, settings)
        for e in by_key(["film", "agglomeration", "basis"]):
            for v in e.values:
                rve = e.rebuild(pack, ms, v, seed=settings.seed)
                assert filler_fractions(rve)[filler] == pytest.approx(phi, abs=0.02)


def test_the_tables_solve_each_value_on_its_own_rve():
    settings = DiscrepancySettings(forward=SMALL, faithful=None,
                                   r_grid_m2K_per_W=(1e-9, 1e-8, 1e-7, 1e-6))
    film = FilmThinning(values=(0.0, 10.0, 20.0))
    t = build_tables({"Al2O3-55": {"Al2O3": 0.55}}, settings=settings, effects=[film])
    col = t.effect[film.name]["Al2O3-55"]                # (nR, ntheta)
    assert col.shape == (4, 3)
    assert np.array_equal(col[:, 0], t.base["Al2O3-55"])
    assert np.all(col[:, 2] < col[:, 1]) and np.all(col[:, 1] < col[:, 0])  # films insulate
