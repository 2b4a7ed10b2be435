"""A fit that fails its chi-square test carries a model-form error and is never "determined"
(issue 47).

The calibration runs on closed-form stand-in forward models (k_iso falls linearly in log10
R, as in tests/test_posterior_stages.py): what is tested is the statistic, the flag and the
intervals, not a solver. The chi-square tail is checked against scipy.stats.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from refusals import refuses
from scipy import stats

from itr_identify.forward.model import ForwardSettings
from itr_identify.inference.calibrate import calibrate
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.measurements import Measurements
from itr_identify.inference.misfit import (
    MISFIT_P,
    chi_square_p,
    fit_record,
    model_form_sd,
    with_model_form,
)
from itr_identify.inference.pipeline import Identification
from itr_identify.inference.validate import posterior_prediction
from itr_identify.reporting.headline import headline_lines, parameter_flag
from tests.stand_in_models import FORMS, StandInModel  # noqa: E402

TRUE = {"R_Al2O3_silicone": 3e-8, "R_AlN_silicone": 1e-7}




def measured(models, *, error, seed=0):
    """Four replicates per formulation around the model at TRUE times (1 + error(f)), with
    a 0.5 % replicate scatter."""
    rng = np.random.default_rng(seed)
    out = {}
    for f, m in models.items():
        k = m.predict({p: np.array([TRUE[p]]) for p in m.parameters})[0][0]
        out[f] = k * (1 + error(f)) * (1 + 0.005 * rng.standard_normal(4))
    return Measurements(out, "stub")


@pytest.fixture(scope="module")
def models():
    return {f: StandInModel(f) for f in FORMS}


def test_chi_square_tail_is_scipys():
    for chi2, dof in [(3.0, 1), (10.4, 10), (104.3, 10), (0.0, 4), (25.0, 6)]:
        assert chi_square_p(chi2, dof) == pytest.approx(stats.chi2.sf(chi2, dof), rel=1e-10,
                                                        abs=1e-300)
    with refuses(ValueError, "dof"):
        chi_square_p(1.0, 0)


def test_model_form_sd_brings_the_chi_square_to_its_dof():
    # n equal terms: n r^2 / (v + tau^2) = dof  ->  tau = sqrt(n r^2 / dof - v)
    terms = {str(i): (1.1, 1.0, 0.01 ** 2) for i in range(6)}
    tau = model_form_sd(terms, 4)
    assert tau == pytest.approx(math.sqrt(6 * 0.1 ** 2 / 4 - 0.01 ** 2), rel=1e-9)
    assert model_form_sd({"a": (1.0, 1.0, 1.0)}, 1) == 0.0   # a fit that passes: none


def test_a_model_that_fits_is_determined_and_left_alone(models):
    meas = measured(models, error=lambda f: 0.0)
    post = calibrate(models, meas, grid_points=41, n_samples=2000)
    new, rec = with_model_form(models, meas, post, grid_points=41, n_samples=2000)
    assert rec["p"] > MISFIT_P and not rec["misfit"] and rec["model_form_sd"] == 0.0
    assert new is post
    ident = Identification("gap", ForwardSettings(), models, new, [], measurements=meas,
                           fit=rec)
    assert {parameter_flag(ident, n) for n in new.names} == {"determined"}


def test_a_failing_fit_carries_a_model_form_error_and_is_never_determined(models):
    """An error of the model's form (+-6 % by fraction, which no R removes): the test
    fails, the intervals widen to hold the misfit, and the flag says so."""
    def error(f):
        return 0.06 if fractions_of(f) and sum(fractions_of(f).values()) > 0.59 else -0.06

    meas = measured(models, error=error)
    post = calibrate(models, meas, grid_points=41, n_samples=2000)
    rec0 = fit_record(models, meas, post)
    assert rec0["misfit"] and rec0["p"] < MISFIT_P and rec0["dof"] == len(FORMS) - 2
    new, rec = with_model_form(models, meas, post, grid_points=41, n_samples=2000)
    assert rec["misfit"] and 0.01 < rec["model_form_sd"] < 0.2
    assert rec["chi2_with"] == pytest.approx(rec["dof"], rel=0.05)
    ident = Identification("gap", ForwardSettings(), models, new, [], measurements=meas,
                           fit=rec)
    for n in new.names:
        assert parameter_flag(ident, n) == "model misfit"
        lo, hi = new.interval(n)
        lo0, hi0 = rec["intervals_without"][n]
        assert math.log10(hi / lo) > 1.5 * math.log10(hi0 / lo0)
        assert lo <= TRUE[n] <= hi                     # the widened interval holds the truth
    # the predictive interval of a formulation carries the model-form error too
    f = "AlN-62"
    _, plo, phi = posterior_prediction(models[f], new, standard_error=meas.standard_error(f))
    _, qlo, qhi = posterior_prediction(models[f], post, standard_error=meas.standard_error(f))
    assert phi - plo > 2 * (qhi - qlo)


def test_the_headline_prints_the_test_and_both_intervals(models, monkeypatch):
    from itr_identify.reporting import headline as headline_module

    monkeypatch.setattr(headline_module, "error_budget", lambda ident: {"parameters": {}})
    monkeypatch.setattr(headline_module, "fidelity_note", lambda *a, **k: "note")
    meas = measured(models, error=lambda f: 0.06 if "AlN" in f and "62" in f else 0.0)
    post = calibrate(models, meas, grid_points=41, n_samples=2000)
    new, rec = with_model_form(models, meas, post, grid_points=41, n_samples=2000)
    assert rec["misfit"]
    ident = Identification("gap", ForwardSettings(), models, new, [], measurements=meas,
                           fit=rec)
    head = headline_module.headline({"gap": ident})
    assert head["fit"]["gap"]["misfit"] is True
    text = "\n".join(headline_lines(head))
    assert "fails its chi-square test" in text and "without the model-form error" in text
    assert "determined)" not in text.replace("undetermined)", "")
