"""The discrepancy workflow on the identification's own model (issue 60), end to end at small
size: the effects' ratio tables on the identification's first replicas, the rule over base
and candidates, and the identification with an effect beside the base model. Small RVEs
(12 um box, 0.5 um voxels) keep it fast; the full-size run is
validation/effect_naming_table3.py."""

from __future__ import annotations

import numpy as np
import pytest

from itr_fv.rve.spec import RVESpec
from itr_identify.discrepancy.naming import VERDICTS, NamingSettings
from itr_identify.discrepancy.on_identification import effects_of, name_on, with_effect
from itr_identify.forward.model import ForwardSettings
from itr_identify.inference.measurements import Measurements, read_measurements
from itr_identify.inference.pipeline import identify
from itr_identify.reporting.naming_words import (
    candidate_lines,
    effect_fit_lines,
    verdict_sentence,
)

# the slow tier (.ci/run runs it after the fast tier): an identification and its effects' tables;
# the fast tier runs the discrepancy workflow in test_discrepancy.py
pytestmark = pytest.mark.slow

SMALL = ForwardSettings(RVESpec(box_um=12.0, voxel_um=0.5, seed=3), replicas=2)
FORMS = ("Al2O3-55", "Al2O3-60", "AlN-55", "AlN-60", "Al2O3-30-AlN-30")
QUICK = NamingSettings(steps=400, burn=200, evidence_draws=20_000)


@pytest.fixture(scope="module")
def ident():
    t3 = read_measurements()
    meas = Measurements({f: t3.values[f] for f in FORMS}, "Table 3, five formulations")
    return identify(meas, "gap", settings=SMALL, grid_points=41, seed=0,
                    echo=lambda line: None, floor_check=False)


@pytest.fixture(scope="module")
def effects(ident):
    return {e.key: e for e in effects_of(ident, ["fraction", "spots", "tester"])}


def test_ratio_tables_hold_the_physics_of_their_effects(effects):
    """Fewer particles conduct less, and relatively less at the higher fraction; solid
    spots conduct more, more with a larger conductance; both vanish at nominal."""
    fr, sp = effects["fraction"].ratios, effects["spots"].ratios
    assert set(fr) == set(FORMS) and set(sp) == set(FORMS)
    lr = np.array([-7.6])
    for f in FORMS:
        assert fr[f](lr, np.array([1.0]))[0] == 0.0
        assert fr[f](lr, np.array([0.8]))[0] < fr[f](lr, np.array([0.9]))[0] < 0.0
        assert 0.0 < sp[f](lr, np.array([3e-6]))[0] < sp[f](lr, np.array([3e-5]))[0]
    assert fr["AlN-60"](lr, np.array([0.8]))[0] < fr["AlN-55"](lr, np.array([0.8]))[0]


def test_the_rule_runs_on_the_identifications_model_and_says_its_verdict(ident, effects):
    v = name_on(ident, list(effects.values()), settings=QUICK)
    assert v.verdict in VERDICTS
    assert [c.key for c in v.candidates] == ["fraction", "spots", "tester"]
    assert set(v.base.resistances) == {"R_Al2O3_silicone", "R_AlN_silicone"}
    assert all(np.isfinite(c.log_evidence) for c in (v.base, *v.candidates))
    text = verdict_sentence(v)
    assert "chi-square" in text and len(candidate_lines(v)) == 2 + 1 + 3


def test_an_effect_is_identified_beside_the_base_model(ident, effects):
    fit = with_effect(ident, effects["spots"], settings=QUICK)
    assert set(fit.residuals) == set(FORMS)
    lo_g, hi_g = fit.effect.value[1], fit.effect.value[2]
    assert 0.0 <= lo_g <= hi_g <= 3e-5
    for which in ("base", "effect"):
        inside, total = fit.loo_inside(which)
        assert total == len(FORMS) and 0 <= inside <= total
    assert any("leave-one-out" in line for line in effect_fit_lines(fit))
