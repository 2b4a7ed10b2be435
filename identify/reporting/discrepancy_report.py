"""Report of the discrepancy workflow: markdown lines and a before/after figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from itr_fv.io import atomic_path

from ..discrepancy.decision import Discrepancy
from ..discrepancy.fit import ModelFit
from ..discrepancy.settings import DiscrepancySettings

__all__ = ["report_lines", "gap_figure"]


def _fit_row(d: Discrepancy, m: ModelFit) -> str:
    e = next((e for e in d.effects if e.name == m.name), None)
    if e is None:
        par = "-"
    else:
        lo, hi = m.interval
        par = (f"{e.parameter} = {m.parameters[e.parameter]:.3g} "
               f"({lo:.3g} - {hi:.3g}; nominal {e.nominal:g})")
    rs = ", ".join(f"{k} {v:.2e}" for k, v in m.parameters.items() if k.startswith("R_"))
    edge = " (R at the grid edge)" if m.at_grid_edge else ""
    return (f"| {m.name} | {par} | {rs}{edge} | {m.chi_square:.1f} / {m.dof(len(d.groups))} "
            f"| {d.p_value(m):.2g} | {d.log_bayes_factor(m):+.2f} | {m.bic:.1f} | "
            f"{d.base.bic - m.bic:+.1f} |")


def report_lines(d: Discrepancy, settings: DiscrepancySettings) -> list[str]:
    """The report's markdown lines."""
    after = d.winner or (d.candidates[0] if d.candidates else d.base)
    lines = ["## Verdict", "", f"**{d.verdict}**: {d.statement}", "",
             "## Residuals before and after", "",
             f"Base model (one R per filler) and {after.name} at their best values; "
             "z = (measured - model) / sqrt(variance), the variance holding the replicate "
             "variance of the mean and the RVE scatter.", "",
             "| group | measured (W/(m K)) | base | base error % | base z | "
             f"{after.name} | error % | z |", "|---|---|---|---|---|---|---|---|"]
    for i, g in enumerate(d.groups):
        zb = (g.mean - d.base.predicted[i]) / np.sqrt(d.base.variance[i])
        za = (g.mean - after.predicted[i]) / np.sqrt(after.variance[i])
        lines.append(f"| {g.label} | {g.mean:.3f} +- {g.standard_error:.3f} | "
                     f"{d.base.predicted[i]:.3f} | {100 * (d.base.predicted[i] / g.mean - 1):+.1f}"
                     f" | {zb:+.2f} | {after.predicted[i]:.3f} | "
                     f"{100 * (after.predicted[i] / g.mean - 1):+.1f} | {za:+.2f} |")
    lines += _auxiliary_lines(d, after)
    lines += ["", "## Structure of the base residuals", ""]
    lines += [f"- {s}" for s in d.structure]
    lines += ["", "## Candidates (ranked by log Bayes factor over the base model)", "",
              "| model | effect parameter (90 % interval) | resistances (m^2 K/W) | "
              "chi-square / dof | p | ln Bayes factor | BIC | BIC gain |",
              "|---|---|---|---|---|---|---|---|", _fit_row(d, d.base)]
    lines += [_fit_row(d, m) for m in d.candidates]
    for name, why in d.skipped.items():
        lines.append(f"| {name} | not tried: {why} | | | | | | |")
    lines += _model_form_lines(d)
    lines += _deciding_lines(d)
    th = d.threshold
    lines += ["", "A candidate is named when its log Bayes factor over the base model (the "
              "likelihood integrated over the resistances and the effect's prior) exceeds the "
              f"threshold calibrated on this table, {th.log_bayes_factor:.2f} (the "
              f"{1 - th.false_naming_rate:.0%} quantile of the largest log Bayes factor on "
              f"{th.replicates} noise-only tables drawn from the base model, seed {th.seed}), "
              f"leaves no significant residual (p >= {settings.significance:g}), needs no "
              "resistance at the edge of its grid and, for an input the material system "
              "states with an uncertainty, keeps its 90 % interval within three of its sds; "
              f"candidates within {settings.tie_margin / 2:g} of the best in log Bayes factor "
              "are reported as a tie." if th is not None else
              "No naming threshold was calibrated.",
              "", "## The library", "", "| effect | kind | parameter (grid) | signature | "
              "separated by |", "|---|---|---|---|---|"]
    for e in d.effects:
        grid = ", ".join(f"{v:g}" for v in e.values)
        lines.append(f"| {e.name} | {e.kind} | {e.parameter} ({grid}) | {e.signature} | "
                     f"{e.separate_by} |")
    f = settings.forward
    t = d.tables
    lines += ["", "## Settings", "",
              "- phase densities (g/cm^3; handbook unless overridden with --density): "
              + ", ".join(f"{k} {v:g}" for k, v in d.densities.items()),
              f"- RVE: {f.box_um:g} um box, {f.voxel_um:g} um voxels, {f.replicas} replicas "
              f"(packing seed {f.seed}), gap contact model, solver tolerance {f.solver_tol:g}",
              _faithful_line(settings, t),
              f"- resistance grid (m^2 K/W): "
              f"{', '.join(f'{r:.1e}' for r in settings.r_grid_m2K_per_W)}",
              "- RVE scatter per formulation (%): " + ", ".join(
                  f"{k} {100 * v:.2f}" for k, v in (t.rve_scatter.items() if t else [])),
              f"- forward tables: {t.solves if t else 0} full-solver results (solved now or "
              f"read from the solve store) in {t.seconds if t else 0:.0f} s"]
    if d.left_out:
        lines.append(f"- left out (two fillers): {', '.join(d.left_out)}")
    return lines


