"""Discrepancy workflow: where the calibrated model misses the measurements, and why.

1. **Forward tables.** Per single-filler formulation, one RVE (the first replica of
   :class:`identify.forward.ForwardModel`, gap contact model) is solved with the full solver
   on a grid of the filler-matrix resistance ``R_<f>_silicone`` for the base model and, for
   every candidate of :mod:`identify.effects`, on that grid times the candidate's parameter
   grid. The other replicas, solved at one resistance, give the RVE-to-RVE scatter and
   scale the first replica to the replica mean (as :mod:`identify.forward`).
2. **Calibration of each model** (base: one ``R`` per filler; candidate: those plus the
   effect's parameter) on a fine grid (cubic interpolation of ``ln k`` between the solved
   points, no extrapolation), Gaussian likelihood per measurement group (a formulation, or
   a formulation at one sample thickness): replicate error ``s / sqrt(n)`` (``s`` pooled
   over a filler's formulations, :func:`groups_of`) and one RVE error ``sigma_rve k``
   shared by a formulation's groups (:func:`_gaussian_shared`).
3. **Disagreement.** The base model's chi-square against its degrees of freedom (p-value),
   standardised residuals per group and their structure: trend with the filler fraction
   per filler, offset between fillers, trend with the thickness.
4. **Selection.** Candidates ranked by BIC, ``-2 ln L_max + p ln n``. One is *named* when
   it lowers the BIC by :attr:`DiscrepancySettings.bic_margin` or more, leaves no
   significant residual and needs no resistance at the edge of its range; two within
   :attr:`DiscrepancySettings.tie_margin` of each other are reported as a *tie* with the
   measurement that separates them; a significant base residual that no candidate removes
   is an *unexplained* discrepancy.

Two-filler formulations are left out (their forward table would need a grid over both
resistances); the report lists them.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats
from scipy.interpolate import RegularGridInterpolator
from scipy.special import logsumexp

from itr_fv import Materials
from itr_fv.parameters import parameter_name
from itr_fv.problem import DiscreteProblem

from .effects import Effect, default_effects
from .forward import MATRIX, PARAMETRISATIONS, ForwardModel, ForwardSettings, full_solve
from .measurements import Measurements

__all__ = ["DiscrepancySettings", "Group", "ModelFit", "Discrepancy", "ForwardTables",
           "build_tables", "find_discrepancy", "synthetic_measurements", "groups_of",
           "fit_model", "residual_structure", "n_solves", "paper_noise"]


@dataclass(frozen=True)
class DiscrepancySettings:
    """Settings of the workflow.

    Attributes
    ----------
    forward : ForwardSettings
        RVE box, voxel, replicas, packing seed, solver tolerance.
    r_grid_m2K_per_W : tuple of float
        Resistances solved per formulation, m^2 K/W (log spaced; also the prior range).
    r_scatter_m2K_per_W : float
        Resistance at which every replica is solved (RVE scatter, replica factor).
    fine_points : int
        Points of the calibration grid per axis.
    bic_margin : float
        BIC decrease over the base model that names an effect.
    tie_margin : float
        BIC difference under which two candidates explain the data equally well.
    significance : float
        p-value of the chi-square test under which a residual is significant.
    """

    forward: ForwardSettings = field(default_factory=lambda: ForwardSettings(
        box_um=12.0, voxel_um=0.5, replicas=3))
    r_grid_m2K_per_W: tuple[float, ...] = tuple(float(x) for x in np.logspace(-9, -6, 7))
    r_scatter_m2K_per_W: float = 3e-8
    fine_points: int = 121
    bic_margin: float = 6.0
    tie_margin: float = 2.0
    significance: float = 0.01

    def __post_init__(self) -> None:
        r = np.asarray(self.r_grid_m2K_per_W, dtype=float)
        if r.size < 4 or np.any(np.diff(r) <= 0) or r[0] <= 0:
            raise ValueError("r_grid_m2K_per_W: expected at least 4 increasing resistances "
                             f"> 0 m^2 K/W, got {self.r_grid_m2K_per_W!r}")
        if not isinstance(self.fine_points, int) or self.fine_points < 11:
            raise ValueError(f"fine_points: expected a whole number >= 11, got "
                             f"{self.fine_points!r}")
        for name in ("bic_margin", "tie_margin"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name}: expected >= 0, got {getattr(self, name)!r}")
        if not 0 < self.significance < 1:
            raise ValueError(f"significance: expected a p-value in (0, 1), got "
                             f"{self.significance!r}")


@dataclass(frozen=True)
class Group:
    """Measurements of one formulation at one thickness (``None``: not given)."""

    formulation: str
    filler: str
    fraction: float
    thickness_m: float | None
    mean: float
    standard_error: float
    n: int

    @property
    def label(self) -> str:
        t = "" if self.thickness_m is None else f" @ {self.thickness_m * 1e3:g} mm"
        return self.formulation + t


def groups_of(measurements: Measurements, fractions: dict[str, dict[str, float]], *,
              pool: bool = True) -> list[Group]:
    """Measurement groups of the single-filler formulations: per formulation, or per
    formulation and thickness where the table gives thicknesses.

    The standard error of a group mean comes from the replicate scatter about the group
    means: with ``pool`` (default) as a relative standard deviation pooled over every
    formulation of the same filler (Table 3's four replicates give 3 degrees of freedom
    per formulation, too few for a chi-square test: one sample deviation in ten comes out
    below 0.43 of the true one), else per formulation. A formulation whose thicknesses
    hold one replicate each contributes its scatter across thicknesses.
    """
    rows = []
    for f in measurements.formulations:
        comp = fractions[f]
        if len(comp) != 1:
            continue
        (filler, phi), = comp.items()
        v = measurements.values[f]
        t = (np.zeros(v.size) if measurements.thickness_m is None
             else measurements.thickness_m[f])
        levels = np.unique(t)
        means = {x: float(v[t == x].mean()) for x in levels}
        ss = sum(((v[t == x] / means[x] - 1) ** 2).sum() for x in levels)
        dof = v.size - levels.size
        if dof < 1:
            ss, dof = float(((v / v.mean() - 1) ** 2).sum()), v.size - 1
        rows.append((f, filler, phi, v, t, levels, means, ss, dof))
    pooled = {}
    for fl in {r[1] for r in rows}:
        ss = sum(r[7] for r in rows if r[1] == fl)
        dof = sum(r[8] for r in rows if r[1] == fl)
        pooled[fl] = math.sqrt(ss / dof)
    out = []
    for f, filler, phi, v, t, levels, means, ss, dof in rows:
        rel = pooled[filler] if pool else math.sqrt(ss / dof)
        for x in levels:
            n = int((t == x).sum())
            out.append(Group(f, filler, phi, None if measurements.thickness_m is None
                             else float(x), means[x], rel * means[x] / math.sqrt(n), n))
    return out


@dataclass
class ForwardTables:
    """Full-solver k_iso (W/(m K)) per formulation: ``base[f]`` on the resistance grid and
    ``effect[name][f]`` on resistance x effect-parameter grids, the replica factor and
    RVE scatter per formulation."""

    settings: DiscrepancySettings
    effects: list[Effect]
    base: dict[str, np.ndarray]
    effect: dict[str, dict[str, np.ndarray]]
    replica_factor: dict[str, float]
    rve_scatter: dict[str, float]
    solves: int = 0
    seconds: float = 0.0


def n_solves(n_formulations: int, settings: DiscrepancySettings,
             effects: Sequence[Effect]) -> int:
    """Full solves :func:`build_tables` makes for ``n_formulations`` single-filler ones."""
    cols = 1 + sum(1 for e in effects for v in e.values
                   if e.kind != "measurement" and v != e.nominal)
    return n_formulations * (len(settings.r_grid_m2K_per_W) * cols + settings.forward.replicas)


def _r_name(filler: str) -> str:
    return parameter_name("R", filler, MATRIX)


def build_tables(fractions: dict[str, dict[str, float]], *,
                 settings: DiscrepancySettings | None = None,
                 effects: Sequence[Effect] | None = None,
                 tick: Callable[[], None] | None = None) -> ForwardTables:
    """Solve the forward tables of the single-filler formulations in ``fractions``.

    Parameters
    ----------
    fractions : dict of formulation to {filler: volume fraction}
    settings : DiscrepancySettings, optional
    effects : sequence of Effect, optional
        Default: :func:`identify.effects.default_effects`.
    tick : callable, optional
        Called after every full solve (progress bars).
    """
    settings = settings or DiscrepancySettings()
    effects = list(default_effects() if effects is None else effects)
    t0 = time.perf_counter()
    s = settings.forward
    base, table, factor, scatter = {}, {e.name: {} for e in effects}, {}, {}
    n = 0

    def solve_grid(ms, materials_at: Callable[[float], Materials]) -> np.ndarray:
        """k_iso (W/(m K)) of ``ms`` over the resistance grid; the geometry is built once
        (at 24^3 it costs several times the solve)."""
        nonlocal n
        problem, out = None, []
        for R in settings.r_grid_m2K_per_W:
            mat = materials_at(R)
            problem = problem or DiscreteProblem.for_materials(ms, mat)
            out.append(float(full_solve(problem, mat, s.solver_tol).mean()))
            n += 1
            if tick is not None:
                tick()
        return np.array(out)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for f, comp in fractions.items():
            if len(comp) != 1:
                continue
            (filler, _), = comp.items()
            r_name = _r_name(filler)
            model = ForwardModel(f, comp, PARAMETRISATIONS["gap"], s)
            model.microstructures = [model.pack(r) for r in range(s.replicas)]
            model.replica_k = model.solve_replicas({r_name: settings.r_scatter_m2K_per_W},
                                                   tick, purpose="RVE scatter")
            n += len(model.microstructures)
            factor[f], scatter[f] = model.replica_factor, model.rve_scatter
            ms0 = model.microstructures[0]
            base[f] = solve_grid(ms0, lambda R: model.materials({r_name: R}))
            for e in effects:
                cols = []
                for theta in e.values:
                    if e.kind == "measurement" or theta == e.nominal:
                        cols.append(base[f])
                        continue
                    ms = e.microstructure(ms0, theta, seed=s.seed)
                    cols.append(solve_grid(ms, lambda R: e.materials(
                        model.materials({r_name: R}), theta)))
                table[e.name][f] = np.stack(cols, axis=1)          # (nR, ntheta)
    return ForwardTables(settings, effects, base, table, factor, scatter, n,
                         time.perf_counter() - t0)


@dataclass
class ModelFit:
    """One calibrated model (base or base + one effect).

    Attributes
    ----------
    name : str
        ``"base"`` or the effect's name.
    parameters : dict
        Best values: ``R_<f>_silicone`` (m^2 K/W) and the effect's parameter.
    interval : tuple of float or None
        90 % credible interval of the effect's parameter.
    predicted : ndarray
        Model value per group at the best parameters, W/(m K).
    variance : ndarray
        Likelihood variance per group, (W/(m K))^2.
    log_likelihood, chi_square, bic : float
    n_parameters : int
    """

    name: str
    parameters: dict[str, float]
    interval: tuple[float, float] | None
    predicted: np.ndarray
    variance: np.ndarray
    log_likelihood: float
    chi_square: float
    bic: float
    n_parameters: int
    at_grid_edge: bool = False

    def dof(self, n_groups: int) -> int:
        return max(n_groups - self.n_parameters, 1)


def _fine_axis(e: Effect | None, n: int) -> np.ndarray:
    if e is None:
        return np.zeros(1)
    v = np.asarray(e.values, dtype=float)
    if e.log_scale:
        return np.geomspace(v[0], v[-1], n)
    return np.linspace(v[0], v[-1], n)


def _interp(logr: np.ndarray, theta_axis: np.ndarray, values: np.ndarray, e: Effect | None,
            fine_r: np.ndarray, fine_t: np.ndarray) -> np.ndarray:
    """k on the fine (R, theta) mesh from the solved table: cubic in ``ln k`` over log R;
    over the effect's parameter, cubic for material effects and, for geometry effects, a
    quadratic through the nominal point fitted to the solved values (each value of a
    geometry effect removes or adds particular particles or voids of one RVE, a jitter
    of RVE size that an interpolant through every point would turn into a free parameter
    per formulation)."""
    col = values if values.ndim == 1 else values[:, list(theta_axis).index(e.nominal)
                                                   if e is not None else 0]
    base = np.exp(RegularGridInterpolator((logr,), np.log(col), method="cubic")(
        fine_r[:, None]))
    if values.ndim == 1 or e is None or e.kind == "measurement":
        return np.repeat(base[:, None], fine_t.size, axis=1)
    scale = np.log if e.log_scale else (lambda x: x)
    ax, ft = scale(theta_axis) - scale(e.nominal), scale(fine_t) - scale(e.nominal)
    if e.kind == "geometry":
        rel = np.log(values / col[:, None])                       # (nR, ntheta)
        A = np.stack([ax, ax ** 2], axis=1)
        coef, *_ = np.linalg.lstsq(A, rel.T, rcond=None)          # (2, nR)
        cr = np.stack([RegularGridInterpolator((logr,), c, method="cubic")(fine_r[:, None])
                       for c in coef])                            # (2, fine R)
        return base[:, None] * np.exp(cr[0][:, None] * ft[None, :]
                                      + cr[1][:, None] * ft[None, :] ** 2)
    f = RegularGridInterpolator((logr, ax), np.log(values),
                                method="cubic" if theta_axis.size >= 4 else "linear")
    R, T = np.meshgrid(fine_r, ft, indexing="ij")
    return np.exp(f(np.stack([R.ravel(), T.ravel()], axis=1))).reshape(R.shape)


def _by_formulation(groups: Sequence[Group]) -> dict[str, list[Group]]:
    out: dict[str, list[Group]] = {}
    for g in groups:
        out.setdefault(g.formulation, []).append(g)
    return out


def _gaussian_shared(means: Sequence[float], ks: Sequence[np.ndarray],
                     standard_errors: Sequence[float], scatter: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(log-likelihood, generalised chi-square) of one formulation's groups: independent
    replicate errors ``se_g`` plus one RVE error ``scatter * k`` shared by all its groups
    (the same RVEs model every thickness), i.e. covariance ``D + c c^T`` with
    ``c_g = scatter k_g``, by the Sherman-Morrison formula."""
    srr = scc = src = logd = 0.0
    for m, k, se in zip(means, ks, standard_errors):
        r, c, d = m - k, scatter * k, se ** 2
        srr = srr + r * r / d
        src = src + r * c / d
        scc = scc + c * c / d
        logd = logd + math.log(2 * math.pi * d)
    quad = srr - src ** 2 / (1 + scc)
    return -0.5 * (quad + logd + np.log1p(scc)), quad


