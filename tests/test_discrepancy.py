"""Discrepancy workflow (issue 13) on measurements made with the full simulator at the
workflow's own box and voxel.

Every synthetic table is solved with itr_fft on RVEs the forward tables never saw (packing
seeds from 500), with one effect switched on and replicate noise at the paper's Table 3
spread (0.047 W/(m K) for Al2O3, 0.088 for AlN); the workflow gets only the table. These
tables share the workflow's box, voxel and effect models, so they test the candidate
machinery, not the workflow's fidelity: they run in the slow suite. The default run's test
of the workflow against truths it does not share (finer voxel, larger box, effects built
with itr_fv's public API) is ``tests/test_discrepancy_truth.py``.
"""

import json
import math
import re
import warnings

import numpy as np
import pytest

from itr_fv import Microstructure
from itr_fv.materials import paper_data
from itr_fv.rve import FillerSpec, generate_rve
from itr_fv.rve.spec import RVESpec
from itr_identify.cli import main
from itr_identify.discrepancy import effects as fx
from itr_identify.discrepancy.decision import find_discrepancy
from itr_identify.discrepancy.settings import DiscrepancySettings
from itr_identify.discrepancy.synthetic import synthetic_measurements
from itr_identify.discrepancy.tables import build_tables
from itr_identify.forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings
from itr_identify.inference.formulations import fractions_of

SETTINGS = DiscrepancySettings(forward=ForwardSettings(
    RVESpec(box_um=12.0, voxel_um=0.5, seed=3), replicas=2), faithful=None)
FORMS = ["Al2O3-45", "Al2O3-50", "Al2O3-55", "Al2O3-60", "AlN-50", "AlN-55", "AlN-60"]
TRUE_R = {"R_Al2O3_silicone": 2.2e-8, "R_AlN_silicone": 3.0e-8}
THICKNESS_MM = (0.5, 1.0, 1.5)


def three_candidates():
    return [fx.MatrixConductivity(), fx.ContactSpots(), fx.TesterContact()]


@pytest.fixture(scope="module")
def tables():
    return build_tables({f: fractions_of(f) for f in FORMS}, settings=SETTINGS,
                        effects=three_candidates())


def measure(effect=None, value=None, *, thickness=False, seed=7, **kw):
    return synthetic_measurements(FORMS, TRUE_R, effect=effect, value=value,
                                  settings=SETTINGS.forward,
                                  replicates=6 if thickness else 4,
                                  thickness_mm=THICKNESS_MM if thickness else None,
                                  seed=seed, **kw)


def check_named(d, effect, value):
    assert d.verdict == "named", d.statement
    assert d.winner.name == effect.name
    lo, hi = d.winner.interval
    assert lo <= value <= hi
    assert d.p_value_base < SETTINGS.significance                  # the gap was significant
    assert d.chi_square_per_dof(d.winner) <= 2.0                   # and closes


@pytest.mark.slow
def test_matrix_conductivity_is_named(tables):
    d = find_discrepancy(measure(fx.MatrixConductivity(), 0.30), settings=SETTINGS,
                         tables=tables)
    check_named(d, fx.MatrixConductivity(), 0.30)
    # the base model pushed both resistances to the bottom of their range to make up for it
    assert d.base.parameters["R_Al2O3_silicone"] == pytest.approx(1e-9)
    assert d.winner.parameters["R_Al2O3_silicone"] > 5e-9


@pytest.mark.slow
def test_contact_spots_are_named(tables):
    d = find_discrepancy(measure(fx.ContactSpots(), 3e-6), settings=SETTINGS, tables=tables)
    check_named(d, fx.ContactSpots(), 3e-6)


@pytest.mark.slow
def test_tester_contact_resistance_is_named_from_the_thickness_trend(tables):
    d = find_discrepancy(measure(fx.TesterContact(), 4e-5, thickness=True), settings=SETTINGS,
                         tables=tables)
    check_named(d, fx.TesterContact(), 4e-5)
    assert any(s.startswith("thickness:") for s in d.structure)


@pytest.mark.slow
@pytest.mark.parametrize("thickness", [False, True])
def test_noise_alone_names_nothing(tables, thickness):
    d = find_discrepancy(measure(thickness=thickness), settings=SETTINGS, tables=tables)
    assert d.verdict == "none", d.statement
    assert d.winner is None
    assert d.p_value_base >= SETTINGS.significance


