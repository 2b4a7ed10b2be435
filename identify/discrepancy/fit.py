"""Calibration of the base model and of each candidate on the measurement groups: cubic
interpolation of ``ln k`` between the solved points of the forward tables, Gaussian
likelihood per measurement group with replicate error ``s / sqrt(n)`` (``s`` pooled over a
filler's formulations, :func:`groups_of`) and one RVE error shared by a formulation's
groups (:func:`_gaussian_shared`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from ..inference.measurements import Measurements
from .effects import Effect
from .tables import ForwardTables, resistance_name

__all__ = ["Group", "groups_of", "ModelFit", "fit_model", "profile_interval", "pooled_scatter"]


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
class ModelFit:
    """One calibrated model (base or base + one effect).

    Attributes
    ----------
    name : str
        ``"base"`` or the effect's name.
    parameters : dict
        Best values: ``R_<f>_silicone`` (m^2 K/W) and the effect's parameter.
    interval : tuple of float or None
        90 % likelihood-ratio interval of the effect's parameter (profiled over the
        resistances; :func:`profile_interval`): it contains the best value.
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
    if values.ndim == 1 or e is None or not e.solved:
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


#: Half the 90 % quantile of chi-square with one degree of freedom: the drop of the profile
#: log-likelihood that bounds a 90 % likelihood-ratio interval.
LR_DROP_90 = 0.5 * 2.705543454095404


def profile_interval(profile: np.ndarray, axis: np.ndarray, drop: float = LR_DROP_90
                     ) -> tuple[float, float]:
    """90 % likelihood-ratio interval of a parameter from its profile log-likelihood.

    The values whose profile lies within ``drop`` of the maximum, from the outermost such
    grid points, with linear interpolation to the crossing where the profile falls below
    the cut between two grid points; an end of the axis bounds the interval where the
    profile is still above the cut there. The maximum, the reported best value, is inside
    by construction (a credible interval from the marginal posterior need not contain the
    profile's maximum: 1.0 outside [0.931, 0.996] was seen).

    Parameters
    ----------
    profile : ndarray, shape (n,)
        Profile log-likelihood on ``axis``.
    axis : ndarray, shape (n,)
        The parameter's values, increasing.
    drop : float
        Log-likelihood drop that bounds the interval (default: 90 %, one parameter).
    """
    profile = np.asarray(profile, dtype=float)
    axis = np.asarray(axis, dtype=float)
    cut = float(profile.max()) - drop
    inside = np.flatnonzero(profile >= cut)
    a, b = int(inside[0]), int(inside[-1])

    def crossing(out: int, inn: int) -> float:
        f = (cut - profile[out]) / (profile[inn] - profile[out])
        return float(axis[out] + f * (axis[inn] - axis[out]))

    lo = float(axis[a]) if a == 0 else crossing(a - 1, a)
    hi = float(axis[b]) if b == axis.size - 1 else crossing(b + 1, b)
    return lo, hi


def pooled_scatter(tables: ForwardTables, groups: Sequence[Group]) -> dict[str, float]:
    """Per filler, the root-mean-square relative model uncertainty (RVE scatter and faithful
    correction) of the formulations of ``groups``."""
    return {fl: math.sqrt(np.mean([tables.relative_sd(g.formulation) ** 2
                                   for g in groups if g.filler == fl]))
            for fl in sorted({g.filler for g in groups})}


def _fraction_slopes(where: dict[str, tuple[str, float]], k: dict[str, np.ndarray]
                     ) -> dict[str, np.ndarray]:
    """``d ln k / d phi`` of the model at each formulation over the resistance axis: per
    filler, a polynomial in phi (degree up to 2, below the number of its formulations)
    through ``ln k`` of its formulations, differentiated at each; 0 for a filler with one
    formulation. ``where[f] = (filler, phi)``, ``k[f]`` the model on the resistance axis."""
    out = {}
    for fl in {w[0] for w in where.values()}:
        fs = [f for f in where if where[f][0] == fl]
        phi = np.array([where[f][1] for f in fs])
        deg = min(2, np.unique(phi).size - 1)
        if deg < 1:
            out.update({f: np.zeros_like(k[f]) for f in fs})
            continue
        coef = np.polyfit(phi, np.log(np.array([k[f] for f in fs])), deg)   # (deg+1, nR)
        for f, x in zip(fs, phi):
            out[f] = sum(c * p * x ** (p - 1) for c, p in zip(coef, range(deg, 0, -1)))
    return out


