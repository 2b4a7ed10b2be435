"""Markdown tables and JSON of identification runs (``report.md``, ``identified.json``)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from itr_fv.materials import paper_data
from itr_fv.materials.parameters import parse_parameter
from itr_fv.rve.spec import SEED_STRIDE

from ..inference.free_inputs_fit import describe as describe_free
from ..inference.joint import CHAIN_TAUS, PROPOSAL_TAUS
from ..inference.measurements import Measurements
from ..inference.pipeline import Identification
from .error_budget import error_budget, error_budget_lines
from .headline import BIC_MARGIN, parametrisation_choice, prior_ends
from .level import level_lines, level_record

__all__ = ["identified_dict", "selection", "table3_lines", "table5_lines", "fidelity_statement",
           "table6_lines", "surrogate_lines",
           "lofo_lines", "identifiability_lines", "settings_lines", "selection_lines",
           "difference_lines", "residual_lines", "box_cut",
           "BIC_MARGIN"]



def _paper_value(name: str) -> float | None:
    kind, (a, b) = parse_parameter(name)
    table5 = paper_data.paper_resistances()
    for key in ((a, b), (b, a)):
        if key in table5 and (kind == "Rff" or "silicone" in key):
            return table5[key]
    return None


def identified_dict(ident: Identification) -> dict:
    """Per parameter: best value, median, 90 % interval, unit, the screening's value and
    range, the paper's Table 5 value; plus fit statistics."""
    post = ident.posterior.to_dict()
    level = level_record(ident)
    screened = {}
    for s in ident.screening:
        edge = s.at_grid_edge()
        for n, r in s.ranges().items():
            screened[n] = {"best": s.best[n], "range_lowest_1pct": list(r),
                           "best_at_grid_edge": edge[n]}
    for n, entry in post["parameters"].items():
        entry["screening"] = screened.get(n)
        entry["paper_table5"] = _paper_value(n)
    return {"parametrisation": ident.parametrisation,
            "contact_model": ident.models[next(iter(ident.models))].parametrisation.contact,
            **post,
            "chi_square": ident.chi_square(), "formulations": len(ident.models),
            "bic": ident.bic(), "settings": ident.settings.to_dict(),
            "fidelity_rounds": ident.fidelity_rounds,
            "fidelity": level,
            "corrections": {f: {**r, **({"runtime_correction": ident.models[f].correction
                                         .to_dict()} if r["source"] == "runtime" else {})}
                            for f, r in level["models"].items() if r["source"] != "none"},
            "error_budget": error_budget(ident),
            "fit": ident.fit, "inputs": ident.inputs, "alone": ident.alone,
            "two_filler_held": ident.held(), "seconds": ident.seconds}


def selection(idents: Mapping[str, Identification]) -> dict:
    """Which parametrisation the data support (the lower BIC, when lower by
    :data:`BIC_MARGIN` or more; otherwise none) and which one the headline quotes and why:
    :func:`~itr_identify.reporting.headline.parametrisation_choice`, the one rule of both."""
    return parametrisation_choice(idents)


def _e(x: float) -> str:
    return f"{x:.2e}"


def table3_lines(meas: Measurements) -> list[str]:
    lines = ["| formulation | replicates (W/(m K)) | mean | standard deviation | "
             "standard error |", "|---|---|---|---|---|"]
    for f in meas.formulations:
        v = meas.values[f]
        lines.append(f"| {f} | {', '.join(f'{x:.2f}' for x in v)} | {meas.mean(f):.3f} | "
                     f"{math.sqrt(meas.variance(f)):.3f} | {meas.standard_error(f):.3f} |")
    return lines


