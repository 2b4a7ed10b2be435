"""Figures of an identification run (analogues of the paper's Figs. 2, 4, 6 and 8).

Every function writes one PNG atomically (matplotlib's Agg backend; the RVE renders use
pyvista off screen) and returns its path.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from itr_fv import paper_data
from itr_fv.io import atomic_path
from itr_fv.parameters import parameter_name
from itr_fv.psd import LogNormalPSD, fit_truncated_sample

from ..inference.pipeline import Identification

__all__ = ["psd_figure", "rve_figure", "parity_figure", "screening_figure",
           "posterior_figure", "packed_diameters", "temperature_figure"]


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
    """Diameters (um) of every packed particle of the single-filler RVEs, per filler."""
    out: dict[str, list] = {}
    for m in ident.models.values():
        if len(m.fractions) != 1:
            continue
        for ms in m.microstructures:
            t = ms.particles
            for mat in np.unique(t.material):
                out.setdefault(str(mat), []).append(2e6 * t.radii_m[t.material == mat])
    return {k: np.concatenate(v) for k, v in out.items()}


def psd_figure(ident: Identification, path: Path) -> tuple[Path, dict]:
    """Fig. 2 analogue: packed diameters against Table 1; returns the path and the fitted
    (mu, sigma) per filler (truncated maximum likelihood, truncation at the drawn extremes)."""
    plt = _pyplot()
    table1 = paper_data.psd_lognormal()
    diam = packed_diameters(ident)
    fig, axes = plt.subplots(1, len(diam), figsize=(5 * len(diam), 3.8), squeeze=False)
    fits = {}
    for ax, (filler, d) in zip(axes[0], sorted(diam.items())):
        mu, sigma = fit_truncated_sample(d, float(d.min()), float(d.max()))
        fits[filler] = {"mu": mu, "sigma": sigma, "particles": int(d.size),
                        "d_min_um": float(d.min()), "d_max_um": float(d.max())}
        x = np.linspace(0.05, max(12.0, float(d.max()) * 1.2), 400)
        ax.hist(d, bins=30, density=True, alpha=0.5, label=f"packed RVEs ({d.size} particles)")
        m1, s1 = table1[filler]
        ax.plot(x, LogNormalPSD(m1, s1).pdf(x), "k-", label=f"Table 1 (mu {m1}, sigma {s1})")
        ax.plot(x, LogNormalPSD(mu, sigma).pdf(x), "r--",
                label=f"fit to packed (mu {mu:.2f}, sigma {sigma:.2f})")
        ax.axvline(float(d.max()), color="grey", ls=":",
                   label=f"largest packed diameter ({d.max():.1f} um: the box cut)")
        ax.set_xlabel("diameter (um)")
        ax.set_ylabel("number density (1/um)")
        ax.set_title(filler)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path), fits


def rve_figure(ident: Identification, names: Sequence[str], path: Path) -> Path:
    """Fig. 4 analogue: off-screen renders of the first replica of ``names``."""
    import tempfile

    from itr_fv.particle_render import render_particles

    plt = _pyplot()
    names = [n for n in names if n in ident.models]
    fig, axes = plt.subplots(1, len(names), figsize=(4.6 * len(names), 4.8), squeeze=False)
    with tempfile.TemporaryDirectory() as tmp:
        for i, (ax, name) in enumerate(zip(axes[0], names)):
            png = Path(tmp) / f"rve{i}.png"
            ms = ident.models[name].microstructures[0]
            render_particles(ms, str(png), colors={"Al2O3": "red", "AlN": "blue"},
                             window_size=(700, 700))
            ax.imshow(plt.imread(png))
            ax.set_title(f"{name} ({len(ms.particles)} particles)", fontsize=10)
            ax.axis("off")
    fig.tight_layout()
    return _save(fig, path)


def parity_figure(validation: Mapping[str, list[dict]], idents: Mapping[str, Identification],
                  path: Path) -> Path:
    """Fig. 6 analogue. Left: the reduced basis of the first replica against the full solve
    of the same replica at the identified values (the surrogate's own error; formulations
    held at fixed values have no reduced basis and are left out). Right: predictions
    (replica means, with the faithful correction where there is one) against measurements,
    with the paper's Table 6 and +-10 % lines."""
    plt = _pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.8))
    for par, rows in validation.items():
        ident = idents[par]
        full, rb = [], []
        for row in rows:
            m = ident.models[row["formulation"]]
            if m.rb is None:
                continue
            k = m.first_replica_k({p: ident.posterior.best[p] for p in m.parameters})
            full.append(row["replica_k_iso"][0])
            rb.append(k)
        a.plot(full, rb, "o", label=f"{par} ({len(rb)} formulations)")
        b.errorbar([r["measured"] for r in rows], [r["predicted"] for r in rows],
                   xerr=[r["measured_se"] for r in rows], yerr=[r["predicted_sd"] for r in rows],
                   fmt="o", label=f"ours ({par})")
    table6 = paper_data.paper_validation()
    b.plot([v[0] for v in table6.values()], [v[1] for v in table6.values()], "k^",
           label="paper (Table 6)")
    for ax, (xl, yl, title) in zip((a, b), (
            ("full solve, replica 1 (W/(m K))", "reduced basis, replica 1 (W/(m K))",
             "surrogate against the full solver"),
            ("measured mean (W/(m K))", "predicted (W/(m K))", "predictions (Table 6)"))):
        lim = [min(ax.get_xlim()[0], ax.get_ylim()[0]), max(ax.get_xlim()[1], ax.get_ylim()[1])]
        ax.plot(lim, lim, "k:", lw=1, label="equal")
        if ax is b:
            ax.plot(lim, [0.9 * x for x in lim], "k--", lw=0.6, label="+-10 %")
            ax.plot(lim, [1.1 * x for x in lim], "k--", lw=0.6)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def screening_figure(idents: Mapping[str, Identification], path: Path) -> Path:
    """Fig. 8 analogue: cumulative frequency of Eq. 4's delta per system, lowest 1 % marked."""
    plt = _pyplot()
    systems = sorted({s.system for i in idents.values() for s in i.screening},
                     key=lambda s: (len(s), s))
    fig, axes = plt.subplots(1, len(systems), figsize=(4.5 * len(systems), 3.8), squeeze=False)
    for ax, system in zip(axes[0], systems):
        for par, ident in idents.items():
            for s in ident.screening:
                if s.system == system:
                    d, c = s.cumulative_frequency()
                    ax.plot(d, 100 * c, label=f"{par}: {', '.join(s.names)}")
                    ax.axvline(np.quantile(s.delta, s.quantile), ls=":", lw=1)
        ax.axhline(1.0, color="k", lw=0.8, label="lowest 1 % (dotted: its delta)")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(_null_formatter())
        ax.set_xlabel("delta of Eq. 4 (W/(m K))")
        ax.set_ylabel("cumulative frequency (%)")
        ax.set_title("+".join(system))
        ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, path)