def _faithful_line(settings: DiscrepancySettings, t) -> str:
    fr = settings.faithful
    if fr is None:
        return ("- faithful correction: none (the tables' own level; 12 um at 0.25 um reads "
                "Al2O3-60 about 3 % and AlN-60 10-12 % low)")
    factors = ", ".join(f"{f} {c.factor:.3f} +- {100 * c.relative_sd:.1f} %"
                        for f, c in (t.corrections.items() if t else []))
    boxes = ", ".join(f"{k} {v:g} um" for k, v in fr.boxes_um)
    line = ""
    if t is not None and t.shipped:
        r = settings.r_scatter_m2K_per_W
        line = ("- shipped correction (the headline's level: converged boxes, the voxel bias "
                "extrapolated away; read per resistance): "
                + ", ".join(f"{f} {t.level(f) / t.replica_factor[f]:.3f} "
                            f"+- {100 * t.relative_sd(f):.1f} %" for f in t.shipped)
                + f" at R = {r:.1e} m^2 K/W")
        if not t.corrections:
            return line
        line += "\n"
    return line + (f"- faithful correction ({fr.name}): {fr.packings} packings per formulation "
                   f"({boxes}) at {fr.voxel_um:g} and {fr.coarse_voxel_um:g} um, voxel bias "
                   f"extrapolated away, at R = {settings.r_scatter_m2K_per_W:.1e} m^2 K/W; "
                   f"factor on the table per formulation: {factors}")


def _model_form_lines(d: Discrepancy) -> list[str]:
    """The model-form term's section (only where it was calibrated)."""
    mf = d.model_form
    if mf is None:
        return []
    from ..discrepancy.gp_discrepancy import AMPLITUDE_RANGE, LENGTH_RANGE

    s, lo, hi = mf.amplitude
    lines = ["", "## Model-form term (no candidate named)", "",
             "ln k_measured = ln k_model(phi; R_filler) + delta_filler(phi) + error, delta a "
             "Gaussian process in the filler fraction (squared-exponential; amplitude "
             f"log-uniform {100 * AMPLITUDE_RANGE[0]:g} - {100 * AMPLITUDE_RANGE[1]:g} % of k, "
             f"length {LENGTH_RANGE[0]:g} - {LENGTH_RANGE[1]:g} vol%), everything integrated "
             "over its posterior.", "",
             f"- amplitude: {100 * s:.2g} % of k (90 %: {100 * lo:.2g} - {100 * hi:.2g} %); "
             f"length {mf.length_vol_percent:.3g} vol% (median)"]
    lines += [f"- {k}: {v[0]:.3g} m^2 K/W (90 %: {v[1]:.3g} - {v[2]:.3g})"
              for k, v in mf.resistances.items()]
    if d.leave_one_out:
        b, m = d.leave_one_out["base"], d.leave_one_out["model-form"]
        lines += ["", "Leave one formulation out: its groups predicted from the others "
                  "(90 % predictive interval, W/(m K)).", "",
                  "| group | measured | base alone | inside | with the term | inside |",
                  "|---|---|---|---|---|---|"]
        for i, label in enumerate(m.labels):
            lines.append(f"| {label} | {m.measured[i]:.3f} | {b.low[i]:.3f} - {b.high[i]:.3f}"
                         f" | {'yes' if b.covered[i] else 'no'} | {m.low[i]:.3f} - "
                         f"{m.high[i]:.3f} | {'yes' if m.covered[i] else 'no'} |")
        lines.append("")
        for name, x in (("base alone", b), ("with the term", m)):
            err = np.abs(x.relative_error)
            lines.append(f"- {name}: {int(x.covered.sum())} of {x.covered.size} inside; "
                         f"error of the interval's centre mean {100 * err.mean():.1f} %, "
                         f"max {100 * err.max():.1f} %")
    return lines