@pytest.mark.slow
def test_without_thicknesses_the_tester_candidate_is_fitted_at_the_assumed_thickness(tables):
    d = find_discrepancy(measure(), settings=SETTINGS, tables=tables)
    assert not d.skipped
    assert len(d.candidates) == 3
    tester = next(m for m in d.candidates if m.name == fx.TesterContact().name)
    assert d.verdict != "named"
    assert tester.interval[0] <= tester.parameters["R_contact_m2K_per_W"] <= tester.interval[1]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="known defect, found when CI first ran the slow tier "
                   "(issue 62; fails the same on a4ee0f4): the verdict is 'unexplained' but "
                   "for another reason (candidates reach the threshold only at the end of "
                   "their resistance grid), so the wording the test asks for is missing")
def test_an_effect_outside_the_library_is_unexplained(tables):
    # a stiffer matrix *and* solid contacts: the library holds one effect at a time
    meas = measure(fx.MatrixConductivity(), 0.27, extra=[(fx.ContactSpots(), 1e-5)])
    d = find_discrepancy(meas, settings=SETTINGS, tables=tables)
    assert d.verdict == "unexplained", d.statement
    assert "not explained" in d.statement
    assert d.chi_square_per_dof(d.candidates[0]) > 2.0


def repack(ms, seed, *, crowd=1.0, **packing):
    """``ms``'s fillers packed anew at their analytic volume fractions times ``crowd``
    (packing seeds ``seed``, ``seed + 100``, ... as :meth:`ForwardModel.pack`), the
    test's box, voxel and size cut; ``packing`` goes to ``generate_rve``. Returns the
    Microstructure and the fillers' total nominal fraction."""
    psd = paper_data.psd_lognormal()
    s = SETTINGS.forward
    t = ms.particles
    phi = {str(m): float(np.sum(4 / 3 * math.pi * t.radii_m[t.material == m] ** 3))
           / float(np.prod(ms.box_m)) for m in np.unique(t.material)}
    specs = [FillerSpec(m, mu=psd[m][0], sigma=psd[m][1], volume_fraction=v * crowd)
             for m, v in phi.items()]
    for attempt in range(6):                     # dense packings may need another seed
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)   # the box cut, as in pack()
                return generate_rve(RVESpec(s.box_um, s.voxel_um, **packing,
                                            max_diameter_box_ratio=s.max_diameter_box_ratio),
                                    specs, seed + 100 * attempt,
                                    matrix=ms.names[0]), sum(phi.values())
        except RuntimeError:
            if attempt == 5:
                raise


def resin_pockets(pocket_fraction):
    """Filler agglomeration, an effect outside the library: the filler of each RVE repacked at
    ``phi / (1 - pocket_fraction)`` and the particles nearest the box centre removed (never
    past the nominal volume), leaving one particle-free silicone pocket of about
    ``pocket_fraction`` of the volume per box and the filler crowded into the rest."""
    def modify(ms, seed):
        dense, phi = repack(ms, seed + 7, crowd=1 / (1 - pocket_fraction))
        d, box = dense.particles, ms.box_m
        x = d.centers_m - box / 2
        x -= box * np.round(x / box)
        excess = float(np.sum(4 / 3 * math.pi * d.radii_m ** 3)) - phi * float(np.prod(box))
        keep, removed = np.ones(len(d), dtype=bool), 0.0
        for i in np.argsort(np.einsum("ij,ij->i", x, x)):
            v = 4 / 3 * math.pi * d.radii_m[i] ** 3
            if removed + v <= excess:
                keep[i], removed = False, removed + v
        return Microstructure.from_spheres(d.centers_m[keep], d.radii_m[keep],
                                           list(d.material[keep]), box, ms.shape,
                                           matrix=ms.names[0])
    return modify


def silicone_films(gap_um):
    """A silicone film of ``gap_um`` between all touching particles (a bound layer that keeps
    them apart; the library's contact spots only add conduction): each RVE repacked at its
    own filler fractions with ``min_gap_um``."""
    return lambda ms, seed: repack(ms, seed, min_gap_um=gap_um)[0]


@pytest.mark.slow
def test_resin_pockets_are_absorbed_by_the_resistances_and_not_named(tables):
    # one physical effect outside the library: 6 vol% particle-free pockets, filler crowded
    # into the rest (up to 64 vol% locally). It leaves no significant residual at these
    # fractions: the AlN resistance absorbs it (biased high), and nothing is named.
    modify = resin_pockets(0.06)
    base = ForwardModel("Al2O3-60", fractions_of("Al2O3-60"), PARAMETRISATIONS["gap"],
                        SETTINGS.forward.with_(seed=500)).pack(0)
    ms = modify(base, 500)
    assert ms.volume_fractions()["Al2O3"] == pytest.approx(0.60, abs=0.005)
    n = ms.shape[0]
    x = (np.indices(ms.shape) + 0.5 - n / 2) / n                # box lengths from the centre
    pocket = (x ** 2).sum(axis=0) < (3 * 0.06 / (4 * math.pi)) ** (2 / 3)
    assert (ms.material_ids[pocket] == 0).mean() > 0.7         # mostly silicone there
    assert (ms.material_ids[~pocket] > 0).mean() > 0.62        # crowded elsewhere
    d = find_discrepancy(measure(modify=modify), settings=SETTINGS, tables=tables)
    assert d.verdict == "none", d.statement
    assert d.p_value_base >= SETTINGS.significance
    assert d.base.parameters["R_AlN_silicone"] > 1.5 * TRUE_R["R_AlN_silicone"]


