"""Candidate effects as terms of the identification's joint model (issue 60): each term
against its physics written out here, and the naming rule on fitted models and on tables
simulated with a stand-in forward model (the machinery's own check; the studies against
truths outside the model are validation/effect_naming_study.py)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from refusals import refuses

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from itr_identify.discrepancy.joint_effects import joint_effects
from itr_identify.discrepancy.naming import (
    ModelFit,
    NamingSettings,
    decide,
    name_effect,
)
from itr_identify.inference.effect_terms import (
    EffectParameter,
    JointEffect,
    RatioTable,
)
from itr_identify.inference.formulations import fractions_of
from itr_identify.inference.joint import JointLikelihood, JointSpace, Tabulated
from itr_identify.inference.measurements import Measurements
from itr_identify.inference.priors import ModelFormPrior, ResistancePrior
from tests.test_joint_posterior import (
    ELASTICITY,
    FORMS,
    INPUTS,
    SCATTER,
    StandIn,
    _simulate,
)

K_M = 0.18


def _tables():
    return {f: Tabulated.of(f, StandIn(f), {**{x: ELASTICITY[x] for x in fractions_of(f)},
                                            "film_nm": -0.008}) for f in FORMS}


def _lik(effect=None, meas=None, densities=None):
    tables = _tables()
    space = JointSpace.build(tables, matrix="silicone", resistance=ResistancePrior(),
                             inputs=INPUTS, model_form=ModelFormPrior(on=False), effect=effect)
    meas = meas or Measurements({f: np.ones(4) for f in FORMS}, "x")
    return JointLikelihood(tables, meas, space, scatter=SCATTER, densities=densities,
                           matrix_conductivity=K_M)


def _point(lik, **values):
    space = lik.space
    theta = np.array([[values.get(n, math.log10(2e-8) if n.startswith("log10") else
                       (0.5 * (a + b) if k == "uniform" and n != "film_nm" else 0.0))
                       for n, k, a, b in zip(space.names, space.kinds, space.a, space.b)]])
    return space.columns(theta)


def _ratios(fn):
    """A ratio table per formulation of ``fn(log10 R, x)`` on a grid."""
    r = np.linspace(-9.4, -5.6, 5)
    x = np.array([0.8, 0.85, 0.9, 0.95, 1.0])
    return {f: RatioTable(r, x, fn(r[:, None], x[None, :])) for f in FORMS}


def test_a_ratio_table_is_exact_for_a_bilinear_ratio_and_held_at_its_edges():
    t = _ratios(lambda r, x: 0.3 * (x - 1) * (r + 10))["AlN-60"]
    rng = np.random.default_rng(0)
    r, x = rng.uniform(-9.4, -5.6, 100), rng.uniform(0.8, 1.0, 100)
    np.testing.assert_allclose(t(r, x), 0.3 * (x - 1) * (r + 10), atol=1e-12)
    assert t(np.array([-12.0]), np.array([0.5]))[0] == pytest.approx(0.3 * -0.2 * 0.6)
    with refuses(ValueError, "ln_ratio"):
        RatioTable(np.arange(3.0), np.arange(2.0), np.zeros((2, 3)))


def test_a_ratio_effect_multiplies_k_by_its_ratio_at_the_formulations_resistance():
    """ln k gains ln r(R_f, x), R_f the resistance the model reads (a hybrid: the
    fraction-weighted geometric mean of its two, scaled by the matrix conductivity)."""
    fn = lambda r, x: 0.5 * (x - 1) * (r + 10)
    e = JointEffect("fraction", "fraction", "ratio",
                    (EffectParameter("filler_fraction_factor", 0.8, 1.0, 1.0, "test"),),
                    "s", "m", _ratios(fn))
    base, cand = _lik(), _lik(e)
    cols = _point(cand, **{"filler_fraction_factor": 0.9, "ln k_silicone": math.log(1.2),
                           "log10 R_AlN_silicone": -7.5, "log10 R_Al2O3_silicone": -8.0})
    k1, _ = cand.conductivities_all(cols)
    k0, _ = base.conductivities_all({n: v for n, v in cols.items() if n in base.space.names
                                     or n in base.space.held})
    lam = math.log10(1.2)
    for i, f in enumerate(cand.order):
        fr = fractions_of(f)
        lr = {"Al2O3": -8.0, "AlN": -7.5}
        r_f = sum(v * lr[x] for x, v in fr.items()) / sum(fr.values()) + lam
        assert k1[i, 0] / k0[i, 0] == pytest.approx(math.exp(fn(r_f, 0.9)), rel=1e-10)


def test_porosity_lowers_the_matrix_by_maxwell_eucken_at_the_voids_share_of_it():
    e, = joint_effects(["porosity"], matrix="silicone")
    base, cand = _lik(), _lik(e)
    p = 0.05
    cols = _point(cand, void_fraction=p)
    k1, _ = cand.conductivities_all(cols)
    for i, f in enumerate(cand.order):
        s = p / (1 - sum(fractions_of(f).values()))
        r = 0.026 / K_M
        me = (2 + r - 2 * s * (1 - r)) / (2 + r + s * (1 - r))   # Maxwell-Eucken, spheres
        c0 = _point(base, **{"ln k_silicone": math.log(me)})
        k0, _ = base.conductivities_all(c0)
        assert k1[i, 0] == pytest.approx(k0[i, 0], rel=1e-9), f


def test_the_matrix_effect_frees_the_matrix_conductivity_over_half_to_twice():
    e, = joint_effects(["matrix"], matrix="silicone")
    space = _lik(e).space
    i = space.names.index("ln k_silicone")
    assert (space.kinds[i], space.a[i], space.b[i]) == ("uniform", math.log(0.5), math.log(2))
    assert len(space.names) == len(_lik().space.names)


def test_the_tester_reads_k_over_one_plus_its_contact_over_the_thickness():
    t = {f: np.array([0.5e-3, 1e-3, 1.5e-3, 1e-3]) for f in FORMS}
    meas = Measurements({f: np.ones(4) for f in FORMS}, "x", thickness_m=t)
    e, = joint_effects(["tester"], matrix="silicone")
    base, cand = _lik(meas=meas), _lik(e, meas=meas)
    cols = _point(cand, R_contact_m2K_per_W=4e-5)
    k1, _ = cand.conductivities_all(cols)
    k0, _ = base.conductivities_all(_point(base))
    inv_t = np.mean(1 / t["AlN-60"])
    np.testing.assert_allclose(k1[:, 0], k0[:, 0] / (1 + 4e-5 * k0[:, 0] * inv_t), rtol=1e-12)


def test_a_batch_error_adds_its_slope_times_its_sd_to_each_formulations_variance():
    c = 2.0
    e = JointEffect("batch", "batch", "batch",
                    (EffectParameter("batch_fraction_sd", 0.0, 0.01, 0.0, "test"),), "s", "m",
                    _ratios(lambda r, x: c * np.log(x) + 0 * r))
    base, cand = _lik(), _lik(e)
    theta_c = np.array([[_point(cand, batch_fraction_sd=0.01)[n][0]
                         for n in cand.space.names]])
    theta_b = np.array([[_point(base)[n][0] for n in base.space.names]])
    x1, x0 = cand.chi_square_terms(theta_c)[:, 0], base.chi_square_terms(theta_b)[:, 0]
    k, _ = base.conductivities_all(_point(base))
    for i, f in enumerate(base.order):
        phi = sum(fractions_of(f).values())
        slope = c * math.log(0.95) / (0.95 - 1.0) / phi          # the table's secant at 1
        v0 = (base._mean[i, 0] - k[i, 0]) ** 2 / x0[i]
        v1 = (base._mean[i, 0] - k[i, 0]) ** 2 / x1[i]
        assert v1 - v0 == pytest.approx((slope * 0.01 * k[i, 0]) ** 2, rel=1e-9)


def test_a_thinning_film_is_the_models_film_at_55_vol_and_gone_at_the_end_point():
    e, = joint_effects(["film"], matrix="silicone")
    base, cand = _lik(), _lik(e)
    cols = _point(cand, film_end_fraction=0.65, film_nm=4.0)
    k1, _ = cand.conductivities_all(cols)
    for i, f in enumerate(cand.order):
        phi = sum(fractions_of(f).values())
        film = 4.0 * max(0.0, (0.65 - phi) / 0.10)
        k0, _ = base.conductivities_all(_point(base, film_nm=film))
        assert k1[i, 0] == pytest.approx(k0[i, 0], rel=1e-12), f
    assert e.parameter.low > 0.55 and e.parameter.source


def test_a_density_column_reads_the_composition_each_effect_gives():
    dens = {"silicone": 0.97, "Al2O3": 3.95, "AlN": 3.26}
    rho = {f: 0.9 * 0.6 * dens[next(iter(fractions_of(f)))]
           + (1 - 0.9 * 0.6) * 0.97 for f in FORMS}
    meas = Measurements({f: np.ones(4) for f in FORMS}, "x",
                        auxiliary={"density_g_per_cm3": {
                            f: np.full(4, rho.get(f, 1.0)) * (1 + 0.003 * np.array(
                                [-1, 1, -1, 1])) for f in FORMS}})
    e, = joint_effects(["fraction"], matrix="silicone",
                       ratios={"fraction": _ratios(lambda r, x: 0 * r + 0 * x)})
    base, cand = _lik(meas=meas, densities=dens), _lik(e, meas=meas, densities=dens)
    assert set(base.density) == {f for f in FORMS if len(fractions_of(f)) == 1}
    th_b = np.array([[_point(base)[n][0] for n in base.space.names]])
    lo = cand.space.names.index("filler_fraction_factor")
    th_c = np.array([[_point(cand)[n][0] for n in cand.space.names]] * 2)
    th_c[0, lo], th_c[1, lo] = 1.0, 0.9
    db = base._density_terms(base.space.columns(th_b), 1)
    dc = cand._density_terms(cand.space.columns(th_c), 2)
    np.testing.assert_allclose(dc[:, 0], db[:, 0], rtol=1e-12)   # factor 1: the base
    f60 = cand.order.index("AlN-60")
    assert dc[f60, 1] > dc[f60, 0] + 100        # the 0.9 factor's density fits, nominal not


def _fit(key, lz, p, value=None):
    return ModelFit(key, key, lz, 0.05, 10.0, 8, p, {}, {}, "x" if value else None, value, 0.0)


def test_the_rule_names_ties_and_says_unexplained_as_its_notes_say():
    s = NamingSettings()
    base_ok, base_bad = _fit("base", 0.0, 0.5), _fit("base", 0.0, 1e-4)
    assert decide(base_ok, [_fit("a", 2.9, 0.5)], s).verdict == "none"
    assert decide(base_bad, [_fit("a", 2.9, 0.5)], s).verdict == "unexplained"
    v = decide(base_bad, [_fit("a", 5.0, 0.4), _fit("b", 3.5, 0.6)], s)
    assert (v.verdict, v.named, v.over_threshold) == ("named", "a", ("a", "b"))
    v = decide(base_bad, [_fit("a", 5.0, 0.4), _fit("b", 4.2, 0.6)], s)
    assert (v.verdict, v.tied, v.named) == ("tie", ("a", "b"), None)
    assert decide(base_bad, [_fit("a", 9.0, 1e-3)], s).verdict == "unexplained"
    # a tie none of whose candidates fits: they reduce the gap, none closes it
    v = decide(base_bad, [_fit("a", 5.0, 1e-3), _fit("b", 4.2, 1e-4)], s,
               separate_by={"a": "measure A", "b": "measure B"})
    assert (v.verdict, v.tied, v.named) == ("unexplained", ("a", "b"), None)
    # one of the tied fits: a tie
    v = decide(base_bad, [_fit("a", 5.0, 1e-3), _fit("b", 4.2, 0.3)], s)
    assert (v.verdict, v.tied) == ("tie", ("a", "b"))
    with refuses(ValueError, "tie_margin"):
        NamingSettings(tie_margin=5.0)


def test_an_unexplained_tie_names_the_measurement_and_what_each_would_leave():
    """The headline of a tie that fails its fits says "unexplained", names each tied
    candidate's separating measurement and the resistances each would leave."""
    from itr_identify.reporting.naming_words import headline_entry, headline_entry_lines

    def fit(key, lz, r):
        return ModelFit(key, f"effect {key}", lz, 0.05, 40.0, 8, 1e-5, {},
                        {"R_A_m": (r, r / 2, 2 * r)}, "x", (1.0, 0.5, 2.0), 0.0)

    v = decide(_fit("base", 0.0, 1e-6), [fit("a", 9.0, 1e-7), fit("b", 8.5, 3e-8)],
               NamingSettings(), separate_by={"a": "a TGA", "b": "a second powder"})
    entry = headline_entry(v)
    assert entry["verdict"] == "unexplained" and entry["text"].startswith("unexplained")
    assert "a TGA" in entry["measurement"] and "a second powder" in entry["measurement"]
    assert entry["each_would_leave"] == {"effect a": {"R_A_m": [1e-7, 5e-8, 2e-7]},
                                         "effect b": {"R_A_m": [3e-8, 1.5e-8, 6e-8]}}
    text = "\n".join(headline_entry_lines(entry))
    assert "the measurement to make" in text and "were it effect b" in text


