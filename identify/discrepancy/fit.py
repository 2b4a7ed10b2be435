"""Calibration of the base model and of each candidate on the measurement groups: cubic
interpolation of ``ln k`` between the solved points of the forward tables, Gaussian
likelihood per measurement group with replicate error ``s / sqrt(n)`` (``s`` pooled over a
filler's formulations, :func:`groups_of`) and one RVE error shared by a formulation's
groups (:func:`_gaussian_shared`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import RegularGridInterpolator
from scipy.special import logsumexp

from itr_fv.materials.material_system import MaterialSystem

from ..inference.measurements import Measurements
from ..inference.plausibility import powder_scale
from .effects import Effect
from .observables import AuxGroup, fraction_derivatives, predict
from .tables import ForwardTables, resistance_name

__all__ = ["Group", "ModelFit", "evaluate", "fit_held_at", "fit_model", "fit_physical",
           "fit_present", "groups_of", "pooled_scatter", "profile_interval"]


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
    scale: float = 1.0

    @property
    def label(self) -> str:
        t = "" if self.thickness_m is None else f" @ {self.thickness_m * 1e3:g} mm"
        p = "" if self.scale == 1.0 else f" (powder x{self.scale:.3g})"
        return self.formulation + p + t


def groups_of(measurements: Measurements, fractions: dict[str, dict[str, float]], *,
              system: MaterialSystem, pool: bool = True) -> list[Group]:
    """Measurement groups of the single-filler formulations: per formulation, or per
    formulation and thickness where the table gives thicknesses, and per powder where it
    gives a ``d50_um`` (the powder's median over the material system's is the group's
    :attr:`Group.scale`).

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
        d50 = measurements.auxiliary_of("d50_um", f)
        scale = (np.ones(v.size) if d50 is None else
                 np.array([1.0 if not np.isfinite(x) else powder_scale(f, x, system)
                           for x in d50]))
        key = np.array([hash((a, b)) for a, b in zip(t, scale)])
        levels = [(float(t[key == u][0]), float(scale[key == u][0])) for u in
                  dict.fromkeys(key)]
        sel = {x: (t == x[0]) & (scale == x[1]) for x in levels}
        means = {x: float(v[sel[x]].mean()) for x in levels}
        ss = sum(((v[sel[x]] / means[x] - 1) ** 2).sum() for x in levels)
        dof = v.size - len(levels)
        if dof < 1:
            ss, dof = float(((v / v.mean() - 1) ** 2).sum()), v.size - 1
        rows.append((f, filler, phi, v, sel, levels, means, ss, dof))
    pooled = {}
    for fl in {r[1] for r in rows}:
        ss = sum(r[7] for r in rows if r[1] == fl)
        dof = sum(r[8] for r in rows if r[1] == fl)
        pooled[fl] = math.sqrt(ss / dof)
    out = []
    for f, filler, phi, v, sel, levels, means, ss, dof in rows:
        rel = pooled[filler] if pool else math.sqrt(ss / dof)
        for x in levels:
            n = int(sel[x].sum())
            out.append(Group(f, filler, phi, None if measurements.thickness_m is None
                             else x[0], means[x], rel * means[x] / math.sqrt(n), n, x[1]))
    return out