def fit_model(tables: ForwardTables, groups: Sequence[Group], effect: Effect | None
              ) -> ModelFit:
    """Calibrate the base model (``effect=None``) or base + ``effect`` on the groups."""
    st = tables.settings
    logr = np.log10(np.asarray(st.r_grid_m2K_per_W))
    fine_r = np.linspace(logr[0], logr[-1], st.fine_points)
    fine_t = _fine_axis(effect, 41)
    fillers = sorted({g.filler for g in groups})
    scatter = {fl: math.sqrt(np.mean([tables.rve_scatter[g.formulation] ** 2
                                      for g in groups if g.filler == fl])) for fl in fillers}
    kmesh = {}

    def model_k(g: Group, i=slice(None), j=slice(None)) -> np.ndarray:
        if g.formulation not in kmesh:
            vals = (tables.base[g.formulation] if effect is None
                    else tables.effect[effect.name][g.formulation])
            kmesh[g.formulation] = tables.replica_factor[g.formulation] * _interp(
                logr, np.asarray(effect.values if effect else [0.0], dtype=float), vals,
                effect, fine_r, fine_t)
        k = kmesh[g.formulation][i, j]
        if effect is not None and g.thickness_m is not None:
            k = effect.apparent(k, g.thickness_m, fine_t[j] if np.ndim(k) == 0
                                else fine_t[None, j])
        return k

    ll = {fl: np.zeros((fine_r.size, fine_t.size)) for fl in fillers}
    for f, members in _by_formulation(groups).items():
        fl = members[0].filler
        ll[fl] = ll[fl] + _gaussian_shared([g.mean for g in members],
                                           [model_k(g) for g in members],
                                           [g.standard_error for g in members],
                                           scatter[fl])[0]
    profile = sum(ll[fl].max(axis=0) for fl in fillers)            # (ntheta,)
    j = int(np.argmax(profile))
    params, pred, var = {}, np.zeros(len(groups)), np.zeros(len(groups))
    best_i = {fl: int(np.argmax(ll[fl][:, j])) for fl in fillers}
    for fl in fillers:
        params[_r_name(fl)] = float(10 ** fine_r[best_i[fl]])
    for i, g in enumerate(groups):
        pred[i] = float(model_k(g, best_i[g.filler], j))
        var[i] = g.standard_error ** 2 + (scatter[g.filler] * pred[i]) ** 2
    interval = None
    edge = any(best_i[fl] in (0, fine_r.size - 1) for fl in fillers)
    if effect is not None:
        params[effect.parameter] = float(fine_t[j])
        # marginal posterior of the effect parameter (uniform on its axis, R log-uniform)
        lm = sum(logsumexp(ll[fl], axis=0) for fl in fillers)
        w = np.exp(lm - lm.max())
        c = np.cumsum(w) / w.sum()
        interval = (float(np.interp(0.05, c, fine_t)), float(np.interp(0.95, c, fine_t)))
    lmax = float(profile[j])
    p = len(fillers) + (effect is not None)
    index = {id(g): i for i, g in enumerate(groups)}
    chi2 = float(sum(_gaussian_shared([g.mean for g in m], [pred[index[id(g)]] for g in m],
                                      [g.standard_error for g in m], scatter[m[0].filler])[1]
                     for m in _by_formulation(groups).values()))
    return ModelFit("base" if effect is None else effect.name, params, interval, pred, var,
                    lmax, chi2, -2 * lmax + p * math.log(len(groups)), p, edge)


