"""The headline of an identification: flags per parameter and the parametrisation to quote."""

import dataclasses
import json

import numpy as np
import pytest

from itr_identify.forward.model import ForwardSettings
from itr_identify.inference.calibrate import Posterior
from itr_identify.inference.pipeline import Identification
from itr_identify.reporting import headline as headline_module
from itr_identify.reporting import report
from itr_identify.reporting.headline import (
    choose_parametrisation,
    headline,
    headline_lines,
    headline_markdown,
    parameter_flag,
)

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
    c = choose_parametrisation({"area": 100.0, "gap": 138.0}, flags,
                               chi2_dof={"area": 1.66, "gap": 8.76}, voxel_um=0.25)
    assert c["quote"] == "gap" and c["supported"] == "area" and not c["agrees"]
    assert "the data support area (BIC lower by 38.0; chi-square/dof 1.66 against 8.76)" \
        in c["why"]
    assert "R_Al2O3_silicone undetermined" in c["why"]
    # the reason is given: the per-area contact values belong to the voxel, and the quoted
    # parametrisation's poorer fit is said
    assert "(Rff_Al2O3_AlN) that are properties of the 0.25 um voxel" in c["why"]
    assert "do not transfer to another resolution" in c["why"]
    assert "its poorer fit (chi-square/dof 8.76)" in c["why"]
    # when the better fit determines its resistances, it is quoted
    flags["area"]["R_Al2O3_silicone"] = "determined"
    c = choose_parametrisation({"area": 100.0, "gap": 138.0}, flags)
    assert c["quote"] == "area" and c["agrees"] and "BIC lower by 38.0 than gap" in c["why"]
    # neither determines them: the lower BIC, with the warning to quote intervals
    flags["gap"]["R_AlN_silicone"] = "bounded on one side"
    flags["area"]["R_Al2O3_silicone"] = "undetermined"
    c = choose_parametrisation({"area": 100.0, "gap": 138.0}, flags)
    assert c["quote"] == "area" and "quote the intervals" in c["why"]
    # a BIC difference below the margin supports neither: the one that determines its
    # resistances is quoted, and that agrees with "neither is supported"
    flags["gap"]["R_AlN_silicone"] = "determined"
    c = choose_parametrisation({"area": 100.0, "gap": 101.0}, flags)
    assert c["supported"] is None and c["quote"] == "gap" and c["agrees"]
    assert "neither parametrisation is supported" in c["why"]


def test_uncorrected_numerical_effects_beyond_the_interval_are_a_caveat():
    from itr_identify.reporting.headline import _caveat

    entry = {"interval_half_width_factor": 2.09,
             "factors": {"voxel bias (not corrected)": 1.50,
                         "box effect beyond the box solved": 2.94, "film 5 nm": 0.59}}
    out = _caveat(entry)
    assert out["numerical_factor"] == pytest.approx(1.50 * 2.94)
    assert "x4.41" in out["caveat"] and "x/2.09" in out["caveat"]
    assert out["interval_factor"] == 2.09
    assert "fidelity" not in out["caveat"]            # said once, in the fidelity note
    # inside the interval: the factor is given, no caveat
    entry["factors"] = {"voxel bias (not corrected)": 1.1,
                        "box effect beyond the box solved": 1.2}
    out = _caveat(entry)
    assert out["numerical_factor"] == pytest.approx(1.32) and "caveat" not in out
    # a corrected model (no uncorrected voxel bias) with an unknown box effect: nothing
    assert _caveat({"interval_half_width_factor": 1.3,
                    "factors": {"box effect beyond the box solved": None}}) == {}


# --- the headline and the report follow one rule, on constructed identifications --------

class _Ident(Identification):
    """An identification with a given BIC and chi-square (no forward models to evaluate)."""

    def __init__(self, parametrisation, columns, best, bic, chi2, n_forms=12):
        rng = np.random.default_rng(0)
        samples = np.column_stack([c(rng) for c in columns.values()])
        super().__init__(parametrisation, ForwardSettings(), {f"F{i}": None
                                                              for i in range(n_forms)},
                         Posterior(list(columns), samples, best, PRIOR), [])
        self._bic, self._chi2 = bic, chi2

    def bic(self):
        return self._bic

    def chi_square(self):
        return self._chi2