def fit_model(tables: ForwardTables, groups: Sequence[Group], effect: Effect | None
              ) -> ModelFit:
    """Calibrate the base model (``effect=None``) or base + ``effect`` on the groups."""
    st = tables.settings
    logr = np.log10(np.asarray(st.r_grid_m2K_per_W))
    fine_r = np.linspace(logr[0], logr[-1], st.fine_points)
    fine_t = _fine_axis(effect, 41)
    fillers = sorted({g.filler for g in groups})
    scatter = pooled_scatter(tables, groups)
    kmesh = {}

    def model_k(g: Group, i=slice(None), j=slice(None)) -> np.ndarray:
        if g.formulation not in kmesh:
            vals = (tables.base[g.formulation] if effect is None or not effect.solved
                    else tables.effect[effect.name][g.formulation])
            kmesh[g.formulation] = tables.level(g.formulation) * _interp(
                logr, np.asarray(effect.values if effect else [0.0], dtype=float), vals,
                effect, fine_r, fine_t)
        k = kmesh[g.formulation][i, j]
        if effect is not None and g.thickness_m is not None:
            k = effect.apparent(k, g.thickness_m, fine_t[j] if np.ndim(k) == 0
                                else fine_t[None, j])
        return k

    forms = _by_formulation(groups)
    slopes = _fraction_slopes({f: (m[0].filler, m[0].fraction) for f, m in forms.items()},
                              {f: model_k(m[0])[:, 0] for f, m in forms.items()})

    def shared_sd(f: str, fl: str, i=slice(None), j=slice(None)) -> np.ndarray:
        """Relative sd of the error shared by a formulation's groups on the (R, theta)
        mesh: the RVE scatter and, for a variance effect, the effect's share."""
        if effect is None:
            return np.asarray(scatter[fl])
        extra = effect.formulation_sd(slopes[f][i, None] if np.ndim(slopes[f][i])
                                      else slopes[f][i], fine_t[j])
        return np.sqrt(scatter[fl] ** 2 + extra ** 2)

    ll = {fl: np.zeros((fine_r.size, fine_t.size)) for fl in fillers}
    for f, members in forms.items():
        fl = members[0].filler
        ll[fl] = ll[fl] + _gaussian_shared([g.mean for g in members],
                                           [model_k(g) for g in members],
                                           [g.standard_error for g in members],
                                           shared_sd(f, fl))[0]
    profile = sum(ll[fl].max(axis=0) for fl in fillers)            # (ntheta,)
    j = int(np.argmax(profile))
    params, pred, var = {}, np.zeros(len(groups)), np.zeros(len(groups))
    best_i = {fl: int(np.argmax(ll[fl][:, j])) for fl in fillers}
    for fl in fillers:
        params[resistance_name(fl)] = float(10 ** fine_r[best_i[fl]])
    sd_best = {f: float(shared_sd(f, m[0].filler, best_i[m[0].filler], j))
               for f, m in forms.items()}
    for i, g in enumerate(groups):
        pred[i] = float(model_k(g, best_i[g.filler], j))
        var[i] = g.standard_error ** 2 + (sd_best[g.formulation] * pred[i]) ** 2
    interval = None
    edge = any(best_i[fl] in (0, fine_r.size - 1) for fl in fillers)
    if effect is not None:
        params[effect.parameter] = float(fine_t[j])
        interval = profile_interval(profile, fine_t)
    lmax = float(profile[j])
    p = len(fillers) + (effect is not None)
    index = {id(g): i for i, g in enumerate(groups)}
    chi2 = float(sum(_gaussian_shared([g.mean for g in m], [pred[index[id(g)]] for g in m],
                                      [g.standard_error for g in m], sd_best[f])[1]
                     for f, m in forms.items()))
    return ModelFit("base" if effect is None else effect.name, params, interval, pred, var,
                    lmax, chi2, -2 * lmax + p * math.log(len(groups)), p, edge)