@dataclass
class Discrepancy:
    """Outcome of the workflow.

    Attributes
    ----------
    verdict : {"none", "named", "tie", "unexplained"}
    statement : str
        One paragraph: what the data say.
    groups : list of Group
    base : ModelFit
    candidates : list of ModelFit
        Ranked by BIC, best first.
    skipped : dict of str to str
        Candidates not tried, with the reason.
    p_value_base : float
        Chi-square test of the base model's residuals.
    structure : list of str
        The residuals' trends (filler fraction, filler type, thickness).
    left_out : list of str
        Formulations not used (two-filler).
    """

    verdict: str
    statement: str
    groups: list[Group]
    base: ModelFit
    candidates: list[ModelFit]
    skipped: dict[str, str]
    p_value_base: float
    structure: list[str]
    left_out: list[str]
    effects: list[Effect]
    winner: ModelFit | None = None
    tables: ForwardTables | None = None

    def p_value(self, fit: ModelFit) -> float:
        return float(stats.chi2.sf(fit.chi_square, fit.dof(len(self.groups))))

    def chi_square_per_dof(self, fit: ModelFit) -> float:
        return fit.chi_square / fit.dof(len(self.groups))

    def to_dict(self) -> dict:
        def fit_dict(m: ModelFit) -> dict:
            return {"name": m.name, "parameters": m.parameters,
                    "interval_90": list(m.interval) if m.interval else None,
                    "chi_square": m.chi_square, "dof": m.dof(len(self.groups)),
                    "p_value": self.p_value(m), "bic": m.bic,
                    "delta_bic": self.base.bic - m.bic,
                    "predicted": m.predicted.tolist(), "at_grid_edge": m.at_grid_edge}
        return {"verdict": self.verdict, "statement": self.statement,
                "groups": [{"label": g.label, "formulation": g.formulation,
                            "thickness_m": g.thickness_m, "measured": g.mean,
                            "standard_error": g.standard_error, "n": g.n}
                           for g in self.groups],
                "base": fit_dict(self.base), "candidates": [fit_dict(c) for c in self.candidates],
                "skipped": self.skipped, "structure": self.structure,
                "left_out": self.left_out,
                "effects": [e.describe() for e in self.effects]}


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
    th = np.array([g.thickness_m if g.thickness_m is not None else np.nan for g in groups])
    if np.isfinite(th).all() and np.unique(th).size >= 2:
        slope, _, r, p, se = stats.linregress(th * 1e3, z)
        out.append(f"thickness: trend {slope:+.2f} per mm (+-{se:.2f}, p = {p:.2g})")
    return out


