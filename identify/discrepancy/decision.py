"""The disagreement between the base model and the measurements (chi-square, residual
structure) and the selection among the candidates (a Bayes factor over a calibrated
threshold, tie, unexplained): the workflow's verdict (:func:`find_discrepancy`, frozen)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from ..inference.formulations import fractions_of
from ..inference.measurements import Measurements
from .best_point import Corrected
from .effects import Effect
from .fit import Group, ModelFit, fit_model, groups_of
from .gp_discrepancy import (
    AMPLITUDE_RANGE,
    LeaveOneOut,
    ModelFormFit,
    fit_model_form,
    leave_one_out,
)
from .naming_threshold import NamingThreshold, calibrate_threshold
from .observables import AuxGroup, auxiliary_groups
from .outcome import Discrepancy, _short
from .settings import DiscrepancySettings
from .tables import ForwardTables, build_tables
from .tie_breaking import deciding_set, rank_measurements, tied_set, unseparated

__all__ = ["Discrepancy", "Verdict", "decide", "find_discrepancy", "residual_structure",
           "resistance_remarks", "thickness_trend"]


def residual_structure(groups: Sequence[Group], fit: ModelFit) -> list[str]:
    """Trends of the standardised residuals ``(measured - model) / sqrt(variance)``: with
    the filler fraction per filler, between fillers, with the thickness."""
    z = (np.array([g.mean for g in groups]) - fit.predicted) / np.sqrt(fit.variance)
    out = []
    for fl in sorted({g.filler for g in groups}):
        sel = np.array([g.filler == fl for g in groups])
        phi = np.array([g.fraction for g in groups])[sel]
        line = f"{fl}: mean standardised residual {z[sel].mean():+.2f} over {sel.sum()} groups"
        if np.unique(phi).size >= 3:
            slope, _, r, p, se = stats.linregress(phi * 100, z[sel])
            line += (f"; trend with the filler fraction {slope:+.2f} per vol% "
                     f"(+-{se:.2f}, p = {p:.2g})")
        out.append(line)
    fillers = sorted({g.filler for g in groups})
    if len(fillers) == 2:
        a, b = (z[np.array([g.filler == fl for g in groups])] for fl in fillers)
        t, p = stats.ttest_ind(a, b, equal_var=False)
        out.append(f"{fillers[0]} minus {fillers[1]}: {a.mean() - b.mean():+.2f} "
                   f"(Welch t = {t:.2f}, p = {p:.2g})")
    trend = thickness_trend(groups, fit)
    if trend is not None:
        slope, se, p = trend
        out.append(f"thickness: trend {slope:+.2f} per mm (+-{se:.2f}, p = {p:.2g})")
    return out


def thickness_trend(groups: Sequence[Group], fit: ModelFit
                    ) -> tuple[float, float, float] | None:
    """(slope per mm, its standard error, p-value) of the standardised residuals of ``fit``
    against the sample thickness; None without two thicknesses or more."""
    th = np.array([g.thickness_m if g.thickness_m is not None else np.nan for g in groups])
    if not (np.isfinite(th).all() and np.unique(th).size >= 2):
        return None
    z = (np.array([g.mean for g in groups]) - fit.predicted) / np.sqrt(fit.variance)
    res = stats.linregress(th * 1e3, z)
    return float(res.slope), float(res.stderr), float(res.pvalue)


def _thickness_remark(groups: Sequence[Group], base: ModelFit,
                      candidates: Sequence[ModelFit], effects: Sequence[Effect],
                      st: DiscrepancySettings) -> str:
    """A sentence on a significant thickness trend of the base residuals (which no RVE
    effect can make: an RVE does not know the sample's thickness) and the
    thickness-dependent candidates that remove it; empty without one. A remark only: the
    verdict is the Bayes factor's."""
    trend = thickness_trend(groups, base)
    if trend is None or trend[2] >= st.significance:
        return ""
    needs = {e.name for e in effects if e.needs_thickness}
    words = []
    for m in candidates:
        after = thickness_trend(groups, m)
        if m.name in needs and after is not None and after[2] >= st.significance:
            words.append(f"{m.name} removes it (p = {after[2]:.2g} after)")
    return (f" The base residuals trend with the sample thickness (p = {trend[2]:.2g}), "
            "which no RVE effect can make" + (": " + "; ".join(words) if words else
                                              "; no thickness-dependent candidate removes it")
            + ".")


def find_discrepancy(measurements: Measurements, *,
                     settings: DiscrepancySettings | None = None,
                     effects: Sequence[Effect] | None = None,
                     tables: ForwardTables | None = None,
                     tick: Callable[[], None] | None = None,
                     correct: Callable[..., Corrected] | None = None,
                     explain: bool = True) -> Discrepancy:
    """Run the workflow on a measurement table.

    Parameters
    ----------
    measurements : Measurements
        Formulation names give the composition
        (:func:`itr_identify.inference.formulations.fractions_of`); a ``thickness_m`` per
        replicate enables the thickness covariate.
    settings : DiscrepancySettings, optional
    effects : sequence of Effect, optional
        The candidate library (default :func:`itr_identify.discrepancy.effects.default_effects`).
    tables : ForwardTables, optional
        Forward tables of an earlier call (they do not depend on the measurements); built
        when not given. They are not changed.
    tick : callable, optional
        Called after every full solve.
    correct : callable, optional
        Refits the candidates over the naming threshold with their table level corrected
        at their best point (:func:`itr_identify.discrepancy.best_point.corrector`; it makes
        full solves); None: every candidate keeps the base model's correction.
    explain : bool
        Also find the tied set, the measurement that would decide it and the model-form
        term (default); False: the verdict alone (calibration studies).

    Returns
    -------
    Discrepancy
        Frozen: the verdict and everything it was decided from.
    """
    settings = settings or DiscrepancySettings()
    comps = {f: fractions_of(f, settings.system) for f in measurements.formulations}
    tables, effects = _tables_of(comps, settings, effects=effects, tables=tables, tick=tick)
    out = _verdict(tables, groups_of(measurements, comps, system=settings.system),
                   auxiliary_groups(measurements, comps), effects, settings,
                   left_out=[f for f, c in comps.items() if len(c) != 1], correct=correct)
    return _explained(out, settings) if explain else out


def _tables_of(comps: Mapping[str, Mapping[str, float]], settings: DiscrepancySettings, *,
               effects: Sequence[Effect] | None, tables: ForwardTables | None,
               tick: Callable[[], None] | None) -> tuple[ForwardTables, list[Effect]]:
    """The forward tables of the single-filler formulations of ``comps`` (``tables``, or
    built) without corrections at best points (those belong to one table's fits), and the
    candidates (``effects``, or the tables'); ValueError for fewer than three single-filler
    formulations or tables that lack one."""
    singles = {f: c for f, c in comps.items() if len(c) == 1}
    if len(singles) < 3:
        raise ValueError(f"measurements: the workflow needs at least 3 single-filler "
                         f"formulations, got {sorted(singles)}")
    if tables is None:
        tables = build_tables(singles, settings=settings, effects=effects, tick=tick)
    missing = [f for f in singles if f not in tables.base]
    if missing:
        raise ValueError(f"tables: no forward table for {missing}")
    effects = list(tables.effects if effects is None else effects)
    # corrections at best points belong to one table's fits: none carried from an earlier call
    return replace(tables, effect_corrections={}), effects


def _verdict(tables: ForwardTables, groups: list[Group], aux: list[AuxGroup],
             effects: list[Effect], settings: DiscrepancySettings, *, left_out: list[str],
             correct: Callable[..., Corrected] | None) -> Discrepancy:
    """The base model and every candidate calibrated, the naming threshold calibrated on
    the table, the candidates corrected at their best points where ``correct`` is given and
    the settings ask, and the naming rule's verdict (:func:`decide`)."""
    base = fit_model(tables, groups, None, aux)
    fits = [fit_model(tables, groups, e, aux) for e in effects]
    threshold = calibrate_threshold(tables, groups, aux, base, effects,
                                    false_naming_rate=settings.false_naming_rate,
                                    replicates=settings.calibration_replicates,
                                    seed=settings.calibration_seed)
    corrected_at_best: dict[str, dict[str, float]] = {}
    if settings.correct_at_best and correct is not None:
        c = correct(tables, groups, aux, base, fits, effects, threshold.log_bayes_factor)
        tables, fits, corrected_at_best = c.tables, c.fits, c.factors
    fits.sort(key=lambda m: base.log_evidence - m.log_evidence)
    p_base = float(stats.chi2.sf(base.chi_square, base.dof()))
    verdict = decide(base, fits, effects, groups, p_base, threshold, settings)
    return Discrepancy(verdict.verdict, verdict.statement, groups, base, fits, {}, p_base,
                       residual_structure(groups, base), left_out, effects, verdict.winner,
                       tables, aux=aux, densities=settings.system.densities(
                           sorted({g.filler for g in groups})),
                       corrected_at_best=corrected_at_best, threshold=threshold)


def _explained(out: Discrepancy, settings: DiscrepancySettings) -> Discrepancy:
    """``out`` with the tied set, the measurements that would decide it (where two models
    or more are tied) and, where no effect is named, the model-form term, each with its
    sentence added to the statement."""
    out = replace(out, tied=tied_set(out, settings))
    if len(out.tied) >= 2:
        deciding = rank_measurements(out, settings)
        keys, text = _say_tied(out, deciding)
        out = replace(out, deciding=deciding, deciding_keys=keys,
                      statement=out.statement + text)
    if out.verdict != "named":
        model_form, loo, text = _model_form(out)
        out = replace(out, model_form=model_form, leave_one_out=loo,
                      statement=out.statement + text)
    return out


def _model_form(d: Discrepancy) -> tuple[ModelFormFit, dict[str, LeaveOneOut] | None, str]:
    """The base model calibrated with the model-form term, the leave-one-formulation-out
    predictions with and without it, and the sentence that says so."""
    mf = fit_model_form(d.tables, d.groups)
    loo = None
    if len({g.formulation for g in d.groups}) >= 3:
        loo = {"base": leave_one_out(d.tables, d.groups, with_term=False),
               "model-form": leave_one_out(d.tables, d.groups)}
    s, s_lo, s_hi = mf.amplitude
    rs = "; ".join(f"{k} {v[0]:.2g} ({v[1]:.2g} - {v[2]:.2g})"
                   for k, v in mf.resistances.items())
    text = (f" With a model-form term (a Gaussian-process discrepancy in the filler fraction, "
            f"amplitude {100 * s:.2g} % of k, 90 % {100 * s_lo:.2g} - {100 * s_hi:.2g} %), "
            f"the resistances are {rs} m^2 K/W (median, 90 % interval)")
    if loo:
        b, m = loo["base"], loo["model-form"]
        n = len(m.labels)
        text += (f"; each formulation predicted from the others falls inside the 90 % "
                 f"predictive interval for {int(m.covered.sum())} of {n} groups with it, "
                 f"{int(b.covered.sum())} of {n} without")
    if mf.at_prior_edge:
        text += (f"; but the amplitude sits at its prior's upper end "
                 f"({100 * AMPLITUDE_RANGE[1]:g} %): the model misses by more than a "
                 "model-form term is meant to carry, and these resistances are not to be used")
    return mf, loo, text + "."


def resistance_remarks(fit: ModelFit, st: DiscrepancySettings) -> list[str]:
    """Remarks on the fitted filler-silicone resistances of ``fit``: at an end of the
    solved grid (the model cannot reach the data inside it), outside the physical range
    :attr:`DiscrepancySettings.physical_r_m2K_per_W`, or more than 5x from the paper's
    Table 5 value."""
    from itr_fv.materials.paper_data import paper_parameters

    paper = paper_parameters()
    grid = st.r_grid_m2K_per_W
    lo, hi = st.physical_r_m2K_per_W
    out = []
    for name, r in fit.parameters.items():
        if not (name.startswith("R_") and name.endswith("_" + st.system.matrix)):
            continue                  # not a filler-matrix resistance (an effect's parameter)
        notes = []
        if r <= grid[0] * (1 + 1e-9) or r >= grid[-1] * (1 - 1e-9):
            notes.append(f"at the {'lower' if r <= grid[0] * (1 + 1e-9) else 'upper'} end "
                         "of the solved grid")
        if not lo <= r <= hi:
            notes.append(f"outside the physical range {lo:g} - {hi:g} m^2 K/W")
        ref = paper.get(name)
        if ref and not 0.2 <= r / ref <= 5:
            notes.append(f"{r / ref:.2g}x the paper's {ref:.2g}")
        if notes:
            out.append(f"{name} = {r:.2g} m^2 K/W ({'; '.join(notes)})")
    return out


def _physical(e: Effect, value: float) -> bool:
    """Whether ``value`` of ``e`` lies in its physical range (where it states one)."""
    if e.physical_range is None:
        return True
    lo, hi = e.physical_range
    return lo - 1e-12 <= value <= hi * (1 + 1e-9)


@dataclass(frozen=True)
class Verdict:
    """What :func:`decide` concludes: ``verdict`` (none, named, tie, unexplained), the
    model it rests on and the paragraph that says why."""

    verdict: str
    winner: ModelFit | None
    statement: str


def _base_verdict(base: ModelFit, candidates: Sequence[ModelFit], effects: Sequence[Effect],
                  groups: Sequence[Group], p_value_base: float,
                  st: DiscrepancySettings) -> tuple[bool, str]:
    """Whether the base model's misfit is a discrepancy (its residuals significant, or a
    resistance at the end of its grid) and the sentences that say so: its chi-square, its
    resistances' remarks, the grid's end and the thickness trend."""
    significant = p_value_base < st.significance
    base_line = (f"Base model: chi-square {base.chi_square:.1f} on {base.dof()} degrees "
                 f"of freedom (p = {p_value_base:.2g}): the residuals are "
                 f"{'significant' if significant else 'consistent with the noise'}.")
    remarks = resistance_remarks(base, st)
    if remarks:
        base_line += " Its resistances: " + "; ".join(remarks) + "."
    if base.at_grid_edge:
        # the base model reaches the data only from the end of its range: a discrepancy in
        # itself, whatever the chi-square says
        base_line += (" A base fit at the end of the resistance grid is a discrepancy in "
                      "itself: inside the grid the model cannot reach the measurements.")
        significant = True
    base_line += _thickness_remark(groups, base, candidates, effects, st)
    return significant, base_line


def decide(base: ModelFit, candidates: Sequence[ModelFit], effects: Sequence[Effect],
           groups: Sequence[Group], p_value_base: float, threshold: NamingThreshold,
           st: DiscrepancySettings) -> Verdict:
    """The naming rule. A candidate is named when its log Bayes factor over the base model
    exceeds the calibrated threshold (:mod:`.naming_threshold`), it leaves no significant
    residual, needs no resistance at the end of its grid, and (an input the lab stated with
    an uncertainty) does not pull that input beyond three of its sds, which says the model
    lacks something rather than that the input is off. Candidates within ``tie_margin / 2``
    of the best in log Bayes factor are a tie. ``candidates`` best first."""
    lbf = {m.name: float(m.log_evidence - base.log_evidence) for m in candidates}
    cut = threshold.log_bayes_factor
    significant, base_line = _base_verdict(base, candidates, effects, groups, p_value_base,
                                           st)
    rule = (f"the naming threshold, a log Bayes factor of {cut:.2f} (at most "
            f"{threshold.false_naming_rate:.0%} of {threshold.replicates} noise-only tables "
            "drawn from the base model name an effect)")
    supported = [m for m in candidates if lbf[m.name] > cut]
    edge = [m.name for m in supported if m.at_grid_edge]
    supported = [m for m in supported if not m.at_grid_edge]
    if edge:
        base_line += (f" Over {rule} only with a resistance at the end of its grid, hence "
                      f"not named: {', '.join(edge)}.")
    if not supported:
        best = candidates[0] if candidates else None
        near = (f" The closest candidate, {best.name}, has a log Bayes factor of "
                f"{lbf[best.name]:.2f}." if best is not None else "")
        if significant:
            return Verdict("unexplained", None, base_line + " No candidate of the library "
                           f"reaches {rule}: an unexplained discrepancy (a missing effect "
                           "outside the library, or an error in the data)." + near)
        return Verdict("none", None, base_line + f" No candidate reaches {rule}: no effect "
                       "is named." + near)
    top = supported[0]
    effect = next(e for e in effects if e.name == top.name)
    lo, hi = top.interval
    value = top.parameters[effect.parameter]
    named = (f"{top.name}: {effect.parameter} = {value:.3g} (90 % interval {lo:.3g} - "
             f"{hi:.3g}), log Bayes factor {lbf[top.name]:.1f} over {rule}, chi-square/dof "
             f"{base.chi_square / base.dof():.2f} -> {top.chi_square / top.dof():.2f}")
    if not _physical(effect, value):
        named += (f"; outside its physical range {effect.physical_range[0]:g} - "
                  f"{effect.physical_range[1]:g} (weighed down by its prior, not excluded)")
    moved = resistance_remarks(top, st)
    if moved:
        named += "; its resistances: " + "; ".join(moved)
    p_after = float(stats.chi2.sf(top.chi_square, top.dof()))
    if p_after < st.significance:
        return Verdict("unexplained", top, base_line + f" The best candidate, {top.name}, "
                       f"has a log Bayes factor of {lbf[top.name]:.1f} but leaves a "
                       f"significant residual (chi-square/dof {top.chi_square / top.dof():.2f}"
                       f", p = {p_after:.2g}): the discrepancy is not explained by one library "
                       "effect.")
    pulled = getattr(effect, "pulled_beyond_statement", None)
    if pulled is not None and pulled((lo, hi)):
        return Verdict("unexplained", top, base_line + f" The data pull {named}; but that "
                       f"input is stated as {effect.nominal:g} with a relative sd of "
                       f"{effect.stated_sd:.0%}, and its whole 90 % interval lies beyond three "
                       "of those: the model lacks something (an effect outside the library) "
                       "rather than the input being off.")
    ties = [m for m in supported[1:] if lbf[top.name] - lbf[m.name] < st.tie_margin / 2]
    if ties:
        others = "; ".join(f"{m.name} (log Bayes factor {lbf[m.name]:.1f})" for m in ties)
        seps = "; ".join(f"{e.name}: {e.separate_by}" for e in effects
                         if e.name in [top.name] + [m.name for m in ties])
        return Verdict("tie", top, base_line + f" Best: {named}. Equally good within "
                       f"{st.tie_margin / 2:g} in log Bayes factor: {others}. The data do not "
                       f"separate them; what would: {seps}.")
    return Verdict("named", top, base_line + f" Named: {named}.")


def _say_tied(d: Discrepancy, deciding: Sequence) -> tuple[list[str], str]:
    """The measurements named to decide the tied set and the sentence on the tied set and
    on them."""
    names = ", ".join(_model_words(m, d) for m in d.tied)
    text = f" The data do not tell apart: {names}."
    scale = [e for e in d.effects if e.scales_resistance]
    if scale:
        text += (" Not in that set, as no measurement of k, density or mass fraction can "
                 "tell it from the resistances: " + "; ".join(
                     f"{e.name} (what would: {e.separate_by})" for e in scale) + ".")
    keys: list[str] = []
    if deciding:
        chosen = deciding_set(deciding)
        keys = [x.key for x in chosen]
        n = len(deciding[0].separation)
        left = unseparated(deciding)
        if len(chosen) > 1:
            text += (" No single measurement separates every pair it could; together these "
                     f"{len(chosen)} are expected to: "
                     + "; ".join(x.description for x in chosen) + " ("
                     + ", ".join(f"{x.separated}" for x in chosen)
                     + f" of the {n} pairs on its own, in that order).")
        if left:
            text += (" No measurement proposed separates "
                     + "; ".join(f"{_short(a)} / {_short(b)}" for a, b in left)
                     + " (k at other fractions or another kind of evidence would).")
        text += "".join(" " + x.sentence(alone=len(chosen) == 1) for x in chosen)
    return keys, text


def _model_words(m: ModelFit, d: Discrepancy) -> str:
    if m.name == "base":
        return "no effect (the base model)"
    e = next(e for e in d.effects if e.name == m.name)
    lo, hi = m.interval
    return (f"{m.name} ({e.parameter} {m.parameters[e.parameter]:.3g}, allowed "
            f"{lo:.3g} - {hi:.3g})")