@pytest.mark.slow
def test_silicone_films_between_particles_are_absorbed_and_not_named(tables):
    # 50 nm of silicone between every pair of touching particles lowers k by 13-21 %,
    # and the resistances take it all (several times their true values): nothing named
    meas = measure(modify=silicone_films(0.05))
    plain = measure()
    assert all(meas.mean(f) < 0.9 * plain.mean(f) for f in FORMS)
    d = find_discrepancy(meas, settings=SETTINGS, tables=tables)
    assert d.verdict == "none", d.statement
    for name, value in TRUE_R.items():
        assert d.base.parameters[name] > 3 * value


def test_discrepancy_command_end_to_end(tmp_path, capsys):
    meas = synthetic_measurements(FORMS[:4], TRUE_R, effect=fx.MatrixConductivity(),
                                  value=0.30, settings=SETTINGS.forward, seed=3)
    csv = tmp_path / "m.csv"
    # with each sample's density at the nominal composition (Archimedes, 0.3 % noise)
    rng = np.random.default_rng(5)
    rho = {f: next(iter(fractions_of(f).values())) * 3.95
           + (1 - next(iter(fractions_of(f).values()))) * 0.97 for f in meas.values}
    csv.write_text("formulation,replicate,k_W_per_mK,density_g_per_cm3\n" + "".join(
        f"{f},{i + 1},{k:.4f},{rho[f] * (1 + 0.003 * rng.standard_normal()):.4f}\n"
        for f, v in meas.values.items() for i, k in enumerate(v)))
    out = tmp_path / "out"
    flags = ["--effects", "matrix", "--box-um", "12", "--voxel-um", "0.5", "--replicas", "2",
             "--seed", "3", "--fidelity", "quick", "--no-progress", "--store",
             str(tmp_path / "shared")]
    assert main(["discrepancy", str(csv), "--out", str(out), *flags]) == 0
    data = json.loads((out / "discrepancy.json").read_text())
    # the data pull the matrix to its truth, 0.30; the paper's system states 0.18 with a
    # relative sd of 10 %, and 0.30 is five of those away: not "the input is off" but "the
    # model lacks something" (issue 49)
    assert data["verdict"] == "unexplained"
    best = data["candidates"][0]
    assert best["name"] == "matrix conductivity off nominal"
    lo, hi = best["interval_90"]
    assert lo <= 0.30 <= hi and lo > 0.18 * math.exp(3 * 0.10)
    assert best["log_bayes_factor"] > data["threshold"]["log_bayes_factor"]
    assert "the model lacks something" in data["statement"]
    md = (out / "discrepancy.md").read_text()
    assert "matrix conductivity off nominal" in md and "Al2O3-60" in md
    # the densities in the likelihood and the report, the phase densities stated
    assert len(data["auxiliary"]) == 4 and data["densities_g_per_cm3"]["Al2O3"] == 3.95
    assert "## Auxiliary observations before and after" in md
    assert "phase densities (g/cm^3" in md and "Al2O3 3.95" in md
    assert (out / "discrepancy.png").stat().st_size > 1000
    files = {f["path"] for f in json.loads((out / "manifest.json").read_text())["files"]}
    assert files >= {"discrepancy.md", "discrepancy.json", "discrepancy.png"}
    assert "discrepancy: unexplained" in capsys.readouterr().out
    # another table, another output folder, the same store: no full solve again
    other = tmp_path / "other.csv"
    other.write_text("formulation,replicate,k_W_per_mK\n" + "".join(
        f"{f},{i + 1},{1.02 * k:.4f}\n" for f, v in meas.values.items()
        for i, k in enumerate(v)))
    assert main(["discrepancy", str(other), "--out", str(tmp_path / "out2"), *flags]) == 0
    assert re.search(r"engine: 0 full solves in this process, \d+ requests from the store of "
                     r"an earlier run, ", capsys.readouterr().out)
    assert not (tmp_path / "out2" / "solves").exists()