@dataclass(frozen=True)
class ModelFit:
    """One calibrated model (base or base + one effect), frozen.

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
        Model value per k group at the best parameters, W/(m K).
    variance : ndarray
        Likelihood variance per k group, (W/(m K))^2.
    log_likelihood, chi_square, bic : float
        Over every observation (k groups and auxiliary groups).
    n_parameters : int
    at_grid_edge : bool
        A resistance at an end of its grid.
    aux_predicted, aux_variance : ndarray
        Model value and likelihood variance per auxiliary group (empty without them).
    n_observations : int
        k groups plus auxiliary groups.
    log_evidence : float
        ``ln`` of the likelihood integrated over the model's priors: each resistance
        log-uniform over the solved grid, the effect's parameter by
        :meth:`Effect.prior_weights`. Its difference to the base model's is the log Bayes
        factor that names an effect (:mod:`.naming_threshold`).
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
    aux_predicted: np.ndarray = field(default_factory=lambda: np.zeros(0))
    aux_variance: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_observations: int = 0
    log_evidence: float = float("nan")

    def dof(self, n_groups: int | None = None) -> int:
        """Degrees of freedom: observations (default :attr:`n_observations`) less
        parameters, at least 1."""
        n = self.n_observations if n_groups is None else n_groups
        return max(n - self.n_parameters, 1)


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
    """(log-likelihood, generalised chi-square) of one formulation's k groups: independent
    replicate errors ``se_g`` plus one RVE error ``scatter * k`` shared by all its groups."""
    c = [scatter * np.asarray(k) for k in ks]
    return _gaussian_low_rank([m - k for m, k in zip(means, ks)],
                              [se ** 2 for se in standard_errors], [c])


def _gaussian_low_rank(residuals: Sequence[np.ndarray], variances: Sequence[np.ndarray],
                       columns: Sequence[Sequence[np.ndarray]]
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(log-likelihood, generalised chi-square) of residuals ``r`` with covariance
    ``D + sum_j c_j c_j^T`` (``D`` diagonal of ``variances``; each ``c_j`` one error shared
    by the observations, e.g. the RVE error of a formulation's k or a batch's fraction
    error that moves its k, density and mass fraction together), elementwise over the
    arrays' common shape (the calibration mesh), by the Woodbury identity:
    ``r^T S^-1 r = r^T D^-1 r - b^T A^-1 b`` with ``A = I + C^T D^-1 C``, ``b = C^T D^-1 r``,
    and ``log det S = sum log d + log det A``."""
    r = np.broadcast_arrays(*[np.asarray(x, dtype=float) for x in residuals])
    shape = np.broadcast_shapes(r[0].shape, *[np.shape(v) for v in variances],
                                *[np.shape(x) for c in columns for x in c])
    d = [np.broadcast_to(np.asarray(v, dtype=float), shape) for v in variances]
    rr = [np.broadcast_to(x, shape) for x in r]
    cols = [[np.broadcast_to(np.asarray(x, dtype=float), shape) for x in c] for c in columns]
    cols = [c for c in cols if any(np.any(x != 0) for x in c)]
    srr = sum(x * x / v for x, v in zip(rr, d))
    logd = sum(np.log(2 * math.pi * v) for v in d)
    if not cols:
        return -0.5 * (srr + logd), srr
    q = len(cols)
    if q == 1:                                  # one shared error: A and b are scalars
        b1 = sum(c * x / v for c, x, v in zip(cols[0], rr, d))
        a1 = 1.0 + sum(c * c / v for c, v in zip(cols[0], d))
        quad = srr - b1 * b1 / a1
        return -0.5 * (quad + logd + np.log(a1)), quad
    A = np.zeros(shape + (q, q))
    b = np.zeros(shape + (q,))
    for i, ci in enumerate(cols):
        b[..., i] = sum(c * x / v for c, x, v in zip(ci, rr, d))
        for j, cj in enumerate(cols):
            A[..., i, j] = (i == j) + sum(a * c / v for a, c, v in zip(ci, cj, d))
    sol = np.linalg.solve(A, b[..., None])[..., 0]
    quad = srr - np.einsum("...i,...i->...", b, sol)
    _, logdet = np.linalg.slogdet(A)
    return -0.5 * (quad + logd + logdet), quad


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