def find_discrepancy(measurements: Measurements, *,
                     settings: DiscrepancySettings | None = None,
                     effects: Sequence[Effect] | None = None,
                     tables: ForwardTables | None = None,
                     tick: Callable[[], None] | None = None) -> Discrepancy:
    """Run the workflow on a measurement table.

    Parameters
    ----------
    measurements : Measurements
        Formulation names give the composition (:func:`identify.pipeline.fractions_of`);
        a ``thickness_m`` per replicate enables the thickness covariate.
    settings : DiscrepancySettings, optional
    effects : sequence of Effect, optional
        The candidate library (default :func:`identify.effects.default_effects`).
    tables : ForwardTables, optional
        Forward tables of an earlier call (they do not depend on the measurements); built
        when not given.
    tick : callable, optional
        Called after every full solve.
    """
    from .pipeline import fractions_of

    settings = settings or DiscrepancySettings()
    comps = {f: fractions_of(f) for f in measurements.formulations}
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
    groups = groups_of(measurements, comps)
    base = fit_model(tables, groups, None)
    skipped, fits = {}, []
    have_thickness = all(g.thickness_m is not None for g in groups)
    for e in effects:
        if e.needs_thickness and not (have_thickness
                                      and len({g.thickness_m for g in groups}) >= 2):
            skipped[e.name] = "needs measurements at two thicknesses or more"
            continue
        fits.append(fit_model(tables, groups, e))
    fits.sort(key=lambda m: m.bic)
    out = Discrepancy("none", "", groups, base, fits, skipped,
                      float(stats.chi2.sf(base.chi_square, base.dof(len(groups)))),
                      residual_structure(groups, base), left_out, effects, None, tables)
    _decide(out, settings)
    return out