def piled_up_at_the_upper_end(lo_log10):
    """Samples rising linearly in log10 up to the prior's end (1e-5): the equal-tailed
    interval's upper end falls short of 1e-5, where the best grid point lies."""
    return lambda rng: -5.0 - (-5.0 - lo_log10) * (1 - np.sqrt(rng.uniform(0, 1, 4000)))


def reproduce_like():
    """The shape of `itr reproduce`'s result: area fits better (chi-square/dof 1.66 against
    8.76) but leaves R_Al2O3_silicone on a ridge and R_AlN_silicone piled up at the prior's
    upper end; gap determines both."""
    area = _Ident("area", {"R_Al2O3_silicone": uniform(-8.8, -5.2),
                           "Rff_Al2O3_Al2O3": normal(-6.9, 0.1),
                           "R_AlN_silicone": piled_up_at_the_upper_end(-6.5),
                           "Rff_AlN_AlN": normal(-7.15, 0.05),
                           "Rff_Al2O3_AlN": normal(-7.03, 0.06)},
                  {"R_Al2O3_silicone": 4.3e-6, "Rff_Al2O3_Al2O3": 7.0e-8,
                   "R_AlN_silicone": 1e-5, "Rff_AlN_AlN": 6.7e-8, "Rff_Al2O3_AlN": 9.3e-8},
                  bic=-10.4, chi2=1.66 * 7)
    gap = _Ident("gap", {"R_Al2O3_silicone": normal(-7.78, 0.07),
                         "R_AlN_silicone": normal(-8.15, 0.2)},
                 {"R_Al2O3_silicone": 1.67e-8, "R_AlN_silicone": 7.7e-9},
                 bic=27.6, chi2=8.76 * 10)
    return {"area": area, "gap": gap}


@pytest.fixture
def no_budget(monkeypatch):
    """The error budget needs forward models: per resistance, uncorrected effects of x1.95
    against a narrower interval (a caveat) for gap's R_Al2O3_silicone only."""
    def budget(ident):
        out = {}
        if ident.parametrisation == "gap":
            out["R_Al2O3_silicone"] = {"interval_half_width_factor": 1.34, "factors": {
                "voxel bias (not corrected)": 1.3, "box effect beyond the box solved": 1.5}}
        return {"parameters": out}
    monkeypatch.setattr(headline_module, "error_budget", budget)


def _text(lines):
    return " ".join(lines)


def test_headline_quotes_what_the_model_selection_section_says(no_budget):
    idents = reproduce_like()
    head = headline(idents)
    sel = report.selection(idents)
    assert head["quote"] == sel["quote"] == "gap"
    assert head["why"] == sel["why"] and head["supported"] == sel["supported"] == "area"
    section = _text(report.selection_lines(idents))
    assert "The data support **area** (BIC lower by 38.0)." in section
    # the report says the headline quotes gap, deliberately, with the headline's own reason
    assert f"The headline nevertheless quotes **gap**, deliberately: {head['why']}." in section
    assert "0.25 um voxel, not of the materials" in head["why"]
    assert "chi-square/dof 1.66 against 8.76" in head["why"]
    # the terminal and the markdown headline carry the same sentence
    assert f"quote gap: {head['why']}." in _text(headline_lines(head, width=10_000))
    assert f"Quote **gap**: {head['why']}." in _text(headline_markdown(head))
    json.dumps(sel)                                            # identified.json["selection"]


def test_headline_and_section_agree_when_the_better_fit_is_quoted(no_budget):
    idents = reproduce_like()
    area = idents["area"]
    area.posterior.samples[:, 0] = np.random.default_rng(3).normal(-7.9, 0.1, 4000)
    area.posterior.samples[:, 2] = np.random.default_rng(4).normal(-7.5, 0.1, 4000)
    area.posterior.best.update(R_Al2O3_silicone=1.2e-8, R_AlN_silicone=3e-8)
    head = headline(idents)
    assert head["quote"] == report.selection(idents)["quote"] == "area"
    section = _text(report.selection_lines(idents))
    assert "The data support **area**" in section and "The headline quotes it:" in section
    assert "nevertheless" not in section