def fit_model(tables: ForwardTables, groups: Sequence[Group], effect: Effect | None,
              aux: Sequence[AuxGroup] = (), *, meshes: dict | None = None) -> ModelFit:
    """Calibrate the base model (``effect=None``) or base + ``effect`` on the k groups and
    the auxiliary groups ``aux`` (density, mass fraction: predicted from the composition the
    effect gives, :mod:`.observables`), every resistance and the effect's value free.

    Per formulation the observations share errors: the RVE error of its k, and for a
    variance effect the batch's fraction error, which moves k (``d ln k / d phi``), the
    density and the mass fraction together (:func:`_gaussian_low_rank`). A group of another
    powder (:attr:`Group.scale`) reads the table at ``R / scale`` and the effect at its
    size-equivalent value (:meth:`Effect.size_equivalent`); a thickness-dependent effect on
    a table without thicknesses is read at :attr:`DiscrepancySettings.assumed_thickness_mm`.
    ``meshes``, a dict the caller owns, keeps the model's k on the fine mesh between calls
    on the same tables (it does not depend on the measurements: a calibration fitting many
    noise-only tables interpolates once). The restricted fits are :func:`fit_physical`,
    :func:`fit_held_at` and :func:`fit_present`.
    """
    model = _MeshModel(tables, groups, effect, aux, meshes=meshes)
    ll, log_evidence = model.likelihood()
    return model.fit(ll, log_evidence)


def fit_physical(tables: ForwardTables, groups: Sequence[Group], effect: Effect | None,
                 aux: Sequence[AuxGroup] = (), *,
                 interval_drop: float | None = None) -> ModelFit:
    """:func:`fit_model` with the resistances restricted to
    :attr:`DiscrepancySettings.physical_r_m2K_per_W` and the effect's value to its physical
    range (the best plausible explanation; the interval is then inside those ranges).
    ``interval_drop`` replaces the 90 % interval's log-likelihood drop (None or 0:
    :data:`LR_DROP_90`); the log evidence is the unrestricted model's."""
    model = _MeshModel(tables, groups, effect, aux)
    ll, log_evidence = model.likelihood()
    return model.fit(model.within_physical(ll), log_evidence,
                     drop=interval_drop or LR_DROP_90)


def fit_held_at(tables: ForwardTables, groups: Sequence[Group], effect: Effect,
                aux: Sequence[AuxGroup] = (), *, at: float) -> ModelFit:
    """:func:`fit_physical` with the effect's parameter held at the fine grid's point
    nearest ``at`` (its unit; the resistances still fitted)."""
    model = _MeshModel(tables, groups, effect, aux)
    ll, log_evidence = model.likelihood()
    return model.fit(model.within_physical(ll), log_evidence, at=at)


def fit_present(tables: ForwardTables, groups: Sequence[Group], effect: Effect,
                aux: Sequence[AuxGroup] = (), *, side: int) -> ModelFit:
    """:func:`fit_physical` with the effect held at least one grid step below (``side``
    -1) or above (+1) its nominal value: the effect there, not its absence (no hold where
    its grid has no value on that side)."""
    if side not in (-1, 1):
        raise ValueError(f"side: expected -1 or +1, got {side!r}")
    model = _MeshModel(tables, groups, effect, aux)
    ll, log_evidence = model.likelihood()
    return model.fit(model.present(model.within_physical(ll), side), log_evidence)