def _decide(d: Discrepancy, st: DiscrepancySettings) -> None:
    n = len(d.groups)
    significant = d.p_value_base < st.significance
    base_line = (f"Base model: chi-square {d.base.chi_square:.1f} on {d.base.dof(n)} degrees "
                 f"of freedom (p = {d.p_value_base:.2g}): the residuals are "
                 f"{'significant' if significant else 'consistent with the noise'}.")
    supported = [m for m in d.candidates if d.base.bic - m.bic >= st.bic_margin]
    edge = [m.name for m in supported if m.at_grid_edge]
    supported = [m for m in supported if not m.at_grid_edge]
    if edge:
        base_line += (f" Lowering the BIC by {st.bic_margin:g} or more only with a resistance "
                      f"at the edge of its range, hence not named: {', '.join(edge)}.")
    if not supported:
        d.verdict = "unexplained" if significant else "none"
        if significant:
            best = d.candidates[0] if d.candidates else None
            near = (f" The closest candidate, {best.name}, lowers the BIC by "
                    f"{d.base.bic - best.bic:.1f} (< {st.bic_margin:g})." if best else "")
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


def paper_noise(filler: str) -> float:
    """Root-mean-square replicate standard deviation of Table 3's single-filler
    formulations of ``filler``, W/(m K)."""
    from .measurements import read_measurements
    from .pipeline import fractions_of

    t3 = read_measurements()
    var = [t3.variance(f) for f in t3.formulations if list(fractions_of(f)) == [filler]]
    if not var:
        raise ValueError(f"filler: Table 3 has no single-filler formulation of {filler!r}")
    return float(math.sqrt(np.mean(var)))


