"""The headline of an identification: flags per parameter and the parametrisation to quote."""

import numpy as np
import pytest

from itr_identify.forward.model import ForwardSettings
from itr_identify.inference.calibrate import Posterior
from itr_identify.inference.pipeline import Identification
from itr_identify.reporting.headline import choose_parametrisation, parameter_flag

PRIOR = (1e-9, 1e-5)


def _ident(parametrisation, columns, best):
    rng = np.random.default_rng(0)
    samples = np.column_stack([c(rng) for c in columns.values()])
    post = Posterior(list(columns), samples, best, PRIOR)
    return Identification(parametrisation, ForwardSettings(), {}, post, [])


def normal(mean_log10, sd):
    return lambda rng: rng.normal(mean_log10, sd, 4000)


def uniform(lo_log10, hi_log10):
    return lambda rng: rng.uniform(lo_log10, hi_log10, 4000)


@pytest.mark.parametrize("column, best, parametrisation, name, flag", [
    (normal(-7.7, 0.1), 2e-8, "gap", "R_Al2O3_silicone", "determined"),
    (uniform(-9.0, -5.0), 4.3e-6, "area", "R_Al2O3_silicone", "undetermined"),
    (normal(-7.0, 0.8), 1e-7, "gap", "R_AlN_silicone", "undetermined"),     # > 2 decades
    (uniform(-6.5, -5.0), 1e-6, "gap", "R_AlN_silicone", "bounded on one side"),
    (normal(-8.9, 0.05), 1.05e-9, "gap", "R_AlN_silicone", "at the prior's edge"),
    (normal(-7.0, 0.1), 9.3e-8, "area", "Rff_Al2O3_AlN", "voxel-specific"),
])
def test_flags(column, best, parametrisation, name, flag):
    ident = _ident(parametrisation, {name: column}, {name: best})
    assert parameter_flag(ident, name) == flag


def test_the_better_fit_is_not_quoted_when_it_leaves_a_resistance_undetermined():
    flags = {"area": {"R_Al2O3_silicone": "undetermined", "R_AlN_silicone": "determined",
                      "Rff_Al2O3_AlN": "voxel-specific"},
             "gap": {"R_Al2O3_silicone": "determined", "R_AlN_silicone": "determined"}}
    par, why = choose_parametrisation({"area": 100.0, "gap": 138.0}, flags)
    assert par == "gap"
    assert "area fits better (BIC lower by 38.0)" in why
    assert "R_Al2O3_silicone undetermined" in why
    # when the better fit determines its resistances, it is quoted
    flags["area"]["R_Al2O3_silicone"] = "determined"
    par, why = choose_parametrisation({"area": 100.0, "gap": 138.0}, flags)
    assert par == "area" and "BIC lower by 38.0 than gap" in why
    # neither determines them: the lower BIC, with the warning to quote intervals
    flags["gap"]["R_AlN_silicone"] = "bounded on one side"
    flags["area"]["R_Al2O3_silicone"] = "undetermined"
    par, why = choose_parametrisation({"area": 100.0, "gap": 138.0}, flags)
    assert par == "area" and "quote the intervals" in why


def test_uncorrected_numerical_effects_beyond_the_interval_are_a_caveat():
    from itr_identify.reporting.headline import _caveat

    entry = {"interval_half_width_factor": 2.09,
             "factors": {"voxel bias (not corrected)": 1.50,
                         "box effect beyond the box solved": 2.94, "film 5 nm": 0.59}}
    out = _caveat(entry)
    assert out["numerical_factor"] == pytest.approx(1.50 * 2.94)
    assert "x4.41" in out["caveat"] and "x/2.09" in out["caveat"]
    # inside the interval: the factor is given, no caveat
    entry["factors"] = {"voxel bias (not corrected)": 1.1,
                        "box effect beyond the box solved": 1.2}
    out = _caveat(entry)
    assert out["numerical_factor"] == pytest.approx(1.32) and "caveat" not in out
    # a corrected model (no uncorrected voxel bias) with an unknown box effect: nothing
    assert _caveat({"interval_half_width_factor": 1.3,
                    "factors": {"box effect beyond the box solved": None}}) == {}