def _fraction_effect():
    """A fraction loss whose ratio grows with the filler fraction (ln r = 8 (phi - 0.5)
    ln x): a steepening the stand-in's resistances cannot mimic (their relative effect is
    the same at every fraction)."""
    r = np.linspace(-9.4, -5.6, 5)
    x = np.array([0.8, 0.85, 0.9, 0.95, 1.0])
    tabs = {f: RatioTable(r, x, np.repeat(8 * (sum(fractions_of(f).values()) - 0.5)
                                          * np.log(x)[None, :], r.size, axis=0))
            for f in FORMS}
    e, = joint_effects(["fraction"], matrix="silicone", ratios={"fraction": tabs})
    return e


@pytest.mark.slow
def test_a_fraction_loss_in_simulated_tables_is_named_and_nothing_on_noise():
    """Inside the model (the machinery's check, not a power study): tables simulated with
    the stand-in and a fraction factor of 0.9 name the fraction loss with the truth inside
    its 90 % interval; tables without an effect name nothing."""
    effects = [_fraction_effect()] + joint_effects(["matrix", "porosity"], matrix="silicone")
    s = NamingSettings(steps=600, burn=300, evidence_draws=40_000)
    truth = {"log10 R_Al2O3_silicone": math.log10(2e-8), "log10 R_AlN_silicone": -7.6}
    sim_lik = _lik(effects[0])
    for case, x in (("fraction", 0.9), ("none", 1.0)):
        meas = _simulate(sim_lik, {**truth, "filler_fraction_factor": x}, seed=3,
                         rel_sd=0.01)
        v = name_effect(lambda e, meas=meas: _lik(e, meas=meas), effects, s)
        if case == "none":
            assert v.verdict == "none", v.to_dict()["log_bayes_factors"]
        else:
            assert v.named == "fraction", v.to_dict()["log_bayes_factors"]
            _, lo, hi = v.candidate("fraction").value
            assert lo <= x <= hi