def gap_figure(d: Discrepancy, path: Path) -> Path:
    """Relative error of the base model and of the named (or best) candidate per group."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    after = d.winner or (d.candidates[0] if d.candidates else d.base)
    meas = np.array([g.mean for g in d.groups])
    se = np.array([g.standard_error for g in d.groups])
    x = np.arange(len(d.groups))
    fig, ax = plt.subplots(figsize=(max(6, 0.6 * len(x) + 2), 4))
    ax.bar(x - 0.2, 100 * (d.base.predicted / meas - 1), 0.4, label="base model")
    ax.bar(x + 0.2, 100 * (after.predicted / meas - 1), 0.4, label=f"+ {after.name}")
    ax.errorbar(x, np.zeros_like(x, dtype=float), yerr=100 * 1.645 * se / meas, fmt="none",
                ecolor="k", capsize=3, label="measurement 90 %")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xticks(x, [g.label for g in d.groups], rotation=45, ha="right")
    ax.set_ylabel("model / measured - 1 (%)")
    ax.set_title(f"Discrepancy: {d.verdict}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return Path(path)


def _auxiliary_lines(d: Discrepancy, after: ModelFit) -> list[str]:
    """The auxiliary observations (density, mass fraction) against both models."""
    if not d.aux:
        return []
    out = ["", "## Auxiliary observations before and after", "",
           "Each predicted from the composition the model gives the sample (the phase "
           "densities below); z as for k.", "",
           f"| observation | measured | base | base z | {after.name} | z |",
           "|---|---|---|---|---|---|"]
    for i, a in enumerate(d.aux):
        zb = (a.mean - d.base.aux_predicted[i]) / np.sqrt(d.base.aux_variance[i])
        za = (a.mean - after.aux_predicted[i]) / np.sqrt(after.aux_variance[i])
        out.append(f"| {a.label} | {a.mean:.4g} +- {a.standard_error:.2g} | "
                   f"{d.base.aux_predicted[i]:.4g} | {zb:+.2f} | "
                   f"{after.aux_predicted[i]:.4g} | {za:+.2f} |")
    return out


def _deciding_lines(d: Discrepancy) -> list[str]:
    """The tied set and the auxiliary measurements ranked by how well they separate it."""
    if len(d.tied) < 2:
        return []
    out = ["", "## What the data cannot tell apart, and the measurement that would", "",
           "Tied: " + "; ".join("no effect (base)" if m.name == "base" else m.name
                                for m in d.tied) + ".", ""]
    if not d.deciding:
        return out + ["No auxiliary measurement is left to propose (the table has them all)."]
    out += ["Each measurement simulated from each tied model's fit (noise-free expected data, "
            "the stated noise), every tied model refitted: pairs separated by the BIC "
            "margin.", "", "| measurement | pairs separated | least separation (BIC) | "
            "least separated pair |", "|---|---|---|---|"]
    for x in d.deciding:
        (a, b), v = x.worst
        out.append(f"| {x.description} | {x.separated} of {len(x.separation)} | {v:.1f} | "
                   f"{a} / {b} |")
    return out
