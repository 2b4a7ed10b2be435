"""Identification (issue 12): screening, calibration with synthetic recovery, validation.

Small RVEs (12 um box, 0.5 um voxels: 24^3) keep the suite fast; the full study is
``validation/identification_study.py``.
"""

import math

import numpy as np
import pytest
from refusals import refuses

from itr_fv.rve.spec import RVESpec
from itr_identify.forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings, full_solve
from itr_identify.inference.calibrate import calibrate, stages_of
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements, read_measurements
from itr_identify.inference.pipeline import identify
from itr_identify.inference.screen import paper_grid, screen
from itr_identify.inference.validate import leave_one_out, validate

SMALL = ForwardSettings(RVESpec(box_um=12.0, voxel_um=0.5, seed=3), replicas=3)
TRUE_R = 3.0e-8
# 50-60 vol%: they pack at once in a 12 um box (65 % needs redraws there)
FORMS = ("Al2O3-50", "Al2O3-55", "Al2O3-60")


@pytest.fixture(scope="module")
def table3():
    return read_measurements()


@pytest.fixture(scope="module")
def models():
    out = {}
    for f in FORMS:
        out[f] = ForwardModel(f, fractions_of(f), PARAMETRISATIONS["gap"], SMALL).build()
    return out


def true_k(seed):
    """k_iso of each formulation at TRUE_R: the mean of full solves of three RVEs that the
    forward models never saw (packing seeds from 40 + 7 seed), a stand-in for a sample much
    larger than one RVE."""
    out = {}
    for f in FORMS:
        m = ForwardModel(f, fractions_of(f), PARAMETRISATIONS["gap"],
                         SMALL.with_(seed=40 + 7 * seed))
        mat = m.materials({"R_Al2O3_silicone": TRUE_R})
        out[f] = float(np.mean([full_solve(m.pack(r), mat, 1e-8).mean() for r in range(3)]))
    return out


@pytest.fixture(scope="module")
def truth():
    return true_k(0)


def synthetic(truth, table3, seed):
    """Four replicates per formulation: truth plus noise at Table 3's replicate spread
    (root-mean-square sample standard deviation of its Al2O3 formulations, 0.047 W/(m K))."""
    sd = math.sqrt(np.mean([table3.variance(f) for f in table3.formulations
                            if f.startswith("Al2O3-") and "AlN" not in f]))
    rng = np.random.default_rng(seed)
    return Measurements({f: truth[f] + sd * rng.standard_normal(4) for f in FORMS},
                        f"synthetic seed {seed}")


def test_formulation_names_give_their_fractions():
    assert fractions_of("Al2O3-60") == {"Al2O3": 0.60}
    assert fractions_of("Al2O3-32.5-AlN-32.5") == {"Al2O3": 0.325, "AlN": 0.325}
    assert fractions_of("AlN-47") == {"AlN": 0.47}
    for bad in ("Al2O3", "SiC-50", "Al2O3-40-Al2O3-20", "AlN-80", "Al2O3-x"):
        with pytest.raises(ValueError, match="formulation"):
            fractions_of(bad)


def test_the_paper_screening_grid_steps_a_tenth_of_each_decade():
    g = paper_grid()
    assert g.size == 271 and g.size ** 2 == 73441
    assert g[0] == pytest.approx(1e-8) and g[-1] == pytest.approx(1e-5)
    assert g[1] == pytest.approx(1.1e-8) and g[90] == pytest.approx(1e-7)
    assert g[91] == pytest.approx(1.1e-7)
    with refuses(ValueError, "lo/hi"):
        paper_grid(3e-8, 1e-5)


def test_forward_models_match_the_full_solver(models):
    for m in models.values():
        k, err = m.predict({"R_Al2O3_silicone": np.array([TRUE_R])})
        full = full_solve(m.microstructures[0], m.materials({"R_Al2O3_silicone": TRUE_R}), 1e-9)
        k = k / m.replica_factor
        err = err / m.replica_factor
        assert abs(k[0] - full.mean()) <= err[0] + 1e-9
        assert abs(k[0] / full.mean() - 1) < 3e-3
        assert 0 < m.rve_scatter < 0.2


def test_screening_finds_the_resistance_of_exact_data(models):
    """Measurements equal to the forward models at R = 4.4e-8 (a grid value): Eq. 4 is zero
    there, and the lowest 1 % of the 271 values bracket it."""
    R = 4.4e-8
    meas = Measurements({f: np.array([1, 1.0]) * models[f].predict(
        {"R_Al2O3_silicone": np.array([R])})[0][0] for f in FORMS}, "exact")
    res = screen(models, meas, FORMS, ["R_Al2O3_silicone"])
    assert res.best["R_Al2O3_silicone"] == pytest.approx(R)
    assert res.delta.min() < 1e-12
    lo, hi = res.ranges()["R_Al2O3_silicone"]
    assert lo <= R <= hi and hi / lo < 1.2
    d, c = res.cumulative_frequency()
    assert np.all(np.diff(d) >= 0) and c[-1] == 1.0


@pytest.mark.slow
def test_synthetic_recovery_inside_the_90_percent_interval(models, table3):
    """Acceptance 1, small version: the true resistance inside the 90 % credible interval
    for at least 9 of 10 seeds (each seed: its own sample microstructure and noise)."""
    inside = 0
    for seed in range(10):
        post = calibrate(models, synthetic(true_k(seed), table3, seed), seed=seed)
        lo, hi = post.interval("R_Al2O3_silicone")
        inside += lo <= TRUE_R <= hi
        assert hi / lo > 1.01
    assert inside >= 9


