"""The joint posterior inside the identification (issue 59), on small real forward models:
the hybrids vary both resistances and move with every input, the fit's test, the flags,
leave-one-out from the others' posterior, the formulations alone tested for agreement and
the floor's sensitivity. Small RVEs (12 um box, 0.5 um voxels) keep it fast."""

from __future__ import annotations

import math

import numpy as np
import pytest

from itr_fv.rve.spec import RVESpec
from itr_identify.forward.model import ForwardSettings
from itr_identify.inference.joint import JointLikelihood, Tabulated
from itr_identify.inference.joint_fit import alone_agreement
from itr_identify.inference.measurements import Measurements, read_measurements
from itr_identify.inference.pipeline import identify
from itr_identify.reporting.headline import DETERMINED_FACTOR, parameter_flag

# the slow tier (.ci/run runs it after the fast tier): an identification on five formulations;
# the fast tier identifies in test_identify_cli.py and test_identify.py
pytestmark = pytest.mark.slow

SMALL = ForwardSettings(RVESpec(box_um=12.0, voxel_um=0.5, seed=3), replicas=2)
FORMS = ("Al2O3-55", "Al2O3-60", "AlN-55", "AlN-60", "Al2O3-30-AlN-30")


@pytest.fixture(scope="module")
def ident():
    t3 = read_measurements()
    meas = Measurements({f: t3.values[f] for f in FORMS}, "Table 3, five formulations")
    return identify(meas, "gap", settings=SMALL, grid_points=41, seed=0,
                    echo=lambda line: None)


def test_the_hybrid_varies_both_resistances_and_moves_with_the_matrix_alone(ident):
    hybrid = ident.models["Al2O3-30-AlN-30"]
    assert hybrid.fixed == {} and hybrid.rb is not None
    assert set(hybrid.parameters) == {"R_AlN_silicone", "R_Al2O3_silicone"}
    tab = Tabulated.of("Al2O3-30-AlN-30", hybrid, ident.inputs["elasticity"]["Al2O3-30-AlN-30"])
    k0 = hybrid.predict({"R_Al2O3_silicone": np.array([2e-8]),
                         "R_AlN_silicone": np.array([3e-8])})[0][0]
    at = {"R_Al2O3_silicone": 2e-8, "R_AlN_silicone": 3e-8}
    k, _, _ = tab.evaluate(np.log10([[at[p] for p in tab.parameters]]))
    assert k[0] == pytest.approx(k0, rel=2e-3)       # the table holds the model
    lik = JointLikelihood({"Al2O3-30-AlN-30": tab}, ident.measurements,
                          _space(ident, {"Al2O3-30-AlN-30": tab}), scatter={"Al2O3-AlN": 0.01})
    names = lik.space.names
    theta = np.zeros((2, len(names)))
    for i, n in enumerate(names):
        if n.startswith("log10"):
            theta[:, i] = math.log10(2e-8)
    theta[1, names.index("ln k_silicone")] = math.log(1.1)
    k = lik.conductivities(lik.space.columns(theta), "Al2O3-30-AlN-30")[0]
    assert k[1] > k[0] * 1.02          # a matrix 10 % more conductive: the hybrid too


def _space(ident, tables):
    from itr_identify.inference.joint import JointSpace
    from itr_identify.inference.priors import DEFAULT_MODEL_FORM

    return JointSpace.build(tables, matrix="silicone", resistance=ident.resistance_prior,
                            inputs=ident.priors, model_form=DEFAULT_MODEL_FORM)


def test_the_posterior_is_the_joint_ones_with_its_point_and_record(ident):
    jp = ident.joint
    assert jp is not None and jp.converged
    for r in ("R_Al2O3_silicone", "R_AlN_silicone"):
        assert ident.posterior.best[r] == pytest.approx(jp.point(r), rel=1e-12)
        lo, hi = ident.posterior.interval(r)
        assert lo < ident.posterior.best[r] < hi
        assert (lo, hi) == pytest.approx(jp.interval(r), rel=2e-3)
    assert ident.posterior.prior == (1e-9, 1e-6)
    fit = ident.fit
    stated = fit["stated"]
    assert stated["dof"] == len(FORMS) - 2 and 0 <= stated["p"] <= 1
    assert stated["chi2_with"] <= stated["chi2"]   # the model form's variance only adds
    # the test: inputs free, film uniform (a flat-prior parameter like the resistances)
    free = fit["free_inputs"]
    assert fit["dof"] == free["dof"] == len(FORMS) - 3 and fit["p"] == free["p"]
    assert fit["misfit"] == (free["p"] < fit["threshold_p"])
    assert free["chi2"] == pytest.approx(free["chi2_data"] + free["chi2_inputs"])
    for key in ("ln k_silicone", "ln k_Al2O3", "ln k_AlN", "film_nm", "offset_Al2O3"):
        assert key in jp.names
    shares = ident.inputs["parameters"]["R_AlN_silicone"]["shares"]
    assert sum(shares.values()) == pytest.approx(1.0, abs=1e-9)
    assert all(v >= -1e-9 for v in shares.values())
    floor = fit["floor_sensitivity"]
    assert set(floor) == {"floor 1e-08", "floor 1e-10", "floor 1e-09 (the prior)"}