def table5_lines(idents: Mapping[str, Identification]) -> list[str]:
    lines = ["| parameter | parametrisation | paper (Table 5, +-10 %) | screening: best | "
             "screening: lowest-1 % range | calibration: best | median | 90 % interval |",
             "|---|---|---|---|---|---|---|---|"]
    for par, ident in idents.items():
        d = identified_dict(ident)
        for n, e in d["parameters"].items():
            paper = _e(e["paper_table5"]) if e["paper_table5"] else "-"
            sc = e["screening"]
            sb = _e(sc["best"]) if sc else "-"
            if sc and sc["best_at_grid_edge"]:
                sb += f" (grid's {sc['best_at_grid_edge']} edge: the minimum may lie beyond)"
            sr = f"{_e(sc['range_lowest_1pct'][0])} - {_e(sc['range_lowest_1pct'][1])}" \
                if sc else "-"
            lines.append(f"| {n} | {par} | {paper} | {sb} | {sr} | {_e(e['best'])} | "
                         f"{_e(e['median'])} | {_e(e['interval_90'][0])} - "
                         f"{_e(e['interval_90'][1])} |")
    first = next(iter(idents.values()))
    lines += ["", fidelity_statement(first.settings, fillers_of(first))]
    for ident in idents.values():
        lines += [""] + level_lines(ident)
    for ident in idents.values():
        lines += [""] + error_budget_lines(ident)
    return lines


def fidelity_statement(settings, fillers=None) -> str:
    """What the intervals hold for and what they leave out (``fillers``: those the box cut
    is given for, default all); which corrections ran is :func:`level_lines`' to say."""
    s = settings
    cut = box_cut_phrase(s, fillers)
    fa = s.faithful
    if fa is not None:
        return (f"Fidelity `{fa.name}`: the gap parametrisation's models are reduced bases "
                f"on {s.box_um:g} um RVEs at {s.voxel_um:g} um ({s.replicas} packings per "
                "formulation) whose level is multiplied by a faithful correction (which one, "
                "per model, below); its intervals carry the measurement noise, the RVE "
                "scatter, the surrogate's bound and the correction's uncertainty. The area "
                "parametrisation is not corrected: its contact values belong to the "
                f"{s.voxel_um:g} um voxel and {s.box_um:g} um box. Neither carries the box "
                "effect beyond the faithful box, a film at contacts (here "
                f"{1000 * s.rve.contact_film_um:g} nm) or the basis of Table 1 (here "
                f"{s.psd_basis}-weighted): the error budget below gives each.")
    return (f"The 90 % intervals hold at this fidelity only: {s.box_um:g} um box, "
            f"{s.voxel_um:g} um voxels, {s.replicas} packings per formulation, a "
            f"{1000 * s.rve.contact_film_um:g} nm film at contacts, Table 1 read as "
            f"{s.psd_basis}-weighted. They carry the measurement noise, the RVE-to-RVE scatter "
            "and the surrogate's error bound; they do not carry the voxel bias "
            "(`validation/results/voxel_bias_law.md`), the box's cut of the coarse tail "
            f"(here {cut}; `validation/results/box_size.md`) or the choice of film and size "
            "basis (`validation/results/inputs_sensitivity.md`), each of which moves k by a "
            "few per cent and the resistances by more than that (d ln k / d ln R is about -0.1).")


def table6_lines(validation: Mapping[str, list[dict]]) -> list[str]:
    """Table 6: per formulation the measured mean, the paper's prediction and ours per
    parametrisation at its fidelity level (the cheap replicas' full solves times the level's
    factor, :func:`~itr_identify.inference.validate.validate`) next to the raw cheap-RVE
    mean, so that no number is read as another kind."""
    pars = list(validation)
    head = ("| formulation | measured mean | paper predicted | paper error (%) | " +
            " | ".join(f"ours {p} at its level (mean +- sd of 3 RVEs x 3 dirs) | level factor "
                       f"| ours {p} raw (cheap RVE) | ours {p} error (%)" for p in pars) + " |")
    lines = [head, "|" + "---|" * (4 + 4 * len(pars))]
    rows = {p: {r["formulation"]: r for r in validation[p]} for p in pars}
    errs: dict[str, list[float]] = {p: [] for p in pars + ["paper"]}
    for f in rows[pars[0]]:
        r0 = rows[pars[0]][f]
        cells = [f, f"{r0['measured']:.3f}"]
        if "paper_predicted" in r0:
            cells += [f"{r0['paper_predicted']:.2f}", f"{r0['paper_error_pct']:+.1f}"]
            errs["paper"].append(abs(r0["paper_error_pct"]))
        else:
            cells += ["-", "-"]
        for p in pars:
            r = rows[p][f]
            cells += [f"{r['predicted']:.3f} +- {r['predicted_sd']:.3f}",
                      f"x{r['level_factor']:.3f} ({r['level']})",
                      f"{r['predicted_raw']:.3f}", f"{r['error_pct']:+.1f}"]
            errs[p].append(abs(r["error_pct"]))
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Mean / max |relative error| (at the level): " + "; ".join(
        f"{p} {np.mean(e):.1f} % / {np.max(e):.1f} %" for p, e in errs.items() if e) + "."]
    lines += predictive_lines(validation)
    return lines


