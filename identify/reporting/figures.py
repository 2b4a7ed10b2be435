"""Figures of an identification run (analogues of the paper's Figs. 2, 4, 6 and 8).

Every function writes one PNG atomically (matplotlib's Agg backend; the RVE renders use
pyvista off screen) and returns its path. Units are written with the micro sign (µm,
µK); parameters are labelled by :func:`~itr_identify.reporting.labels.parameter_label`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from itr_fv.io import atomic_path
from itr_fv.materials import paper_data
from itr_fv.materials.parameters import parameter_name
from itr_fv.materials.psd import LogNormalPSD, fit_truncated_sample
from itr_fv.rve import FillerSpec, SizeCut, size_cut

from ..forward.fidelity import fidelity_name
from ..inference.pipeline import Identification
from .labels import MICRO_M, parameter_label, parameter_symbol, phase_label

__all__ = ["psd_figure", "rve_figure", "parity_figure", "surrogate_check", "screening_figure",
           "posterior_figure", "packed_diameters", "filler_cuts", "box_cut_text",
           "temperature_figure", "level_caption", "effect_residual_figure"]


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _null_formatter():
    from matplotlib.ticker import NullFormatter
    return NullFormatter()


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    _pyplot().close(fig)
    return Path(path)


def packed_diameters(ident: Identification) -> dict[str, np.ndarray]:
    """Diameters (µm) of every packed particle of the single-filler RVEs, per filler."""
    out: dict[str, list] = {}
    for m in ident.models.values():
        if len(m.fractions) != 1:
            continue
        for ms in m.microstructures:
            t = ms.particles
            for mat in np.unique(t.material):
                out.setdefault(str(mat), []).append(2e6 * t.radii_m[t.material == mat])
    return {k: np.concatenate(v) for k, v in out.items()}


def filler_cuts(ident: Identification) -> dict[str, tuple[SizeCut, float, LogNormalPSD]]:
    """Per filler of the single-filler models: the size cut its RVEs were drawn with
    (:func:`itr_fv.rve.size_cut` at the first such model's RVE settings), the box edge
    (µm) and the number-weighted Table 1 distribution in the run's basis."""
    out = {}
    for m in ident.models.values():
        if len(m.fractions) != 1:
            continue
        (filler, phi), = m.fractions.items()
        if filler in out:
            continue
        spec = FillerSpec.from_table1(filler, phi, basis=m.settings.psd_basis)
        rve = m.settings.rve
        cut = size_cut(spec, rve.box_um, rve.voxel_um, tail_quantile=rve.tail_quantile,
                       max_diameter_box_ratio=rve.max_diameter_box_ratio)
        out[filler] = (cut, float(rve.box_um), spec.psd)
    return out


def box_cut_text(filler: str, cut: SizeCut, box_um: float) -> str:
    """The sentence of Fig. 2 on the box cut: where it cuts and the shares of the filler's
    Table 1 volume and particles it removes (:func:`itr_fv.rve.size_cut`)."""
    where = (f"box cut at {cut.d_hi_um:.1f} {MICRO_M} ({cut.d_hi_um / box_um:.2g} × the "
             f"{box_um:g} {MICRO_M} box)" if cut.box_limited
             else f"far-tail cut at {cut.d_hi_um:.1f} {MICRO_M}")
    return (f"{where}\nremoves {100 * cut.volume_high:.0f} % of the {phase_label(filler)} "
            "volume\n"
            f"({100 * cut.number_high:.0f} % of its particles)")


def psd_figure(ident: Identification, path: Path) -> tuple[Path, dict]:
    """Fig. 2 analogue: packed diameters against Table 1; returns the path and the fitted
    (mu, sigma) per filler (truncated maximum likelihood, truncation at the drawn extremes).

    The histogram of the packed diameters is compared with Table 1's lognormal truncated
    to the drawn range and renormalised (solid); the uncut lognormal is dashed, the range
    the box cuts off is shaded, and the share of the filler's volume it removes is written
    in the panel."""
    plt = _pyplot()
    diam = packed_diameters(ident)
    cuts = filler_cuts(ident)
    fig, axes = plt.subplots(1, len(diam), figsize=(5.6 * len(diam), 4.4), squeeze=False)
    fits = {}
    for ax, (filler, d) in zip(axes[0], sorted(diam.items())):
        mu, sigma = fit_truncated_sample(d, float(d.min()), float(d.max()))
        fits[filler] = {"mu": mu, "sigma": sigma, "particles": int(d.size),
                        "d_min_um": float(d.min()), "d_max_um": float(d.max())}
        cut, box_um, table1 = cuts[filler]
        lo, hi = cut.d_lo_um, cut.d_hi_um
        x_max = max(1.5 * hi, float(table1.ppf(0.97)), float(d.max()) * 1.1)
        x = np.linspace(0.02, x_max, 600)
        heights, _, _ = ax.hist(d, bins=np.linspace(lo, hi, 25), density=True, color="C0",
                                alpha=0.45, label=f"packed RVEs ({d.size} particles)")
        inside = (x >= lo) & (x <= hi)
        kept = float(table1.cdf(hi) - table1.cdf(lo))
        ax.plot(x[inside], table1.pdf(x[inside]) / kept, "k-", lw=1.6,
                label=f"Table 1, cut to {lo:.1f}–{hi:.1f} {MICRO_M} and renormalised\n"
                      "(what the RVEs draw: compare with the histogram)")
        ax.plot(x, table1.pdf(x), color="0.35", ls="--", lw=1.2,
                label=f"Table 1, uncut ($\\mu$ = {table1.mu:g}, $\\sigma$ = {table1.sigma:g})")
        ax.plot(x, LogNormalPSD(mu, sigma).pdf(x), color="C3", ls=":", lw=1.6,
                label=f"parent fitted to the packed diameters\n(truncated ML: $\\mu$ = "
                      f"{mu:.2f}, $\\sigma$ = {sigma:.2f})")
        ax.axvspan(hi, x_max, color="0.6", alpha=0.25, hatch="//", lw=0,
                   label=f"cut off {'by the box ' if cut.box_limited else ''}"
                         f"(> {hi:.1f} {MICRO_M})")
        ax.set_xlim(0.0, x_max)
        top = max(float(np.max(heights)), float(np.max(table1.pdf(x[inside]))) / kept)
        ax.set_ylim(0.0, 1.55 * top)              # room for the legend above the data
        ax.text(0.97, 0.55, box_cut_text(filler, cut, box_um), transform=ax.transAxes,
                ha="right", va="top", fontsize=8,
                bbox={"boxstyle": "round", "facecolor": "white", "edgecolor": "0.5"})
        ax.set_xlabel(f"particle diameter D ({MICRO_M})")
        ax.set_ylabel(f"number density (1/{MICRO_M})")
        ax.set_title(phase_label(filler))
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return _save(fig, path), fits


def rve_figure(ident: Identification, names: Sequence[str], path: Path) -> Path:
    """Fig. 4 analogue: off-screen renders of the first replica of ``names``."""
    import tempfile

    from itr_fv.output.particle_render import render_particles

    plt = _pyplot()
    names = [n for n in names if n in ident.models]
    fig, axes = plt.subplots(1, len(names), figsize=(5.2 * len(names), 5.4), squeeze=False,
                             layout="constrained")
    with tempfile.TemporaryDirectory() as tmp:
        for i, (ax, name) in enumerate(zip(axes[0], names)):
            png = Path(tmp) / f"rve{i}.png"
            ms = ident.models[name].microstructures[0]
            # the render draws the three box edges as axes (ticks and titles in µm)
            render_particles(ms, str(png), colors={"Al2O3": "red", "AlN": "blue"},
                             window_size=(700, 700))
            ax.imshow(_trim_white(plt.imread(png)))
            ax.set_title(f"{name} ({len(ms.particles)} particles)", fontsize=12)
            ax.axis("off")
    return _save(fig, path)


def _trim_white(image: np.ndarray, pad: int = 6) -> np.ndarray:
    """An RGB(A) image without its white border (``pad`` pixels kept)."""
    ink = np.any(image[..., :3] < 0.98, axis=-1)
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    if rows.size == 0:
        return image
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, image.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, image.shape[1])
    return image[r0:r1, c0:c1]