def synthetic_measurements(formulations: Sequence[str], resistances: dict[str, float], *,
                           effect: Effect | None = None, value: float | None = None,
                           settings: ForwardSettings | None = None, rves: int = 2,
                           rve_seed: int = 500, replicates: int = 4,
                           noise_sd: float | None = None,
                           thickness_mm: Sequence[float] | None = None,
                           modify: Callable | None = None,
                           extra: Sequence[tuple[Effect, float]] = (),
                           seed: int = 0) -> Measurements:
    """Measurements made with the full solver: every formulation solved on ``rves`` RVEs
    (packing seeds from ``rve_seed``, none of the forward models' own) with ``effect`` at
    ``value`` switched on, averaged, read through the effect's tester model at each
    thickness, plus Gaussian replicate noise of relative standard deviation
    ``relative_sd``.

    Parameters
    ----------
    formulations : names (``<filler>-<vol%>`` or Table 2)
    resistances : dict
        ``R_<f>_silicone`` values, m^2 K/W.
    effect, value : the hidden effect and its parameter (None: noise only).
    modify : callable, optional
        ``modify(microstructure, seed) -> microstructure``: a change outside the library
        (e.g. a particle shape) applied to every RVE.
    extra : sequence of (Effect, value)
        Further material or geometry effects switched on together with ``effect`` (a
        combination the library holds only one at a time).
    thickness_mm : sequence of float, optional
        Replicates cycle through these thicknesses (then the table has a thickness).
    seed : int
        Seed of the noise.
    """
    from .pipeline import fractions_of

    if (effect is None) != (value is None):
        raise ValueError("value: give an effect and its value together")
    s = settings or DiscrepancySettings().forward
    rng = np.random.default_rng(seed)
    if noise_sd is not None and not noise_sd >= 0:
        raise ValueError(f"noise_sd: expected >= 0 W/(m K), got {noise_sd!r}")
    values, thick = {}, {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for f in formulations:
            comp = fractions_of(f)
            model = ForwardModel(f, comp, PARAMETRISATIONS["gap"], s.with_(seed=rve_seed))
            mat = model.materials({p: resistances[p] for p in model.parameters})
            ks = []
            for r in range(rves):
                ms = model.pack(r)
                if modify is not None:
                    ms = modify(ms, rve_seed + r)
                m = mat
                for e, v in ([(effect, value)] if effect is not None else []) + list(extra):
                    ms = e.microstructure(ms, v, seed=rve_seed + r)
                    m = e.materials(m, v)
                ks.append(full_solve(ms, m, s.solver_tol).mean())
            k = float(np.mean(ks))
            t = (np.resize(np.asarray(thickness_mm, dtype=float), replicates) * 1e-3
                 if thickness_mm is not None else None)
            k_app = (effect.apparent(np.full(replicates, k), t, value)
                     if effect is not None and t is not None else np.full(replicates, k))
            sd = paper_noise(next(iter(comp))) if noise_sd is None else noise_sd
            values[f] = k_app + sd * rng.standard_normal(replicates)
            if t is not None:
                thick[f] = t
    what = ", ".join(f"{e.name} = {v:g}" for e, v in
                     ([(effect, value)] if effect is not None else []) + list(extra))
    what = what or "noise only"
    return Measurements(values, f"synthetic ({what})", thick or None)
