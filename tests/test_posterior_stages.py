"""The calibration's per-stage results (:class:`StageResult`): typed, frozen, and the same
JSON-ready dict as before through ``to_dict()``.

Stand-in forward models (a closed-form k_iso, no solves) keep this fast and reach both
kinds of stage: single-filler systems that identify their own parameter and a two-filler
system (gap parametrisation) that has nothing new to identify.
"""

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from itr_identify.inference.calibrate import Posterior, StageResult, calibrate
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements

TRUE = {"R_Al2O3_silicone": 3e-8, "R_AlN_silicone": 1e-7}


class _StubModel:
    """What :func:`calibrate` reads of a ForwardModel; k_iso (W/(m K)) falls linearly in
    log10 of each interface resistance."""

    def __init__(self, formulation: str):
        self.fractions = fractions_of(formulation)
        self.parameters = tuple(f"R_{f}_silicone" for f in sorted(self.fractions))
        self.rve_scatter = 0.01
        self.carried_scatter = 0.0
        self.model_sd = 0.0          # earlier stages' spread and faithful correction
        self.settings = SimpleNamespace(prior_m2K_per_W=(1e-9, 1e-5))

    def predict(self, columns):
        k = 2.0
        for p in self.parameters:
            k = k - 0.3 * (np.log10(np.asarray(columns[p], dtype=float)) + 7.0)
        k = np.atleast_1d(k)
        return k, np.full(k.shape, 1e-3)


@pytest.fixture(scope="module")
def posterior() -> Posterior:
    forms = ("Al2O3-60", "AlN-60", "Al2O3-30-AlN-30")
    models = {f: _StubModel(f) for f in forms}
    noise = np.array([-0.02, 0.01, 0.02, -0.01])
    meas = Measurements({f: models[f].predict({p: np.array([TRUE[p]]) for p in TRUE})[0][0]
                         + noise for f in forms}, "stub")
    return calibrate(models, meas, grid_points=31, n_samples=500)


def test_stages_are_typed_frozen_results(posterior):
    assert len(posterior.stages) == 3
    assert all(isinstance(s, StageResult) for s in posterior.stages)
    first, _, hybrid = posterior.stages
    with pytest.raises(dataclasses.FrozenInstanceError):
        first.log_likelihood_best = 0.0
    assert first.parameters == ("R_Al2O3_silicone",)
    assert hybrid.parameters == () and hybrid.axes_log10 is None and hybrid.density is None
    assert posterior.log_likelihood_best() == pytest.approx(
        sum(s.log_likelihood_best for s in posterior.stages))


def test_stage_attributes_match_their_dict_form(posterior):
    for s in posterior.stages:
        d = s.to_dict()
        assert d["parameters"] == list(s.parameters)
        assert d["system"] == list(s.system)
        assert d["log_likelihood_best"] == s.log_likelihood_best
        assert d["rve_scatter"] == s.rve_scatter
        assert d["identifiability"] == s.identifiability
        json.dumps(d)                                        # JSON-ready as it is
    first = posterior.stages[0].to_dict()
    assert list(first) == ["system", "formulations", "parameters", "carried", "rve_scatter",
                           "axes_log10", "density", "log_likelihood_best", "identifiability"]
    assert first["density"] == posterior.stages[0].density.tolist()
    assert sum(first["density"]) == pytest.approx(1.0)
    hybrid = posterior.stages[2].to_dict()
    assert list(hybrid) == ["system", "formulations", "parameters", "carried", "rve_scatter",
                            "log_likelihood_best", "identifiability"]
    assert hybrid["carried"] == ["R_Al2O3_silicone", "R_AlN_silicone"]
    assert posterior.to_dict()["identifiability"] == [s.identifiability
                                                      for s in posterior.stages]


