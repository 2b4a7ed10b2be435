"""The disagreement between the base model and the measurements (chi-square, residual
structure) and the selection among the candidates (BIC, tie, unexplained): the workflow's
verdict (:func:`find_discrepancy`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import stats

from ..inference.formulations import fractions_of
from ..inference.measurements import Measurements
from .deciding import deciding_set, rank_measurements, tied_set, unseparated
from .effects import Effect
from .fit import Group, ModelFit, fit_model, groups_of
from .model_form import AMPLITUDE_RANGE, fit_model_form, leave_one_out
from .observables import auxiliary_groups
from .outcome import Discrepancy, _short
from .settings import DiscrepancySettings
from .tables import ForwardTables, build_tables

__all__ = ["Discrepancy", "find_discrepancy", "residual_structure", "resistance_remarks",
           "thickness_trend"]


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


def _explains_thickness_trend(d: "Discrepancy", st: DiscrepancySettings
                              ) -> tuple[list[ModelFit], str]:
    """The thickness-dependent candidates (a tester effect) that a significant thickness
    trend of the base residuals supports: a trend no RVE effect can make (an RVE does not
    know the sample's thickness), which the candidate removes while fitting better than
    the base. Returns them and the sentence that says so."""
    base = thickness_trend(d.groups, d.base)
    if base is None or base[2] >= st.significance:
        return [], ""
    needs = {e.name for e in d.effects if e.needs_thickness}
    out, words = [], []
    for m in d.candidates:
        after = thickness_trend(d.groups, m)
        if (m.name in needs and m.bic < d.base.bic and after is not None
                and after[2] >= st.significance):
            out.append(m)
            words.append(f"{m.name} removes it (p = {after[2]:.2g} after)")
    if not out:
        return [], (f" The base residuals trend with the sample thickness (p = {base[2]:.2g}), "
                    "which no RVE effect can make; no thickness-dependent candidate removes "
                    "it.")
    return out, (f" The base residuals trend with the sample thickness (p = {base[2]:.2g}), "
                 "which no RVE effect can make: " + "; ".join(words) + ".")


def find_discrepancy(measurements: Measurements, *,
                     settings: DiscrepancySettings | None = None,
                     effects: Sequence[Effect] | None = None,
                     tables: ForwardTables | None = None,
                     tick: Callable[[], None] | None = None,
                     correct: Callable[["Discrepancy"], None] | None = None) -> Discrepancy:
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
        when not given.
    tick : callable, optional
        Called after every full solve.
    correct : callable, optional
        ``correct(d)`` refits candidates with their table level corrected at their best
        point (:func:`itr_identify.discrepancy.best_point.corrector`; it makes full
        solves); None: every candidate keeps the base model's correction.
    """
    settings = settings or DiscrepancySettings()
    comps = {f: fractions_of(f, settings.system) for f in measurements.formulations}
    left_out = [f for f, c in comps.items() if len(c) != 1]
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
    tables.effect_corrections.clear()
    groups = groups_of(measurements, comps, system=settings.system)
    aux = auxiliary_groups(measurements, comps)
    base = fit_model(tables, groups, None, aux)
    skipped, fits = {}, []
    for e in effects:
        fits.append(fit_model(tables, groups, e, aux))
    fits.sort(key=lambda m: m.bic)
    out = Discrepancy("none", "", groups, base, fits, skipped,
                      float(stats.chi2.sf(base.chi_square, base.dof())),
                      residual_structure(groups, base), left_out, effects, None, tables,
                      aux=aux, densities=settings.system.densities(
                          sorted({g.filler for g in groups})))
    if settings.correct_at_best and correct is not None:
        correct(out)
    _decide(out, settings)
    out.tied = tied_set(out, settings)
    if len(out.tied) >= 2:
        out.deciding = rank_measurements(out, settings)
        _say_tied(out, settings)
    if out.verdict != "named":
        _add_model_form(out)
    return out


def _add_model_form(d: Discrepancy) -> None:
    """Calibrate the base model with the model-form term, measure the leave-one-formulation-
    out predictions with and without it, and say so in the statement."""
    d.model_form = mf = fit_model_form(d.tables, d.groups)
    if len({g.formulation for g in d.groups}) >= 3:
        d.leave_one_out = {"base": leave_one_out(d.tables, d.groups, with_term=False),
                           "model-form": leave_one_out(d.tables, d.groups)}
    s, s_lo, s_hi = mf.amplitude
    rs = "; ".join(f"{k} {v[0]:.2g} ({v[1]:.2g} - {v[2]:.2g})"
                   for k, v in mf.resistances.items())
    text = (f" With a model-form term (a Gaussian-process discrepancy in the filler fraction, "
            f"amplitude {100 * s:.2g} % of k, 90 % {100 * s_lo:.2g} - {100 * s_hi:.2g} %), "
            f"the resistances are {rs} m^2 K/W (median, 90 % interval)")
    if d.leave_one_out:
        b, m = d.leave_one_out["base"], d.leave_one_out["model-form"]
        n = len(m.labels)
        text += (f"; each formulation predicted from the others falls inside the 90 % "
                 f"predictive interval for {int(m.covered.sum())} of {n} groups with it, "
                 f"{int(b.covered.sum())} of {n} without")
    if mf.at_prior_edge:
        text += (f"; but the amplitude sits at its prior's upper end "
                 f"({100 * AMPLITUDE_RANGE[1]:g} %): the model misses by more than a "
                 "model-form term is meant to carry, and these resistances are not to be used")
    d.statement += text + "."


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


def _decide(d: Discrepancy, st: DiscrepancySettings) -> None:
    significant = d.p_value_base < st.significance
    base_line = (f"Base model: chi-square {d.base.chi_square:.1f} on {d.base.dof()} degrees "
                 f"of freedom (p = {d.p_value_base:.2g}): the residuals are "
                 f"{'significant' if significant else 'consistent with the noise'}.")
    remarks = resistance_remarks(d.base, st)
    if remarks:
        base_line += " Its resistances: " + "; ".join(remarks) + "."
    if d.base.at_grid_edge:
        # the base model reaches the data only from the end of its range: a discrepancy in
        # itself, whatever the chi-square says
        base_line += (" A base fit at the end of the resistance grid is a discrepancy in "
                      "itself: inside the grid the model cannot reach the measurements.")
        significant = True
    supported = [m for m in d.candidates if d.base.bic - m.bic >= st.bic_margin]
    by_trend, trend_line = _explains_thickness_trend(d, st)
    base_line += trend_line
    if by_trend:
        significant = True
        supported += [m for m in by_trend if m not in supported]
        supported.sort(key=lambda m: m.bic)
    edge = [m.name for m in supported if m.at_grid_edge]
    supported = [m for m in supported if not m.at_grid_edge]
    if edge:
        base_line += (f" Lowering the BIC by {st.bic_margin:g} or more only with a resistance "
                      f"at the edge of its range, hence not named: {', '.join(edge)}.")
    implausible = [(m, e) for m in supported for e in d.effects
                   if e.name == m.name and not _physical(e, m.parameters[e.parameter])]
    if implausible:
        supported = [m for m in supported if m not in [x for x, _ in implausible]]
        base_line += " Lowering the BIC by {:g} or more only with a value outside its " \
            "physical range, hence not named: {}.".format(st.bic_margin, "; ".join(
                f"{m.name} ({e.parameter} = {m.parameters[e.parameter]:.3g}, 90 % "
                f"{m.interval[0]:.3g} - {m.interval[1]:.3g}; physical "
                f"{e.physical_range[0]:g} - {e.physical_range[1]:g}; what would decide: "
                f"{e.separate_by})" for m, e in implausible))
    if not supported:
        d.verdict = "unexplained" if significant else "none"
        if significant:
            best = d.candidates[0] if d.candidates else None
            near = (f" The closest candidate, {best.name}, lowers the BIC by "
                    f"{d.base.bic - best.bic:.1f} (< {st.bic_margin:g})."
                    if best and d.base.bic - best.bic < st.bic_margin else "")
            d.statement = (base_line + " No candidate of the library explains them: an "
                           "unexplained discrepancy (a missing effect outside the library, or "
                           "an error in the data)." + near)
        else:
            d.statement = base_line + (f" No candidate lowers the BIC by {st.bic_margin:g} "
                                       "or more: no effect is named.")
        return
    top = supported[0]
    ties = [m for m in supported[1:] if m.bic - top.bic < st.tie_margin]
    p_after = d.p_value(top)
    if p_after < st.significance:
        d.verdict = "unexplained"
        d.winner = top
        d.statement = (base_line + f" The best candidate, {top.name}, lowers the BIC by "
                       f"{d.base.bic - top.bic:.1f} but leaves a significant residual "
                       f"(chi-square/dof {d.chi_square_per_dof(top):.2f}, p = {p_after:.2g}): "
                       "the discrepancy is not explained by one library effect.")
        return
    effect = next(e for e in d.effects if e.name == top.name)
    lo, hi = top.interval
    named = (f"{top.name}: {effect.parameter} = {top.parameters[effect.parameter]:.3g} "
             f"(90 % interval {lo:.3g} - {hi:.3g}), BIC lower by "
             f"{d.base.bic - top.bic:.1f}, chi-square/dof {d.chi_square_per_dof(d.base):.2f} "
             f"-> {d.chi_square_per_dof(top):.2f}")
    d.winner = top
    moved = resistance_remarks(top, st)
    if moved:
        named += "; its resistances: " + "; ".join(moved)
    if ties:
        d.verdict = "tie"
        others = "; ".join(f"{m.name} (BIC {m.bic - top.bic:+.1f})" for m in ties)
        seps = "; ".join(f"{e.name}: {e.separate_by}" for e in d.effects
                         if e.name in [top.name] + [m.name for m in ties])
        d.statement = (base_line + f" Best: {named}. Equally good within "
                       f"{st.tie_margin:g} in BIC: {others}. The data do not separate them; "
                       f"what would: {seps}.")
    else:
        d.verdict = "named"
        d.statement = base_line + f" Named: {named}."


def _say_tied(d: Discrepancy, st: DiscrepancySettings) -> None:
    """Add the tied set and the measurement that would decide it to the statement."""
    names = ", ".join(_model_words(m, d) for m in d.tied)
    text = f" The data do not tell apart: {names}."
    scale = [e for e in d.effects if e.scales_resistance]
    if scale:
        text += (" Not in that set, as no measurement of k, density or mass fraction can "
                 "tell it from the resistances: " + "; ".join(
                     f"{e.name} (what would: {e.separate_by})" for e in scale) + ".")
    if d.deciding:
        chosen = deciding_set(d.deciding)
        d.deciding_keys = [x.key for x in chosen]
        n = len(d.deciding[0].separation)
        left = unseparated(d.deciding)
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
    d.statement += text


def _model_words(m: ModelFit, d: Discrepancy) -> str:
    if m.name == "base":
        return "no effect (the base model)"
    e = next(e for e in d.effects if e.name == m.name)
    lo, hi = m.interval
    return (f"{m.name} ({e.parameter} {m.parameters[e.parameter]:.3g}, allowed "
            f"{lo:.3g} - {hi:.3g})")