@pytest.mark.parametrize("args, expected", [
    (["discrepancy", "missing.csv"], "MEASUREMENTS"),
    (["discrepancy", "--effects", "shape"], "--effects: unknown effect 'shape'"),
    (["discrepancy", "--replicas", "1"], "--replicas"),
])
def test_discrepancy_bad_invocations_fail_in_one_line(tmp_path, capsys, args, expected):
    assert main(args + ["--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("itr: error: ") and err.count("\n") == 1
    assert expected in err


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="known defect, found when CI first ran the slow tier "
                   "(issue 62): the noise-only table names 'filler fraction below nominal' "
                   "(log Bayes factor 2.5 against the threshold 2.0) instead of none")
def test_the_whole_library_names_three_effects():
    """The seven candidates of issue 13 at once: matrix conductivity, contact spots and the tester's
    contact resistance are each named; filler conductivity, porosity and the filler
    fraction are absorbed by the resistances at these fractions (no discrepancy)."""
    tables = build_tables({f: fractions_of(f) for f in FORMS}, settings=SETTINGS,
                          effects=fx.by_key(["matrix", "filler", "porosity", "fraction",
                                             "spots", "tester", "batch"]))
    for effect, value, thickness in ((fx.MatrixConductivity(), 0.30, False),
                                     (fx.ContactSpots(), 3e-6, False),
                                     (fx.TesterContact(), 4e-5, True)):
        d = find_discrepancy(measure(effect, value, thickness=thickness), settings=SETTINGS,
                             tables=tables)
        check_named(d, effect, value)
    d = find_discrepancy(measure(thickness=True), settings=SETTINGS, tables=tables)
    assert d.verdict == "none", d.statement
    assert np.isfinite(d.base.chi_square)


def test_a_likelihood_ratio_interval_holds_its_maximum_also_at_an_edge():
    from itr_identify.discrepancy.fit import LR_DROP_90, profile_interval

    axis = np.linspace(0.8, 1.0, 41)
    # a parabola peaking at 0.95 with curvature giving a half-width of 0.03 at the cut
    prof = -LR_DROP_90 * ((axis - 0.95) / 0.03) ** 2
    lo, hi = profile_interval(prof, axis)
    assert lo == pytest.approx(0.92, abs=2e-4) and hi == pytest.approx(0.98, abs=2e-4)
    # a maximum on the end of the axis (the filler factor at nominal 1.0): inside
    prof = -LR_DROP_90 * ((axis - 1.0) / 0.05) ** 2
    lo, hi = profile_interval(prof, axis)
    assert hi == 1.0 and lo == pytest.approx(0.95, abs=2e-4)


@pytest.mark.slow
def test_every_reported_interval_contains_its_best_value(tables):
    for value, kw in ((None, {}), (0.30, {"effect": fx.MatrixConductivity()})):
        d = find_discrepancy(measure(value=value, **kw), settings=SETTINGS, tables=tables)
        for m in d.candidates:
            if m.interval is None:
                continue
            (param,) = set(m.parameters) - {"R_Al2O3_silicone", "R_AlN_silicone"}
            lo, hi = m.interval
            assert lo <= m.parameters[param] <= hi, (m.name, m.parameters, m.interval)


def test_implausible_resistances_and_grid_ends_are_reported():
    from itr_identify.discrepancy.decision import resistance_remarks
    from itr_identify.discrepancy.fit import ModelFit

    def fit(**r):
        return ModelFit("base", dict(r), None, np.zeros(1), np.ones(1), 0.0, 0.0, 0.0, 2)

    # a jump like the tester's 46 % effect: 13-20x the generating values
    remarks = resistance_remarks(fit(R_Al2O3_silicone=2.9e-7, R_AlN_silicone=6.0e-7),
                                 SETTINGS)
    assert remarks == [
        "R_Al2O3_silicone = 2.9e-07 m^2 K/W (outside the physical range 1e-09 - 1e-07 "
        "m^2 K/W; 13x the paper's 2.2e-08)",
        "R_AlN_silicone = 6e-07 m^2 K/W (outside the physical range 1e-09 - 1e-07 m^2 K/W; "
        "20x the paper's 3e-08)"]
    # the grid's lower end (the base model at its most conductive)
    (edge,) = resistance_remarks(fit(R_Al2O3_silicone=1e-9, R_AlN_silicone=2e-8), SETTINGS)
    assert edge.startswith("R_Al2O3_silicone = 1e-09 m^2 K/W (at the lower end of the "
                           "solved grid; 0.045x the paper's 2.2e-08)")
    # plausible values: nothing to say
    assert resistance_remarks(fit(R_Al2O3_silicone=2e-8, R_AlN_silicone=3e-8), SETTINGS) == []