def posterior_figure(ident: Identification, path: Path) -> Path:
    """Marginal posterior densities of each calibration stage (2-D maps show which
    combinations the data determine)."""
    plt = _pyplot()
    stages = [s for s in ident.posterior.stages if s.parameters]
    fig, axes = plt.subplots(1, len(stages), figsize=(4.5 * len(stages), 4), squeeze=False)
    paper = paper_data.paper_parameters()
    paper.update({parameter_name("Rff", a, b): v
                  for (a, b), v in paper_data.paper_resistances().items()
                  if "silicone" not in (a, b)})
    for ax, st in zip(axes[0], stages):
        axes_ = [np.asarray(a) for a in st.axes_log10]
        dens = np.asarray(st.density)
        labels = [f"log10 {p} (R in m^2 K/W)" for p in st.parameters]
        marks = [paper.get(p) for p in st.parameters]
        best = [ident.posterior.best[p] for p in st.parameters]
        if dens.ndim == 2:
            mesh = ax.pcolormesh(axes_[0], axes_[1], dens.T, shading="auto", cmap="viridis")
            fig.colorbar(mesh, ax=ax, label="posterior mass per grid cell")
            ax.set_xlabel(labels[0], fontsize=8)
            ax.set_ylabel(labels[1], fontsize=8)
            ax.plot(np.log10(best[0]), np.log10(best[1]), "w+", ms=10, mew=2,
                    label="best (ours)")
            if all(m is not None for m in marks):
                ax.plot(np.log10(marks[0]), np.log10(marks[1]), "r*", ms=12,
                        label="paper (Table 5)")
        else:
            ax.plot(axes_[0], dens, label="posterior")
            ax.set_xlabel(labels[0], fontsize=8)
            ax.set_ylabel("posterior mass per grid point")
            ax.axvline(np.log10(best[0]), color="k", ls=":", label="best (ours)")
            if marks[0] is not None:
                ax.axvline(np.log10(marks[0]), color="r", ls="--", label="paper (Table 5)")
        ax.legend(fontsize=7, loc="best")
        ax.set_title(f"{ident.parametrisation}: {'+'.join(st.system)}", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def temperature_figure(result, path: Path) -> Path:
    """Temperature on the mid-plane normal to z for the first load case (a unit gradient
    along x1: T = -x1 + theta, K for 1 K/m), particle outlines in white."""
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
    fig.colorbar(im, ax=ax, label="temperature (uK, unit gradient 1 K/m along x1)")
    ax.set_xlabel("x1 (um)")
    ax.set_ylabel("x2 (um)")
    ax.set_title(f"mid-plane x3 = {(z + 0.5) * h_um:.1f} um; k_11 = {result.k_eff[0, 0]:.3f} "
                 "W/(m K)", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