def test_posterior_narrows_with_more_precise_data(models, truth, table3):
    wide = calibrate(models, synthetic(truth, table3, 0))
    tight = Measurements({f: truth[f] + 0.001 * np.array([-1, 1, -1, 1.0]) for f in FORMS},
                         "precise")
    narrow = calibrate(models, tight)
    w = np.log10(wide.interval("R_Al2O3_silicone"))
    n = np.log10(narrow.interval("R_Al2O3_silicone"))
    assert n[1] - n[0] <= w[1] - w[0]


@pytest.mark.slow
def test_area_parametrisation_reports_what_the_data_cannot_separate(table3):
    """Two parameters (R_fp, Rff) from three Al2O3 fractions: the posterior is a ridge of
    negatively correlated log values (a higher matrix resistance is made up by a lower
    contact resistance)."""
    forms = ("Al2O3-55", "Al2O3-60", "Al2O3-65")
    ms = {f: ForwardModel(f, fractions_of(f), PARAMETRISATIONS["area"], SMALL).build()
          for f in forms}
    meas = Measurements({f: table3.values[f] for f in forms}, "Table 3")
    post = calibrate(ms, meas, grid_points=61)
    corr = post.correlation()
    assert corr[0, 1] < -0.3
    st = post.stages[0].identifiability
    assert len(st["directions"]) == 2
    ratios = sorted(d["posterior_to_prior_sd"] for d in st["directions"])
    assert ratios[0] < 0.2     # the contact resistance is pinned
    assert "determined" in st["directions"][0]


def test_central_point_stays_on_a_bent_ridge_and_off_its_far_end():
    """A posterior spread evenly along a half circle of radius 2 in (log10 R, log10 Rff)
    with the best grid point at one end (a ridge's end the data allow): the central point
    is a sample, on the arc (the marginal medians are not: the median of each coordinate
    falls inside the circle), and in the middle of the ridge, not at the best point."""
    from itr_identify.inference.calibrate import Posterior

    rng = np.random.default_rng(4)
    t = rng.uniform(0, np.pi, 4000)
    x = np.stack([-7 + 2 * np.cos(t), -9 + 2 * np.sin(t)], axis=1)
    post = Posterior(["R_a_b", "Rff_a_a"], x, {"R_a_b": 1e-9, "Rff_a_a": 1e-9}, (1e-9, 1e-5))
    centre = np.array([-7.0, -9.0])
    assert np.hypot(*(np.median(x, axis=0) - centre)) < 1.6     # the medians: off the arc
    c = post.central()
    point = np.log10([c["R_a_b"], c["Rff_a_a"]])
    assert np.min(np.abs(x - point).sum(axis=1)) < 1e-9          # a sample
    assert abs(np.hypot(*(point - centre)) - 2) < 1e-9           # on the arc
    angle = np.arctan2(point[1] - centre[1], point[0] - centre[0])
    assert np.pi / 4 < angle < 3 * np.pi / 4                     # the middle, not an end


def test_stages_follow_the_papers_hierarchy():
    fake = {f: ForwardModel(f, fractions_of(f), PARAMETRISATIONS["area"], SMALL)
            for f in ("Al2O3-60", "AlN-60", "Al2O3-30-AlN-30")}
    stages = stages_of(fake)
    assert [s.system for s in stages] == [("Al2O3",), ("AlN",), ("Al2O3", "AlN")]
    assert stages[0].new == ("R_Al2O3_silicone", "Rff_Al2O3_Al2O3")
    assert stages[2].new == ("Rff_Al2O3_AlN",)
    with pytest.raises(ValueError, match="single-filler"):
        stages_of({"Al2O3-30-AlN-30": fake["Al2O3-30-AlN-30"]})


def test_calibrate_rejects_bad_input(models, table3):
    with refuses(ValueError, "measurements"):
        calibrate(models, Measurements({"Al2O3-55": table3.values["Al2O3-55"]}, "part"))
    with refuses(ValueError, "measurements"):
        calibrate(models, table3)       # Al2O3-50 is not in Table 3
    with refuses(ValueError, "grid_points"):
        calibrate(models, synthetic(true_k(0), table3, 0), grid_points=2)
    with refuses(ValueError, "models"):
        calibrate({}, table3)
    with refuses(ValueError, "replicas"):
        ForwardSettings(replicas=1)
    with refuses(ValueError, "box_um/voxel_um"):
        ForwardSettings().with_(box_um=8.0, voxel_um=0.3)
    with refuses(ValueError, "parametrisation"):
        identify(table3, "spots")


def test_validation_and_leave_one_out(models, truth, table3):
    meas = synthetic(truth, table3, 1)
    post = calibrate(models, meas)
    rows = validate(models, post.best, meas)
    assert [r["formulation"] for r in rows] == list(FORMS)
    for r in rows:
        # full solves of two RVEs x 3 directions agree with the data within 10 %
        assert abs(r["error_pct"]) < 10
        assert len(r["replica_k_iso"]) == 3
        assert ("paper_predicted" in r) == (r["formulation"] in ("Al2O3-55", "Al2O3-60"))
    lofo = leave_one_out(models, meas)
    assert len(lofo) == 3
    for r in lofo:
        lo, hi = r["interval_90"]
        assert lo < r["predicted"] < hi
        assert abs(r["error_pct"]) < 15