def _piled_up_at_the_upper_end() -> Posterior:
    """One AlN formulation measured below what any resistance of the prior gives: the
    posterior rises to the prior's upper end (1e-5) and piles up there, broadly enough that
    the equal-tailed 90 % interval stops short of that end (the area parametrisation's
    R_AlN_silicone in `itr reproduce`: best 1.00e-5, interval up to 9.90e-6)."""
    models = {"AlN-60": _StubModel("AlN-60")}
    k = 2.0 - 0.3 * (-4.8 + 7.0)                 # the stub's k at R = 10^-4.8
    meas = Measurements({"AlN-60": k + np.array([-0.3, 0.3, -0.2, 0.2])}, "stub")
    return calibrate(models, meas, grid_points=121, n_samples=4000)


def test_a_best_value_at_the_prior_end_is_inside_its_interval():
    post = _piled_up_at_the_upper_end()
    name = "R_AlN_silicone"
    best = post.best[name]
    assert best == pytest.approx(1e-5)
    # the equal-tailed interval of the samples misses the best value ...
    assert 10 ** np.quantile(post.samples[:, 0], 0.95) < best
    # ... the reported one holds it: one-sided, from the 10 % quantile to the prior's end
    lo, hi = post.interval(name)
    assert lo <= best <= hi
    assert lo == pytest.approx(10 ** np.quantile(post.samples[:, 0], 0.10), rel=0.05)
    entry = post.to_dict()["parameters"][name]
    assert entry["interval_90"][0] <= entry["best"] <= entry["interval_90"][1]
    assert post.prior_ends(name) == (False, True)
    assert post.determination(name) == "at the prior's edge"


def test_identifiability_statement_agrees_with_the_flags():
    """The posterior's spread is below half the prior's (the direction counts as
    determined), but the interval reaches the prior's end: the statement must not say
    that every parameter is determined."""
    post = _piled_up_at_the_upper_end()
    ia = post.stages[0].identifiability
    assert all(d["determined"] for d in ia["directions"])
    assert ia["parameters"] == {"R_AlN_silicone": "at the prior's edge"}
    assert "every parameter" not in ia["statement"]
    assert "R_AlN_silicone is bounded from below only" in ia["statement"]
    # and a determined parameter is said to be
    forms = ("Al2O3-60",)
    models = {f: _StubModel(f) for f in forms}
    meas = Measurements({"Al2O3-60": 2.0 + np.array([-0.02, 0.01, 0.02, -0.01])}, "stub")
    ok = calibrate(models, meas, grid_points=61, n_samples=500)
    assert ok.determination("R_Al2O3_silicone") == "determined"
    assert ok.stages[0].identifiability["statement"] == (
        "every parameter and combination is determined by the data")


@pytest.mark.parametrize("best, expect", [
    (-7.0, (-7.0 - 1.645 * 0.3, -7.0 + 1.645 * 0.3)),   # inside: the equal-tailed interval
    (None, (-7.0 - 1.645 * 0.3, -7.0 + 1.645 * 0.3)),
])
def test_credible_interval_is_equal_tailed_where_the_best_value_is_inside(best, expect):
    from itr_identify.inference.calibrate import credible_interval

    x = np.random.default_rng(1).normal(-7.0, 0.3, 200_000)
    assert credible_interval(x, best) == pytest.approx(expect, abs=0.01)


def test_credible_interval_moves_to_hold_a_best_value_in_a_tail():
    from itr_identify.inference.calibrate import credible_interval

    x = np.random.default_rng(2).normal(0.0, 1.0, 200_000)
    for best in (1.8, -1.8, 3.0, 6.0, -6.0):
        lo, hi = credible_interval(x, best)
        assert lo <= best <= hi
        inside = np.mean((x >= lo) & (x <= hi))
        assert inside >= 0.9 - 1e-3                           # the mass is kept
    # a best value in the upper 5 % tail (3.6 % above it): moved just far enough, the upper
    # end at it and the lower tail 10 - 3.6 = 6.4 %
    lo, hi = credible_interval(x, 1.8)
    assert hi == pytest.approx(1.8, abs=0.01) and lo == pytest.approx(-1.52, abs=0.02)
    # beyond every sample: one-sided, from the 10 % quantile to the best value
    lo, hi = credible_interval(x, 6.0)
    assert hi == 6.0 and lo == pytest.approx(-1.2816, abs=0.02)