def test_every_best_value_is_inside_its_interval(no_budget):
    head = headline(reproduce_like())
    for params in head["parameters"].values():
        for n, e in params.items():
            lo, hi = e["interval_90"]
            assert lo <= e["best"] <= hi, n
    e = head["parameters"]["area"]["R_AlN_silicone"]
    assert e["best"] == 1e-5 and e["interval_90"][1] == pytest.approx(1e-5)
    assert e["flag"] == "at the prior's edge"


def test_identifiability_sentences_agree_with_the_flags(no_budget):
    """A stage says "every parameter and combination is determined" only where no parameter
    of it is flagged otherwise (voxel-specific is determined)."""
    from itr_identify.inference.calibrate import StageResult, _identifiability, _statement

    idents = reproduce_like()
    head = headline(idents)
    for par, ident in idents.items():
        post = ident.posterior
        stages = []
        for system, names in (("Al2O3", ("R_Al2O3_silicone", "Rff_Al2O3_Al2O3")),
                              ("AlN", ("R_AlN_silicone", "Rff_AlN_AlN"))):
            names = tuple(n for n in names if n in post.names)
            cols = [post.names.index(n) for n in names]
            ia = _identifiability(names, post.samples[:, cols], PRIOR)
            ia = {"system": system, **ia, **_statement(post, names, ia["directions"])}
            stages.append(StageResult((system,), (), names, (), 0.0, 0.0, ia))
        ident.posterior = dataclasses.replace(post, stages=stages)
        for st in stages:
            flags = [head["parameters"][par][n]["flag"] for n in st.parameters]
            every = "every parameter and combination is determined" in \
                st.identifiability["statement"]
            assert every == all(f in ("determined", "voxel-specific") for f in flags), \
                (par, st.identifiability["statement"], flags)
    text = _text(report.identifiability_lines(idents))
    assert "**area, AlN**: R_AlN_silicone is bounded from below only" in text
    assert "**area, Al2O3**: R_Al2O3_silicone is undetermined" in text
    assert "**gap, AlN**: every parameter and combination is determined by the data." in text


def test_the_fidelity_caveat_is_said_once_with_its_notation_explained(no_budget):
    head = headline(reproduce_like())
    assert head["fidelity"] == "quick"
    lines = headline_lines(head, width=10_000)
    text = _text(lines)
    # once, at the top: indicative, the measured bias, what to run for values to quote
    assert lines[0].startswith("Fidelity `quick`: indicative values")
    assert text.count("--fidelity standard") == 2           # the bias's source, what to run
    assert "gave R_Al2O3_silicone 1.7 times and R_AlN_silicone 2.0 times the `quick` value" \
        in lines[0]
    assert "run again at the default `--fidelity shipped`" in lines[0]
    # per value a mark, not a repeated instruction; the x/F notation explained
    caveats = [ln for ln in lines if ln.lstrip().startswith("*")]
    assert len(caveats) == 1 and "x1.95" in caveats[0] and "x/1.34" in caveats[0]
    assert "fidelity" not in caveats[0]
    assert "x/F is the 90 % interval's half-width as a factor: the interval runs from its " \
           "geometric middle divided by F to its middle times F" in text
    md = _text(headline_markdown(head))
    assert md.count("run again at the default `--fidelity shipped`") == 1
    assert "x/F is the 90 % interval's half-width" in md and "x1.95 *" in md
    assert "quote it from a higher --fidelity" not in text + md


def test_models_at_different_fidelity_are_not_compared_by_their_bic():
    """Issue 47: the BIC of a corrected gap model and of an uncorrected area model is not a
    comparison of parametrisations; none is then supported, and the reason is said."""
    bics = {"area": 10.0, "gap": 60.0}
    flags = {"area": {"R_Al2O3_silicone": "undetermined"},
             "gap": {"R_Al2O3_silicone": "model misfit"}}
    same = choose_parametrisation(bics, flags)
    assert same["supported"] == "area" and same["margin"] == 50.0
    other = choose_parametrisation(bics, flags, levels={"area": "the cheap RVE",
                                                        "gap": "fidelity shipped"})
    assert other["supported"] is None and other["margin"] is None
    assert other["why"].startswith("not compared by their BIC")
    assert other["quote"] == "gap" and "quote the intervals" in other["why"]
    flags["gap"]["R_Al2O3_silicone"] = "determined"
    assert choose_parametrisation(bics, flags, levels={"area": "a", "gap": "b"})["quote"] == "gap"