def test_a_thickness_series_reads_the_tester_contact_from_its_shape():
    """Samples at 0.5, 1 and 1.5 mm read k_app(t) = t / (t / k + R_c): the series' shape
    (each thickness's mean over the thinnest's) is matched exactly at the true R_c, and
    the base model (no contact: a flat series) is penalised."""
    base = _lik()
    k0, _ = base.conductivities_all(_point(base))
    t = np.repeat([0.5e-3, 1e-3, 1.5e-3], 2)
    rc = 4e-5
    vals = {f: t / (t / k0[i, 0] + rc) * (1 + 0.002 * np.tile([-1, 1], 3))
            for i, f in enumerate(base.order)}
    meas = Measurements(vals, "series", thickness_m={f: t for f in FORMS})
    e, = joint_effects(["tester"], matrix="silicone")
    cand, flat = _lik(e, meas=meas), _lik(meas=meas)
    assert set(cand.series) == set(FORMS)
    ts, means, se = cand.series["AlN-60"]
    np.testing.assert_allclose(ts, [0.5e-3, 1e-3, 1.5e-3])
    i = cand.order.index("AlN-60")
    ll = []
    for r in (0.0, rc, 2 * rc):
        cols = _point(cand, R_contact_m2K_per_W=r)
        k, _, _ = cand._evaluate(cols)
        ll.append(cand._series_terms(cols, k)[i, 0])
    assert ll[1] > ll[0] + 10 and ll[1] > ll[2] + 10
    kb, _, _ = flat._evaluate(_point(flat))
    assert flat._series_terms(_point(flat), kb)[i, 0] == pytest.approx(ll[0], rel=1e-9)