def test_a_value_is_determined_only_within_x_over_three_on_a_passing_fit(ident):
    for r in ident.posterior.names:
        flag = parameter_flag(ident, r)
        lo, hi = ident.posterior.interval(r)
        if flag == "determined":
            assert math.sqrt(hi / lo) <= DETERMINED_FACTOR and not ident.fit["misfit"]
        if flag.startswith("bounded ("):
            assert flag == f"bounded (x/{math.sqrt(hi / lo):.1f})"


def test_leave_one_out_predicts_each_formulation_from_the_others(ident):
    rows = ident.leave_one_out(seed=1)
    assert [r["formulation"] for r in rows] == list(ident.models)
    for r in rows:
        lo, hi = r["interval_90"]
        assert lo < r["predicted"] < hi and r["effective_draws"] > 10
        assert r["inside"] == (lo <= r["measured"] <= hi)


def test_formulations_alone_are_tested_for_agreement():
    rows = [{"formulation": "a", "parameter": "R", "best": 1e-8, "interval_90": [5e-9, 2e-8]},
            {"formulation": "b", "parameter": "R", "best": 1.2e-8,
             "interval_90": [6e-9, 2.4e-8]},
            {"formulation": "c", "parameter": "R", "best": 1e-7, "interval_90": [8e-8, 1.25e-7]}]
    out = alone_agreement(rows)["R"]
    assert out["dof"] == 2 and not out["agree"] and out["p"] < 0.01
    agree = alone_agreement(rows[:2])["R"]
    assert agree["agree"] and agree["p"] > 0.5


def test_no_error_budget_factor_reaches_beyond_the_priors_width(ident):
    from itr_identify.reporting.error_budget import error_budget

    lo, hi = ident.posterior.prior
    width = math.log(hi / lo)
    budget = error_budget(ident)
    for p, entry in budget["parameters"].items():
        for name, factor in entry["factors"].items():
            if factor is None:
                continue
            assert abs(math.log(factor)) <= width, (p, name, factor)
        for name in entry["beyond_prior"]:
            assert entry["factors"][name] is None


def test_the_predictive_interval_is_anchored_by_the_full_solves(ident):
    """A validation row whose full solves read 10 % above the tables at the point: the
    interval moves up by the same 10 %; a measured mean at the anchored centre is inside,
    one 40 % above is not; the interval is at least as wide as the measurement's error."""
    from itr_identify.inference.joint_fit import mark_predictive

    lik = ident.likelihood()
    at = np.zeros((1, lik.space.dim))
    for r in ident.joint.resistances:
        at[0, lik.space.names.index(f"log10 {r}")] = math.log10(ident.posterior.best[r])
    f = "Al2O3-60"
    k_table = float(lik.conductivities(lik.space.columns(at), f)[0][0])
    se = 0.01 * k_table

    def row(predicted, measured):
        return {"formulation": f, "predicted": predicted, "measured": measured,
                "measured_se": se, "replica_k_iso": [predicted] * 3}

    rows = [row(k_table, k_table), row(1.1 * k_table, k_table),
            row(k_table, 1.4 * k_table)]
    mark_predictive(rows, ident)
    (a0, b0), (a1, b1), _ = (r["predictive_90"] for r in rows)
    assert a1 == pytest.approx(1.1 * a0, rel=0.03) and b1 == pytest.approx(1.1 * b0, rel=0.03)
    assert b0 - a0 > 2 * 1.645 * se
    assert a0 < k_table < b0 and rows[0]["inside"]
    assert not rows[2]["inside"]


def test_every_inference_has_the_one_resistance_prior(ident):
    """The grid calibration at the nominal inputs and each formulation fitted alone search
    the joint posterior's resistance prior (1e-9 - 1e-6 by default), not the reduced bases'
    wider box (5e-10 - 2e-6): a value at the nominal inputs never lies outside the prior."""
    rp = ident.resistance_prior
    box = ident.settings.prior_m2K_per_W
    assert box[0] < rp.low and rp.high < box[1]
    assert ident.posterior.prior == pytest.approx((rp.low, rp.high))
    assert ident.at_nominal.prior == pytest.approx((rp.low, rp.high))
    for n in ident.at_nominal.names:
        lo, hi = ident.at_nominal.interval(n)
        assert rp.low * 0.999 <= lo <= ident.at_nominal.best[n] <= hi <= rp.high * 1.001
    for row in ident.alone:
        assert rp.low * 0.999 <= row["interval_90"][0] <= row["interval_90"][1] <= rp.high * 1.001