def predictive_lines(validation: Mapping[str, list[dict]]) -> list[str]:
    """Per parametrisation whose rows carry it, the measured means against the posterior
    predictive interval anchored by these full solves
    (:func:`~itr_identify.inference.joint_fit.mark_predictive`)."""
    out = []
    for p, rows in validation.items():
        marked = [r for r in rows if "predictive_90" in r]
        if not marked:
            continue
        out += ["", f"{p}: the measured mean against the 90 % posterior predictive interval "
                "anchored by these full solves (the draws' inputs and model form move the "
                "solves' k; the measurement's error, one RVE's scatter and the level's sd "
                f"added): inside for {sum(r['inside'] for r in marked)} of {len(marked)}; "
                + ", ".join(f"{r['formulation']} [{r['predictive_90'][0]:.3f}, "
                            f"{r['predictive_90'][1]:.3f}]" + ("" if r["inside"] else " (out)")
                            for r in marked) + "."]
    return out


def surrogate_lines(check: Mapping[str, list[dict]]) -> list[str]:
    """Fig. 6's left panel in words: how many reduced-basis predictions hold the full
    solve of their replica within their certified bounds (both raw)."""
    out = []
    for par, pts in check.items():
        inside = sum(p["inside"] for p in pts)
        worst = max((abs(p["reduced_basis"] / p["full_solve"] - 1) for p in pts), default=0)
        out.append(f"- {par}: {inside} of {len(pts)} full solves (replica 1, raw) within the "
                   f"reduced basis's certified bounds; largest |reduced basis / full - 1| "
                   f"{100 * worst:.2f} %")
    return out