class _MeshModel:
    """One model (the base, or base + ``effect``) on the fine mesh of its calibration:
    log10 R over the solved resistance grid (:attr:`DiscrepancySettings.fine_points`)
    crossed with the effect's parameter (41 points over its grid; one point for the base
    model), and what it predicts of each observation there."""

    def __init__(self, tables: ForwardTables, groups: Sequence[Group], effect: Effect | None,
                 aux: Sequence[AuxGroup], *, meshes: dict | None = None):
        st = tables.settings
        self.tables, self.groups, self.effect, self.aux, self.st = (tables, groups, effect,
                                                                     aux, st)
        self.logr = np.log10(np.asarray(st.r_grid_m2K_per_W))
        self.fine_r = np.linspace(self.logr[0], self.logr[-1], st.fine_points)
        self.fine_t = _fine_axis(effect, 41)
        self.fillers = sorted({g.filler for g in groups})
        self.scatter = pooled_scatter(tables, groups)
        self.theta_axis = np.asarray(effect.values if effect else [0.0], dtype=float)
        self.kmesh = {} if meshes is None else meshes.setdefault(
            (id(tables), effect.name if effect is not None else None), {})
        self.forms = _by_formulation(groups)
        self.aux_by: dict[str, list[AuxGroup]] = {}
        for a in aux:
            self.aux_by.setdefault(a.formulation, []).append(a)
        self.slopes = _fraction_slopes(
            {f: (m[0].filler, m[0].fraction) for f, m in self.forms.items()},
            {f: self.mesh(f, 1.0)[:, 0] for f, m in self.forms.items()})

    def mesh(self, f: str, scale: float) -> np.ndarray:
        """k of formulation ``f`` (W/(m K)) on the fine mesh, for a powder ``scale`` times
        the nominal one's size (kept in :attr:`kmesh`)."""
        effect, fine_r, logr = self.effect, self.fine_r, self.logr
        if (f, scale) not in self.kmesh:
            vals = (self.tables.base[f] if effect is None or not effect.solved
                    else self.tables.effect[effect.name][f])
            fr = np.clip(fine_r - math.log10(scale), logr[0], logr[-1])
            ft = self.fine_t
            if effect is not None and scale != 1.0:
                ft = np.clip(effect.size_equivalent(self.fine_t, scale), self.theta_axis[0],
                             self.theta_axis[-1])
            # the level per resistance, at the resistance the table is read at (R / scale
            # for another powder: the correction belongs to the RVE the table solved)
            level = np.broadcast_to(np.asarray(
                self.tables.level(f, effect.name if effect else None, 10 ** fr), float),
                fr.shape)
            self.kmesh[(f, scale)] = level[:, None] * _interp(logr, self.theta_axis, vals,
                                                              effect, fr, ft)
        return self.kmesh[(f, scale)]

    def model_k(self, g: Group, i=slice(None), j=slice(None)) -> np.ndarray:
        """The model's k of group ``g`` at mesh rows ``i`` and columns ``j`` (the apparent
        k at the group's thickness for a thickness-dependent effect)."""
        effect = self.effect
        k = self.mesh(g.formulation, g.scale)[i, j]
        if effect is not None and (g.thickness_m is not None or effect.needs_thickness):
            t = (g.thickness_m if g.thickness_m is not None
                 else self.st.assumed_thickness_mm * 1e-3)
            k = effect.apparent(k, t, self.fine_t[j] if np.ndim(k) == 0
                                else self.fine_t[None, j])
        return k

    def composition(self, a: AuxGroup, j=slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(filler, void) volume fractions of the samples of ``a`` at mesh columns ``j``."""
        if self.effect is None:
            return np.asarray(a.fraction), np.asarray(0.0)
        return self.effect.composition(a.fraction, self.fine_t[j])

    def model_aux(self, a: AuxGroup, j=slice(None)) -> np.ndarray:
        """The model's value of the auxiliary observable of ``a`` at mesh columns ``j``."""
        phi, p = self.composition(a, j)
        v = predict(a.observable, self.st.system, a.filler, phi, p)
        return v if np.ndim(v) == 0 else v[None, :]

    def terms(self, f: str, i=slice(None), j=slice(None)):
        """Residuals, variances and shared columns of formulation ``f``'s observations."""
        st, effect = self.st, self.effect
        members, extra = self.forms[f], self.aux_by.get(f, [])
        fl = members[0].filler
        ks = [self.model_k(g, i, j) for g in members]
        res = [g.mean - k for g, k in zip(members, ks)]
        var = [g.standard_error ** 2 for g in members]
        rve = [self.scatter[fl] * k for k in ks] + [0.0] * len(extra)
        batch = None
        sd = np.asarray(st.fraction_sd)
        if effect is not None:
            sd = np.hypot(effect.fraction_sd(self.fine_t[j]), st.fraction_sd)
        if np.any(sd != 0):
            sd = sd if np.ndim(sd) == 0 else sd[None, :]
            sl = self.slopes[f][i] if np.ndim(self.slopes[f][i]) == 0 \
                else self.slopes[f][i][:, None]
            batch = [sl * k * sd for k in ks]
        for a in extra:
            pred = self.model_aux(a, j)
            res.append(a.mean - pred)
            var.append(a.standard_error ** 2 + (st.auxiliary_model_sd * pred) ** 2)
            if batch is not None:
                phi, p = self.composition(a, j)
                d = fraction_derivatives(a.observable, st.system, a.filler, phi, p)
                batch.append((d if np.ndim(d) == 0 else d[None, :]) * sd)
        return res, var, [rve] + ([batch] if batch is not None else [])

    def likelihood(self) -> tuple[dict[str, np.ndarray], float]:
        """Per filler the log-likelihood of its formulations on the mesh (R rows, the
        effect's columns), and the model's log evidence (:func:`_log_evidence`)."""
        ll = {fl: np.zeros((self.fine_r.size, self.fine_t.size)) for fl in self.fillers}
        for f, members in self.forms.items():
            ll[members[0].filler] = ll[members[0].filler] + _gaussian_low_rank(
                *self.terms(f))[0]
        weights = (self.effect.prior_weights(self.fine_t) if self.effect is not None
                   else np.ones(1))
        return ll, _log_evidence(ll, weights)

    def within_physical(self, ll: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``ll`` with the mesh outside the physical resistances and the effect's physical
        range ruled out."""
        lo, hi = np.log10(self.st.physical_r_m2K_per_W)
        fine_r, fine_t, effect = self.fine_r, self.fine_t, self.effect
        out_r = (fine_r < lo - 1e-9) | (fine_r > hi + 1e-9)
        out_t = np.zeros(fine_t.size, dtype=bool)
        if effect is not None and effect.physical_range is not None:
            a, b = effect.physical_range
            out_t = (fine_t < a - 1e-12) | (fine_t > b * (1 + 1e-9))
        return {fl: np.where(out_r[:, None] | out_t[None, :], -1e300, ll[fl])
                for fl in self.fillers}

    def present(self, ll: dict[str, np.ndarray], side: int) -> dict[str, np.ndarray]:
        """``ll`` with the effect's values short of one grid step below (``side`` -1) or
        above (+1) nominal ruled out; as it is where the grid has no value on that side."""
        effect, fine_t = self.effect, self.fine_t
        v = np.asarray(effect.values, dtype=float)
        beyond = v[v < effect.nominal] if side < 0 else v[v > effect.nominal]
        if not beyond.size:
            return ll
        edge = beyond.max() if side < 0 else beyond.min()
        absent = fine_t > edge * (1 + 1e-9) if side < 0 else fine_t < edge * (1 - 1e-9)
        return {fl: np.where(absent[None, :], -1e300, ll[fl]) for fl in self.fillers}

    def fit(self, ll: dict[str, np.ndarray], log_evidence: float, *, at: float | None = None,
            drop: float = LR_DROP_90) -> ModelFit:
        """The fit read off ``ll``: the effect's value of highest profile likelihood (or
        the mesh point nearest ``at``), each filler's best resistance there, the
        predictions and variances at that point and the effect's likelihood-ratio interval
        (log-likelihood ``drop``)."""
        effect, fine_r, fine_t, fillers = self.effect, self.fine_r, self.fine_t, self.fillers
        profile = sum(ll[fl].max(axis=0) for fl in fillers)            # (ntheta,)
        j = int(np.argmax(profile)) if at is None else int(np.argmin(np.abs(fine_t - at)))
        params = {}
        best_i = {fl: int(np.argmax(ll[fl][:, j])) for fl in fillers}
        for fl in fillers:
            params[resistance_name(fl, self.st.system.matrix)] = float(10 ** fine_r[best_i[fl]])
        pred, var, aux_pred, aux_var, chi2 = self.at_point(best_i, j)
        interval = None
        edge = any(best_i[fl] in (0, fine_r.size - 1) for fl in fillers)
        if effect is not None:
            params[effect.parameter] = float(fine_t[j])
            interval = profile_interval(profile, fine_t, drop)
        lmax = float(profile[j])
        p = len(fillers) + (effect is not None)
        n_obs = len(self.groups) + len(self.aux)
        return ModelFit("base" if effect is None else effect.name, params, interval, pred,
                        var, lmax, chi2, -2 * lmax + p * math.log(n_obs), p, edge, aux_pred,
                        aux_var, n_obs, log_evidence)

    def at_point(self, best_i: dict[str, int], j: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """At each filler's resistance row ``best_i`` and the effect's column ``j``: the
        model value and marginal variance (its own plus the shared ones) of each k group
        and each auxiliary group, and the generalised chi-square."""
        groups, aux = self.groups, self.aux
        index = {id(g): n for n, g in enumerate(groups)}
        pred, var = np.zeros(len(groups)), np.zeros(len(groups))
        aux_index = {id(a): n for n, a in enumerate(aux)}
        aux_pred, aux_var = np.zeros(len(aux)), np.zeros(len(aux))
        chi2 = 0.0
        for f, members in self.forms.items():
            i = best_i[members[0].filler]
            res, v, cols = self.terms(f, i, j)
            chi2 += float(_gaussian_low_rank(res, v, cols)[1])
            # the marginal variance of each observation: its own plus the shared ones
            for n, g in enumerate(members):
                pred[index[id(g)]] = float(g.mean - res[n])
                var[index[id(g)]] = float(v[n] + sum(c[n] ** 2 for c in cols))
            for n, a in enumerate(self.aux_by.get(f, []), start=len(members)):
                aux_pred[aux_index[id(a)]] = float(a.mean - res[n])
                aux_var[aux_index[id(a)]] = float(v[n] + sum(c[n] ** 2 for c in cols))
        return pred, var, aux_pred, aux_var, chi2


def _log_evidence(ll: dict[str, np.ndarray], weights: np.ndarray) -> float:
    """``ln`` of the likelihood ``exp(sum over fillers of ll[filler])`` integrated over each
    filler's resistance (log-uniform over the fine grid: rows of ``ll[filler]``) and the
    effect's parameter (``weights`` over the columns, summing to 1)."""
    per_theta = sum(logsumexp(v, axis=0) - math.log(v.shape[0]) for v in ll.values())
    keep = weights > 0
    return float(logsumexp(per_theta[keep], b=weights[keep]))


def evaluate(tables: ForwardTables, effect: Effect | None, parameters: dict[str, float],
             groups: Sequence[Group], aux: Sequence[AuxGroup] = ()
             ) -> tuple[np.ndarray, np.ndarray]:
    """A model at given ``parameters`` (as :attr:`ModelFit.parameters`) on any groups: k
    per group (W/(m K); of another powder, at another thickness) and the auxiliary
    observables per auxiliary group, read as :func:`fit_model` reads them."""
    st = tables.settings
    logr = np.log10(np.asarray(st.r_grid_m2K_per_W))
    axis = np.asarray(effect.values if effect else [0.0], dtype=float)
    theta = float(parameters[effect.parameter]) if effect is not None else 0.0
    k = np.zeros(len(groups))
    for n, g in enumerate(groups):
        vals = (tables.base[g.formulation] if effect is None or not effect.solved
                else tables.effect[effect.name][g.formulation])
        r_name = resistance_name(g.filler, st.system.matrix)
        fr = np.clip(np.log10(parameters[r_name] / g.scale), logr[0],
                     logr[-1])
        ft = theta if effect is None or g.scale == 1.0 else float(np.clip(
            effect.size_equivalent(theta, g.scale), axis[0], axis[-1]))
        level = float(np.ravel(tables.level(g.formulation, effect.name if effect else None,
                                            np.array([10 ** fr])))[0])
        k[n] = level * _interp(logr, axis, vals, effect, np.array([fr]), np.array([ft]))[0, 0]
        if effect is not None and (g.thickness_m is not None or effect.needs_thickness):
            t = g.thickness_m if g.thickness_m is not None else st.assumed_thickness_mm * 1e-3
            k[n] = float(effect.apparent(np.asarray(k[n]), t, theta))
    a_out = np.zeros(len(aux))
    for n, a in enumerate(aux):
        phi, p = ((a.fraction, 0.0) if effect is None
                  else effect.composition(a.fraction, theta))
        a_out[n] = float(predict(a.observable, st.system, a.filler, phi, p))
    return k, a_out