def surrogate_check(validation: Mapping[str, list[dict]],
                    idents: Mapping[str, Identification]) -> dict[str, list[dict]]:
    """Per parametrisation and formulation with a reduced basis: the full solve of the first
    replica at the identified values and its reduced basis's k_iso with the certified
    bounds, all raw (the cheap RVE's own numbers, no replica or level factor), W/(m K);
    ``inside``: the full solve lies within the bounds (to 1e-6 relative)."""
    out: dict[str, list[dict]] = {}
    for par, rows in validation.items():
        ident = idents[par]
        out[par] = []
        for row in rows:
            m = ident.models[row["formulation"]]
            if m.rb is None:
                continue
            k, lo, hi = m.first_replica_k({p: ident.quoted[p] for p in m.parameters})
            full = row["replica_k_iso_raw"][0]
            out[par].append({"formulation": row["formulation"], "full_solve": full,
                             "reduced_basis": k, "lower": lo, "upper": hi,
                             "inside": bool(lo * (1 - 1e-6) <= full <= hi * (1 + 1e-6))})
    return out


def parity_figure(validation: Mapping[str, list[dict]], idents: Mapping[str, Identification],
                  path: Path) -> Path:
    """Fig. 6 analogue. Left: the reduced basis of the first replica against the full solve
    of the same replica at the identified values, both raw (the cheap RVE's own k, no level
    factor), with the reduced basis's certified bounds as error bars (the surrogate's own
    error; formulations held at fixed values have no reduced basis and are left out).
    Right: predictions at the fidelity level (replica means times the level's factor)
    against measurements, with the paper's Table 6 and ±10 % lines."""
    plt = _pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.8))
    check = surrogate_check(validation, idents)
    level = fidelity_name(next(iter(idents.values())).settings.faithful)
    for par, rows in validation.items():
        pts = check[par]
        a.errorbar([p["full_solve"] for p in pts], [p["reduced_basis"] for p in pts],
                   yerr=[[max(p["reduced_basis"] - p["lower"], 0.0) for p in pts],
                         [max(p["upper"] - p["reduced_basis"], 0.0) for p in pts]],
                   fmt="o", capsize=2, label=f"{par} ({len(pts)} formulations)")
        corrected = any(r["level"] != "none" for r in rows)
        b.errorbar([r["measured"] for r in rows], [r["predicted"] for r in rows],
                   xerr=[r["measured_se"] for r in rows], yerr=[r["predicted_sd"] for r in rows],
                   fmt="o", label=f"ours ({par}, " + (f"at fidelity {level})" if corrected
                                                        else "raw: not corrected)"))
    table6 = paper_data.paper_validation()
    b.plot([v[0] for v in table6.values()], [v[1] for v in table6.values()], "k^",
           label="paper (Table 6)")
    for ax, (xl, yl, title) in zip((a, b), (
            ("full solve, replica 1, raw (W/(m K))", "reduced basis, replica 1, raw (W/(m K))",
             "surrogate against the full solver (cheap RVE, bounds as bars)"),
            ("measured mean (W/(m K))", "predicted (W/(m K))", "predictions (Table 6)"))):
        lim = [min(ax.get_xlim()[0], ax.get_ylim()[0]), max(ax.get_xlim()[1], ax.get_ylim()[1])]
        ax.plot(lim, lim, "k:", lw=1, label="equal")
        if ax is b:
            ax.plot(lim, [0.9 * x for x in lim], "k--", lw=0.6, label="±10 %")
            ax.plot(lim, [1.1 * x for x in lim], "k--", lw=0.6)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def screening_figure(idents: Mapping[str, Identification], path: Path) -> Path:
    """Fig. 8 analogue: cumulative frequency of Eq. 4's delta per system, lowest 1 % marked.

    Each screening series has its own colour and line style (the same in every panel for a
    parametrisation); its threshold (the delta of its lowest 1 %) is a dotted vertical line
    in its colour, and the legend names both."""
    plt = _pyplot()
    systems = sorted({s.system for i in idents.values() for s in i.screening},
                     key=lambda s: (len(s), s))
    fig, axes = plt.subplots(1, len(systems), figsize=(5.2 * len(systems), 4.2),
                             squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ["-", "--", "-.", (0, (5, 1, 1, 1, 1, 1))]
    for ax, system in zip(axes[0], systems):
        for j, (par, ident) in enumerate(idents.items()):
            for m, s in enumerate(t for t in ident.screening if t.system == system):
                n = j + len(idents) * m        # the same series index in every panel
                colour, style = colours[n % len(colours)], styles[n % len(styles)]
                d, c = s.cumulative_frequency()
                what = ", ".join(map(parameter_symbol, s.names)) or "no new parameter"
                ax.plot(d, 100 * c, color=colour, ls=style, lw=1.6, label=f"{par}: {what}")
                cut = float(np.quantile(s.delta, s.quantile))
                ax.axvline(cut, color=colour, ls=":", lw=1.4,
                           label=f"{par}: lowest {100 * s.quantile:g} % below "
                                 f"$\\delta$ = {cut:.3g}")
        ax.axhline(100 * 0.01, color="k", lw=0.8, label="1 % cumulative frequency")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(_null_formatter())
        ax.set_xlabel("$\\delta$ of Eq. 4 (W/(m K))")
        ax.set_ylabel("cumulative frequency (%)")
        ax.set_title(phase_label("+".join(system)))
        ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def _include(lim: tuple[float, float], values: Sequence[float], margin: float = 0.06
             ) -> tuple[float, float]:
    """Axis limits ``lim`` widened so that every value lies inside with ``margin`` (a
    fraction of the span) to spare: a marker on the edge is drawn whole."""
    lo, hi = lim
    pad = margin * (hi - lo)
    vals = [v for v in values if v is not None and np.isfinite(v)]
    if vals:
        lo, hi = min(lo, min(vals) - pad), max(hi, max(vals) + pad)
    return lo, hi


def posterior_figure(ident: Identification, path: Path) -> Path:
    """Marginal posterior densities of each calibration stage (2-D maps show which
    combinations the data determine).

    The axis limits hold every marker (best point, the paper's values) with a margin; the
    grey band beyond a map is outside the posterior grid."""
    from matplotlib.patches import Patch
    from matplotlib.patheffects import withStroke

    plt = _pyplot()
    stages = [s for s in ident.posterior.stages if s.parameters]
    fig, axes = plt.subplots(1, len(stages), figsize=(5.0 * len(stages), 4.4), squeeze=False)
    paper = paper_data.paper_parameters()
    paper.update({parameter_name("Rff", a, b): v
                  for (a, b), v in paper_data.paper_resistances().items()
                  if "silicone" not in (a, b)})
    for ax, st in zip(axes[0], stages):
        axes_ = [np.asarray(a) for a in st.axes_log10]
        dens = np.asarray(st.density)
        labels = [parameter_label(p, log10=True) for p in st.parameters]
        marks = [None if paper.get(p) is None else float(np.log10(paper[p]))
                 for p in st.parameters]
        best = [float(np.log10(ident.at_nominal.best[p])) for p in st.parameters]
        if dens.ndim == 2:
            mesh = ax.pcolormesh(axes_[0], axes_[1], dens.T, shading="auto", cmap="viridis")
            fig.colorbar(mesh, ax=ax, label="posterior mass per grid cell")
            ax.set_xlabel(labels[0], fontsize=9)
            ax.set_ylabel(labels[1], fontsize=9)
            ax.plot(best[0], best[1], "w+", ms=11, mew=2.2, label="best (ours)",
                    path_effects=[withStroke(linewidth=4, foreground="k")])
            if all(m is not None for m in marks):
                ax.plot(marks[0], marks[1], "r*", ms=12, mec="k", mew=0.5,
                        label="paper (Table 5)")
            xlim, ylim = ax.get_xlim(), ax.get_ylim()
            new_x = _include(xlim, [best[0], marks[0]])
            new_y = _include(ylim, [best[1], marks[1]])
            ax.set_xlim(new_x)
            ax.set_ylim(new_y)
            handles, names = ax.get_legend_handles_labels()
            if (new_x, new_y) != (xlim, ylim):
                ax.set_facecolor("0.88")
                handles.append(Patch(facecolor="0.88", edgecolor="0.6"))
                names.append("outside the posterior grid")
            ax.legend(handles, names, fontsize=7, loc="best")
        else:
            ax.plot(axes_[0], dens, label="posterior")
            ax.set_xlabel(labels[0], fontsize=9)
            ax.set_ylabel("posterior mass per grid point")
            ax.axvline(best[0], color="k", ls=":", label="best (ours)")
            if marks[0] is not None:
                ax.axvline(marks[0], color="r", ls="--", label="paper (Table 5)")
            ax.set_xlim(_include(ax.get_xlim(), [best[0], marks[0]]))
            ax.legend(fontsize=7, loc="best")
        ax.set_title(f"{ident.parametrisation}: {phase_label('+'.join(st.system))}",
                     fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def alone_figure(ident: Identification, path: Path) -> Path | None:
    """Each single-filler formulation's resistance fitted alone (90 % interval) against its
    filler fraction, with the joint fit's interval as a band; None where no formulation was
    fitted alone."""
    rows = ident.alone
    if not rows:
        return None
    plt = _pyplot()
    params = sorted({r["parameter"] for r in rows})
    fig, axes = plt.subplots(1, len(params), figsize=(4.8 * len(params), 3.8), squeeze=False)
    for ax, p in zip(axes[0], params):
        mine = [r for r in rows if r["parameter"] == p]
        x = np.array([100 * r["fraction"] for r in mine])
        best = np.array([r["best"] for r in mine])
        lo = np.array([r["interval_90"][0] for r in mine])
        hi = np.array([r["interval_90"][1] for r in mine])
        ax.errorbar(x, best, yerr=[np.maximum(best - lo, 0), np.maximum(hi - best, 0)],
                    fmt="o", capsize=4,
                    label="each formulation alone (90 %)")
        joint = ident.at_nominal          # the formulations alone hold the inputs nominal
        jlo, jhi = joint.interval(p)
        ax.axhspan(jlo, jhi, color="C1", alpha=0.25, label="joint fit, nominal inputs (90 %)")
        ax.axhline(joint.best[p], color="C1", lw=1)
        ax.set_yscale("log")
        ax.set_xlabel("filler volume fraction (%)")
        ax.set_ylabel(parameter_label(p))
        ax.set_title(f"{ident.parametrisation}: {p}", fontsize=10)
        ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return _save(fig, path)


def level_caption(k: float, level: Mapping[str, object] | None, name: str, *,
                  sep: str = "; ") -> str:
    """``k`` (W/(m K)) of one cheap RVE said as raw, with its value at the fidelity level
    where ``level`` (:meth:`~itr_identify.forward.model.ForwardModel.level_at`) has a
    factor other than 1 (after ``sep``): the figures' k is the report's, or says it is
    not."""
    text = f"{k:.3f} W/(m K) raw (this RVE)"
    factor = float(level["factor"]) if level else 1.0
    if abs(factor - 1.0) > 1e-12:
        text += (f"{sep}at fidelity {name} (x{factor:.3f}, {level['source']}) "
                 f"{k * factor:.3f} W/(m K)")
    return text


def temperature_figure(result, path: Path, *, level: Mapping[str, object] | None = None,
                       level_name: str = "quick") -> Path:
    """Temperature on the mid-plane normal to z for the first load case (a unit gradient
    along x1: T = -x1 + theta, K for 1 K/m), particle outlines in white; the title gives
    k_11 raw and at the fidelity level (:func:`level_caption`)."""
    plt = _pyplot()
    ms = result.microstructure
    theta = np.asarray(result.theta[0])
    n = theta.shape
    h_um = ms.voxel_m * 1e6
    z = n[2] // 2
    x_m = (np.arange(n[0]) + 0.5) * ms.voxel_m
    T = (-x_m[:, None] + theta[:, :, z]) * 1e6          # uK for 1 K/m: K per m of box
    fig, ax = plt.subplots(figsize=(5.5, 4.6))
    extent = (0, n[0] * h_um, 0, n[1] * h_um)
    im = ax.imshow(T.T, origin="lower", extent=extent, cmap="coolwarm")
    ax.contour((ms.particle_ids[:, :, z] > 0).T.astype(float), levels=[0.5], colors="white",
               linewidths=0.6, extent=extent)
    fig.colorbar(im, ax=ax, label="temperature (µK; unit gradient 1 K/m along $x_1$)")
    ax.set_xlabel(f"$x_1$ ({MICRO_M})")
    ax.set_ylabel(f"$x_2$ ({MICRO_M})")
    ax.set_title(f"mid-plane $x_3$ = {(z + 0.5) * h_um:.1f} {MICRO_M}; $k_{{11}}$ = "
                 + level_caption(float(result.k_eff[0, 0]), level, level_name, sep="\n"),
                 fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def effect_residual_figure(effect_fit, path: Path) -> Path:
    """Each formulation's residual (measured mean - model k) over the sd of a measured mean
    about the model, at the base model's best point and at the named effect's: the gap
    before and after (:class:`~itr_identify.discrepancy.on_identification.EffectFit`)."""
    plt = _pyplot()
    forms = list(effect_fit.residuals)
    rows = np.array([effect_fit.residuals[f] for f in forms])
    mean, k_base, sd_base, k_eff, sd_eff = rows.T
    z0, z1 = (mean - k_base) / sd_base, (mean - k_eff) / sd_eff
    x = np.arange(len(forms))
    fig, ax = plt.subplots(figsize=(max(6.0, 0.55 * len(forms) + 2), 3.6))
    ax.bar(x - 0.2, z0, 0.4, label=f"base model (chi-square {effect_fit.base.chi_square:.1f})",
           color="0.6")
    ax.bar(x + 0.2, z1, 0.4, label=f"with {effect_fit.effect.name} (chi-square "
           f"{effect_fit.effect.chi_square:.1f})", color="tab:blue")
    for y in (-2, 2):
        ax.axhline(y, color="0.3", lw=0.6, ls=":")
    ax.axhline(0, color="0.2", lw=0.8)
    ax.set_xticks(x, forms, rotation=45, ha="right")
    ax.set_ylabel("(measured - model) / sd")
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=130, format="png")
    plt.close(fig)
    return Path(path)