def lofo_lines(lofo: Mapping[str, list[dict]]) -> list[str]:
    lines = ["| formulation | measured | " + " | ".join(
        f"{p}: held-out prediction [90 % interval] | {p}: error (%)" for p in lofo) + " |",
        "|" + "---|" * (2 + 2 * len(lofo))]
    by = {p: {r["formulation"]: r for r in rows} for p, rows in lofo.items()}
    first = next(iter(by.values()))
    for f in first:
        cells = [f, f"{first[f].get('measured', float('nan')):.3f}"]
        for p in lofo:
            r = by[p][f]
            if "skipped" in r:
                cells += [r["skipped"], "-"]
            else:
                cells += [f"{r['predicted']:.3f} [{r['interval_90'][0]:.3f}, "
                          f"{r['interval_90'][1]:.3f}]", f"{r['error_pct']:+.1f}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    # the paper's predictions against the same measured means as Table 6 above
    table6 = paper_data.paper_validation()
    paper = [abs(table6[r["formulation"]][1] / r["measured"] - 1) * 100
             for r in first.values() if r["formulation"] in table6 and "measured" in r]
    for p, rows in lofo.items():
        e = [abs(r["error_pct"]) for r in rows if "error_pct" in r]
        inside = sum(r["inside"] for r in rows if "inside" in r)
        if e:
            lines.append(f"- {p}: mean |error| {np.mean(e):.1f} %, max {np.max(e):.1f} %; "
                         f"measured mean inside the 90 % predictive interval for {inside} of "
                         f"{len(e)}" + (f" (the paper's predictions, not held out, against "
                                        f"the same means: mean {np.mean(paper):.1f} %, max "
                                        f"{np.max(paper):.1f} %)" if paper else ""))
    return lines


def identifiability_lines(idents: Mapping[str, Identification]) -> list[str]:
    """Per stage its identifiability statement: the parameters the data do not determine
    (by :meth:`~itr_identify.inference.calibrate.Posterior.determination`, the rule of the
    headline's flags) and the combinations they do not separate; then strong correlations."""
    lines = []
    for par, ident in idents.items():
        corr = ident.posterior.correlation()
        names = ident.posterior.names
        for st in ident.posterior.stages:
            ia = st.identifiability
            lines.append(f"- **{par}, {ia['system']}**: {ia['statement']}.")
            for d in ia["directions"]:
                lines.append(f"  - {d['combination']}: posterior/prior spread "
                             f"{d['posterior_to_prior_sd']:.2f}")
        pairs = [(names[i], names[j], corr[i, j]) for i in range(len(names))
                 for j in range(i + 1, len(names)) if abs(corr[i, j]) >= 0.5]
        for a, b, c in pairs:
            lines.append(f"  - correlation of log10 {a} and log10 {b}: {c:+.2f}")
    return lines


def selection_lines(idents: Mapping[str, Identification]) -> list[str]:
    """The fit of each parametrisation, which one the data support and which one the
    headline quotes, with the headline's own reason (:func:`selection`)."""
    sel = selection(idents)
    lines = ["| parametrisation | parameters | chi-square at best | chi-square / dof | BIC |",
             "|---|---|---|---|---|"]
    for p, ident in idents.items():
        lines.append(f"| {p} | {ident.n_parameters} | {ident.chi_square():.1f} | "
                     f"{sel['chi2_dof'][p]:.2f} | {sel['bic'][p]:.1f} |")
    lines.append("")
    if sel["margin"] is None:
        text = "One parametrisation: no comparison (run both to compare them)."
    elif sel["supported"]:
        text = (f"Criterion: the lower BIC by {BIC_MARGIN:g} or more. The data support "
                f"**{sel['supported']}** (BIC lower by {sel['margin']:.1f}).")
    else:
        text = (f"Criterion: the lower BIC by {BIC_MARGIN:g} or more. Neither "
                f"parametrisation is supported over the other (BIC difference "
                f"{sel['margin']:.1f}).")
    if sel["agrees"] and sel["supported"]:
        text += f" The headline quotes it: {sel['why']}."
    elif sel["agrees"]:
        text += f" The headline quotes **{sel['quote']}**: {sel['why']}."
    else:
        text += (f" The headline nevertheless quotes **{sel['quote']}**, deliberately: "
                 f"{sel['why']}.")
    lines.append(text)
    return lines


def box_cut(settings, fillers=None) -> dict[str, float]:
    """Volume fraction of each filler's size distribution (of the settings' material
    system) above the largest diameter its RVEs draw (``fillers``: those to give, default
    all of the system's): the cut of :func:`itr_fv.rve.size_cut`, the one that packs
    them."""
    from itr_fv.rve import size_cut

    from ..forward.model import filler_specs

    rve = settings.rve
    names = [f for f in settings.system.filler_names if fillers is None or f in fillers]
    return {spec.material: size_cut(spec, rve.box_um, rve.voxel_um,
                                     tail_quantile=rve.tail_quantile,
                                     max_diameter_box_ratio=rve.max_diameter_box_ratio
                                     ).volume_high
            for spec in filler_specs(settings, {f: 0.5 for f in names})}


def fillers_of(ident: Identification) -> set[str]:
    """The fillers of an identification's formulations."""
    return {f for m in ident.models.values() for f in m.fractions}


def box_cut_phrase(settings, fillers=None) -> str:
    """:func:`box_cut` as words: ``"20 % of the Al2O3 volume, 85 % of the AlN volume"``."""
    return ", ".join(f"{100 * v:.0f} % of the {f} volume"
                     for f, v in box_cut(settings, fillers).items())


def conductivities_used(ident: Identification) -> str:
    """The phase conductivities the forward models solved with, as one phrase."""
    used: dict[str, float] = {}
    for m in ident.models.values():
        used.update(m.materials(m.centre).conductivity)
    return ", ".join(f"{p} {k:g}" for p, k in used.items()) + " W/(m K)"


def settings_lines(idents: Mapping[str, Identification], extra: Mapping[str, object]
                   ) -> list[str]:
    ident = next(iter(idents.values()))
    s = ident.settings
    system = s.system
    sizes = "; ".join(f"{f.name}: {f.size_note or 'lognormal'}" for f in system.fillers)
    lines = [f"- material system {system.name!r} ({system.source or 'default'}): "
             f"{system.describe()}, relative sd "
             + ", ".join(f"{p} {v:g}" for p, v in system.conductivity_sds().items())
             + f"; sizes: {sizes}",
             f"- RVE: {s.box_um:g} um box, {s.voxel_um:g} um voxels ({s.n}^3), "
             f"{s.replicas} replicas per formulation, packing seeds from {s.seed} "
             f"(seeds used: " + ", ".join(
                 f"{f} {m.seeds}" for f, m in ident.models.items()) + "; replica r packs "
             f"with seed {s.seed} + r, and a packing that fails to reach its fraction is "
             f"replaced by seed + r + {SEED_STRIDE}, + {2 * SEED_STRIDE}, ...)",
             f"- largest particle diameter {s.max_diameter_box_ratio:g} x box "
             f"({s.max_diameter_box_ratio * s.box_um:.1f} um): the cut removes "
             + box_cut_phrase(s, fillers_of(ident))
             + " of the size distributions (replaced by smaller particles); conductivities "
             + conductivities_used(ident),
             "- stated inputs: silicone film between touching particles "
             + (f"{1000 * s.rve.contact_film_um:g} nm (`--film-nm`, held)"
                if "film_nm" not in ident.inputs.get("inputs", {}) else
                "0 nm in the models, marginalised over 0-5 nm (uniform; `--film-nm` states "
                "and holds one)")
             + f" (0 = in contact through the two interface resistances alone, at every "
             f"particle size), Table 1 read as {s.psd_basis}-weighted (`--psd-basis`)",
             f"- prior: log-uniform {ident.posterior.prior[0]:g} - "
             f"{ident.posterior.prior[1]:g} m^2 K/W for every resistance in every inference "
             f"(the reduced bases span {s.prior_m2K_per_W[0]:g} - {s.prior_m2K_per_W[1]:g}); "
             "screening grid 1e-8 - 1e-5 (the paper's)",
             f"- reduced basis: relative bound gap {s.rb_tol:g}, at most {s.rb_max_solves} "
             f"full solves; full solves by the solver {s.solver.key!r} "
             f"({s.solver.summary}) at relative residual "
             f"{s.solver_tol:g}"]
    for par, i in idents.items():
        c = next(iter(i.models.values())).parametrisation
        lines.append(f"- parametrisation {par}: {c.description}")
        held = i.held()
        if held:
            point = next(iter(held.values()))["held_at"]
            spread = [100 * h["carried_scatter"] for h in held.values()]
            lines.append("  - two-filler formulations held at the single-filler posterior's "
                         "central point (the sample nearest the medians): "
                         + ", ".join(f"{n} {v:.2e}" for n, v in point.items())
                         + f"; their k_iso spread over that posterior {min(spread):.1f}-"
                         f"{max(spread):.1f} % (in the likelihood)")
    lines += [f"- {k}: {v}" for k, v in extra.items()]
    return lines


def joint_lines(idents: Mapping[str, Identification]) -> list[str]:
    """The joint posterior of each parametrisation that has one: what it samples, its
    priors and convergence, the point quoted, the fit's test with and without the model
    form, and how the point and interval move with the resistance prior's floor."""
    lines = []
    for par, ident in idents.items():
        jp = ident.joint
        if jp is None:
            continue
        sampler = ident.inputs.get("sampler", {})
        fit = ident.fit
        mf = fit.get("model_form", {})
        lo_p, hi_p = ident.posterior.prior
        lines += ["", f"### The joint posterior ({par})", "",
                  f"One posterior over {', '.join(jp.names)} (held: "
                  + (", ".join(f"{k} = {v:g}" for k, v in jp.held.items()) or "none")
                  + "), every formulation evaluated at every point "
                  "(`itr_identify.inference.joint`), sampled by emcee: "
                  f"{sampler.get('walkers')} walkers, {sampler.get('steps')} steps after "
                  f"{sampler.get('burn')} of burn-in, longest autocorrelation "
                  f"{max(jp.autocorr.values()):.0f} steps, "
                  + (_convergence(jp) if jp.converged else "NOT converged") + ".",
                  "",
                  f"Priors: each resistance log-uniform over {lo_p:g} - {hi_p:g} m^2 K/W "
                  "(`itr_identify.inference.priors`); the conductivities lognormal about the "
                  "system's values; the film uniform where none is stated; per filler system "
                  "one offset (the shipped correction's shared term and the model form's "
                  f"offset, sd {100 * mf.get('offset_sd', 0):g} %) and a slope in the fraction "
                  f"(sd {100 * mf.get('slope_sd_per_5_vol_pct', 0):g} % per 5 vol%). The point "
                  "quoted is the posterior median of ln R; the intervals are equal-tailed; both "
                  "read from each resistance's Rao-Blackwell marginal (the average of its "
                  "exact conditional densities over the posterior's draws).",
                  "",
                  f"The fit's test: {describe_free(fit['free_inputs'])}. At the points quoted "
                  f"with the stated inputs: chi-square {fit['stated']['chi2']:.1f} on "
                  f"{fit['stated']['dof']} dof (p {fit['stated']['p']:.2g}) without the "
                  f"model form, {fit['stated']['chi2_with']:.1f} (p "
                  f"{fit['stated']['p_with']:.2g}) with its prior "
                  "variance. The model form's posterior medians: " + ", ".join(
                      f"{k} {100 * v * (mf.get('offset_sd') if k.startswith('offset') else mf.get('slope_sd_per_5_vol_pct', 0)):+.1f} %"  # noqa: E501
                      for k, v in mf.get("posterior_medians", {}).items()) + ".", "",
                  "| resistance prior | parameter | point | 90 % interval |",
                  "|---|---|---|---|"]
        for label, per in fit.get("floor_sensitivity", {}).items():
            for n, e in per.items():
                lines.append(f"| {label} | {n} | {e['point']:.2e} | {e['interval_90'][0]:.2e}"
                             f" - {e['interval_90'][1]:.2e} |")
    if lines:
        lines = ["## The joint posterior"] + lines
    return lines


def alone_lines(idents: Mapping[str, Identification]) -> list[str]:
    """Each single-filler formulation fitted alone (:func:`~itr_identify.inference.alone.
    fit_alone`) beside the joint fit: do the formulations agree?"""
    lines = []
    for par, ident in idents.items():
        if not ident.alone:
            continue
        lines += ["", f"### Each formulation alone ({par})", "",
                  "| formulation | parameter | best (m^2 K/W) | 90 % interval | inside the "
                  "joint interval? |", "|---|---|---|---|---|"]
        for r in ident.alone:
            lo, hi = r["interval_90"]
            jlo, jhi = ident.posterior.interval(r["parameter"])
            overlap = "overlaps" if lo <= jhi and hi >= jlo else "no overlap"
            lines.append(f"| {r['formulation']} | {r['parameter']} | {r['best']:.2e} | "
                         f"{lo:.2e} - {hi:.2e} ({r['determination']}) | {overlap} |")
        for p, a in ident.fit.get("alone_agreement", {}).items():
            lines += ["", f"Agreement of the formulations alone on {p} (at the nominal inputs; "
                      f"chi-square of their log10 values about their weighted mean "
                      f"{a['weighted_mean']:.2e}): {a['chi2']:.1f} on {a['dof']} dof, p "
                      f"{a['p']:.2g}: " + ("they agree" if a["agree"] else
                                           "they DISAGREE (p < 0.01)") + "."]
    if lines:
        lines = ["## Do the formulations agree?", "",
                 "Each single-filler formulation calibrated on its own replicates "
                 "(`fig_alone.png`); where the intervals do not overlap, the formulations "
                 "disagree on the resistance and the model's form is in question."] + lines
    return lines


def residual_lines(idents: Mapping[str, Identification]) -> list[str]:
    pars = list(idents)
    lines = ["| formulation | measured mean | " + " | ".join(
        f"{p}: reduced basis at best | {p}: (meas - model) / sd" for p in pars) + " |",
        "|" + "---|" * (2 + 2 * len(pars))]
    res = {p: i.residuals() for p, i in idents.items()}
    for f in res[pars[0]]:
        cells = [f, f"{res[pars[0]][f][0]:.3f}"]
        for p in pars:
            m, k, v = res[p][f]
            cells += [f"{k:.3f}", f"{(m - k) / math.sqrt(v):+.1f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


#: Which of the numbered reasons of :func:`difference_lines` bear on a parameter, by
#: (parametrisation, kind): the voxel (1) only where the model is tied to it or biased by
#: it, the ridge (3) only under the per-area model, the missing contact resistance (5) only
#: under the gap model.
_REASONS = {("area", "R"): (2, 3, 4), ("area", "Rff"): (1, 2, 3, 4),
            ("gap", "R"): (1, 2, 4, 5)}


def difference_lines(idents: Mapping[str, Identification]) -> list[str]:
    """Each identified value against the paper's Table 5, with the reasons that apply."""
    lines = ["| parameter | parametrisation | ours (best) / paper | paper's value inside our "
             "90 % interval | remark |", "|---|---|---|---|---|"]
    for par, ident in idents.items():
        for n in ident.posterior.names:
            paper = _paper_value(n)
            if paper is None:
                continue
            lo, hi = ident.posterior.interval(n)
            low_end, high_end = prior_ends(ident.posterior, n)
            remarks = []
            if high_end:
                remarks.append("interval reaches the prior's upper end: the data bound it "
                               "only from below")
            if low_end:
                remarks.append("interval reaches the prior's lower end")
            kind = parse_parameter(n)[0]
            if kind == "Rff":
                remarks.append("per-area contact value: belongs to our voxel, not the paper's "
                               "0.1 um")
            reasons = _REASONS.get((par, kind), range(1, 6))
            remarks.append("reasons " + ", ".join(str(r) for r in reasons) + " below")
            lines.append(f"| {n} | {par} | {ident.posterior.best[n] / paper:.2g} | "
                         f"{'yes' if lo <= paper <= hi else 'no'} | {'; '.join(remarks)} |")
    first = next(iter(idents.values()))
    s = first.settings
    lines += ["", "Reasons for the differences (numbered in the remarks):", "",
              f"1. Voxel: {s.voxel_um:g} um against the paper's 0.1 um. Under the per-area "
              "model the faces two touching voxelized spheres share grow with the voxel, so a "
              "per-area contact resistance is a property of the voxel it was identified at "
              "(`validation/results/resolution_area.md`); the gap model converges, with a "
              "discretisation bias of about -2.5 % of k at 0.25 um "
              "(`validation/results/resolution.md`), which the identified resistances absorb.",
              f"2. Box: {s.box_um:g} um against 40 um. The largest particle is "
              f"{s.max_diameter_box_ratio * s.box_um:.1f} um, which removes "
              + box_cut_phrase(s, fillers_of(first))
              + " of Table 1; the smaller replacements add interface area per volume.",
              "3. Identifiability: under the per-area model a higher particle-matrix "
              "resistance is traded for a lower contact resistance along a ridge of the "
              "posterior (correlations above); the paper's screening picks one point of that "
              "ridge and reports +-10 %, the posterior shows its extent.",
              "4. The paper's values come from its prototypical-function surrogate fitted to "
              "its own campaign; ours from reduced bases certified against the full solver "
              "(error bound in the likelihood) and calibrated on all 12 formulations with the "
              "replicate variances and the RVE scatter, the screening on the paper's subsets.",
              "5. Under the gap model a contact conducts through the true silicone film; the "
              "paper's same-filler and Al2O3-AlN contact resistances have no counterpart "
              "there, so its hybrids are predicted, not fitted."]
    return lines


def _convergence(jp) -> str:
    """How a converged joint posterior met its rule (:func:`~..inference.joint.sample`)."""
    if jp.source == "importance":
        return (f"converged (importance draws from two t fitted to a chain spanning "
                f"{PROPOSAL_TAUS} or more of its autocorrelation times as estimated on it, "
                f"worth {jp.effective_draws:.0f} independent draws)")
    return (f"converged (every chain spans {CHAIN_TAUS} autocorrelation times, worth "
            f"{jp.effective_draws:.0f} independent draws)")
