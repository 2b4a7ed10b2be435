"""One joint posterior over the resistances and every uncertain input, sampled by emcee.

Every formulation, the two-filler ones included, is evaluated at every point of the
parameter space::

    log10 R_<filler>_<matrix>     log-uniform over the resistance prior (:mod:`.priors`)
    ln(k_<phase> / nominal)       normal, the material system's sd (lognormal conductivities)
    film_nm                       uniform over the film prior, where no film is stated
    offset_<system>               standard normal: one relative offset of all a system's
                                  formulations, of sd sqrt(u_sys(R)^2 + tau_offset^2): the
                                  shipped correction's shared term (box step, voxel order,
                                  tail cut; sd u_sys) and the model form's offset (sd
                                  tau_offset), two independent normals in one (non-centred)
    slope_<system>                standard normal: the model form's slope in the system's
                                  filler fraction, of sd tau_slope
    tau_offset, tau_slope         the model form's sds, half-normal priors (:mod:`.priors`)

A formulation's conductivity at a point is its forward model at nominal conductivities
(reduced basis times replica factor times correction, tabulated once, :class:`Tabulated`)
with the exact scaling of the matrix conductivity and the first-order terms of the filler
conductivities and the film (:mod:`.nuisance`)::

    k = lam prod_f (mu_f / lam)^(s_f) exp(s_film film) k_model(lam R)
        x (1 + sqrt(u_sys(R)^2 + tau_o^2) o_sys + tau_s c_sys z)

(``lam``, ``mu_f`` the conductivities over nominal, ``z`` the formulation's filler fraction
about its system's mean in units of 5 vol%). The likelihood is the package's one
(:func:`~itr_identify.inference.calibrate.log_likelihood`, :func:`~itr_identify.inference.
calibrate.variance`): per formulation a Student t of the measured mean whose degrees of
freedom count the replicate variance and the shipped correction's pooled packing variance as
estimates. The shared and model-form terms are parameters here, where the grid calibration
integrates the shared term by quadrature: the same model.

The sampler is emcee's affine-invariant ensemble (differential-evolution moves), chosen
because its walkers are evaluated together: the likelihood is vectorised over the ensemble
(every reduced basis tabulated on a grid in log10 R once), so a posterior with tens of
thousands of effective samples takes seconds, which the 2 % convergence rule on interval
ends needs; it is seeded and deterministic. Once the chain spans 20 autocorrelation times,
an even mixture of two t fitted to it (one in the parameters, one with each uniform
parameter on its logit) is the proposal of importance sampling over the same likelihood
(:func:`refine`): where the weighted draws are worth the
target they are the posterior and the chain stops (on Table 3 a sixth of the steps the
chain's own rule needs, the same intervals); else the chain runs on to its own rule. The
importance weights give the evidence, where a comparison of models needs one.

The resistances' point and interval ends are read from their Rao-Blackwell marginals
(:mod:`.marginal`: the average of each draw's exact conditional density on a grid), not
counted from draws: where the likelihood is flat in R, below where k responds to it, counted
quantiles move by several per cent between two runs; the averaged ones do not.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from scipy import special

from ..forward.model import ForwardModel
from ._table_kernels import linear_1d, linear_2d
from .calibrate import log_likelihood, variance
from .chunked import map_chunks
from .effect_terms import BoundEffect, JointEffect
from .marginal import DRAWS as MARGINAL_DRAWS
from .marginal import GRID as MARGINAL_GRID
from .marginal import Marginal, rao_blackwell
from .measurements import Measurements
from .nuisance import FilmPrior, InputPrior
from .priors import ModelFormPrior, ResistancePrior

__all__ = ["Tabulated", "JointSpace", "JointLikelihood", "JointPosterior", "sample", "refine",
           "marginal_of", "with_marginals",
           "weighted_quantile", "density_data", "DENSITY_MODEL_SD",
           "thickness_series", "system_means",
           "TABLE_POINTS_1D", "TABLE_POINTS_2D", "FRACTION_UNIT"]

#: Grid points of a one-parameter forward model's table over its reduced basis's box.
TABLE_POINTS_1D = 401
#: Grid points per axis of a two-parameter model's table.
TABLE_POINTS_2D = 97
#: The model-form slope's unit of filler fraction (5 vol%).
FRACTION_UNIT = 0.05


def _system_name(fractions: Mapping[str, float]) -> str:
    return "-".join(sorted(fractions))


@dataclass(frozen=True, eq=False)
class Tabulated:
    """A forward model as fast functions of its resistances: ln k, the relative error bound
    and the shipped correction's shared sd on a grid in log10 R (the reduced basis's box),
    interpolated (linear in one parameter, bilinear in two), and what the likelihood reads
    of the model.

    Attributes
    ----------
    formulation : str
    parameters : tuple of str
        Flat resistance names the model varies (0, 1 or 2).
    fractions : dict
        Filler volume fractions.
    axes : tuple of ndarray
        log10 R grid per parameter.
    log_k, rel_err, shared : ndarray
        On the grid (shape of the axes; scalars for a model without parameters).
    system : str or None
        The shipped correction's system whose shared term the model carries.
    model_sd, rve_scatter : float
        The model level's own relative sd and one RVE's relative scatter.
    packing : (float, int) or None
        The shipped correction's pooled packing sd and its degrees of freedom.
    elasticity : dict
        d ln k / d ln k_f per filler, and ``film_nm`` (1/nm) where the film is sampled.
    """

    formulation: str
    parameters: tuple[str, ...]
    fractions: dict[str, float]
    axes: tuple[np.ndarray, ...]
    log_k: np.ndarray
    rel_err: np.ndarray
    shared: np.ndarray
    system: str | None
    model_sd: float
    rve_scatter: float
    packing: tuple[float, int] | None
    elasticity: dict[str, float] = field(default_factory=dict)

    @classmethod
    def of(cls, name: str, model: ForwardModel,
           elasticity: Mapping[str, float]) -> Tabulated:
        """Tabulate ``model`` over its reduced basis's box (:data:`TABLE_POINTS_1D`,
        :data:`TABLE_POINTS_2D`); a model without parameters is one value."""
        params = tuple(model.parameters)
        if model.rb is None or not params:
            k, err = model.predict({})
            axes: tuple[np.ndarray, ...] = ()
            k, err = np.asarray(k[:1]), np.asarray(err[:1])
            shared = model.shared_sd({p: np.array([v]) for p, v in model.fixed.items()}) \
                if model.fixed else np.zeros(1)
            shape: tuple[int, ...] = ()
        else:
            box = model.rb.box_
            n = TABLE_POINTS_1D if len(params) == 1 else TABLE_POINTS_2D
            axes = tuple(np.linspace(math.log10(box.lo[box.names.index(p)]),
                                     math.log10(box.hi[box.names.index(p)]), n)
                         for p in params)
            mesh = np.meshgrid(*axes, indexing="ij")
            cols = {p: 10 ** m.ravel() for p, m in zip(params, mesh)}
            k, err = model.predict(cols)
            shared = model.shared_sd(cols)
            shape = mesh[0].shape
        pack = model.packing_dof
        return cls(name, params, dict(model.fractions), axes,
                   np.log(k).reshape(shape), (err / k).reshape(shape),
                   np.asarray(shared, dtype=float).reshape(shape), model.shared_system,
                   float(model.model_sd), float(model.rve_scatter), pack,
                   {k_: float(v) for k_, v in elasticity.items()})

    @property
    def group(self) -> str:
        """The filler system the formulation belongs to (its fillers joined by '-')."""
        return _system_name(self.fractions)

    def evaluate(self, log10_r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k, relative error bound, shared sd), each (N,), at ``log10_r`` (N, P) (held
        inside the table's box: the scaled resistance of an extreme conductivity beyond it
        takes the box's edge)."""
        n = log10_r.shape[0]
        if not self.axes:
            return (np.full(n, math.exp(float(self.log_k.ravel()[0]))),
                    np.full(n, float(self.rel_err.ravel()[0])),
                    np.full(n, float(self.shared.ravel()[0])))
        if len(self.axes) == 1:
            x = log10_r[:, 0]
            ax = self.axes[0]
            return (np.exp(np.interp(x, ax, self.log_k)), np.interp(x, ax, self.rel_err),
                    np.interp(x, ax, self.shared))
        x = log10_r
        return (np.exp(_bilinear(self.axes, self.log_k, x)),
                _bilinear(self.axes, self.rel_err, x), _bilinear(self.axes, self.shared, x))


def _bilinear(axes: tuple[np.ndarray, np.ndarray], table: np.ndarray,
              x: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of ``table`` on the regular ``axes`` at the rows of ``x``
    (N, 2), clipped into the grid."""
    out_idx, out_w = [], []
    for d, ax in enumerate(axes):
        step = ax[1] - ax[0]
        t = np.clip((x[:, d] - ax[0]) / step, 0.0, len(ax) - 1 - 1e-9)
        i = np.floor(t).astype(int)
        out_idx.append(i)
        out_w.append(t - i)
    (i, j), (a, b) = out_idx, out_w
    return ((1 - a) * (1 - b) * table[i, j] + a * (1 - b) * table[i + 1, j]
            + (1 - a) * b * table[i, j + 1] + a * b * table[i + 1, j + 1])



@dataclass(frozen=True)
class JointSpace:
    """The sampled parameters, their priors and the held ones.

    Attributes
    ----------
    names : tuple of str
        Sampled parameters, in the order of a point's coordinates (module notes).
    kinds : tuple of str
        Per parameter its prior: ``"uniform"`` (over ``a`` to ``b``), ``"normal"`` (mean
        ``a``, sd ``b``) or ``"halfnormal"`` (scale ``b``).
    a, b : tuple of float
    held : dict
        Parameters held at a value (a stated input, a resistance fixed by the caller).
    groups : dict
        Per formulation its filler system and standardised filler fraction ``z``.
    matrix : str
        The matrix phase (its conductivity scales the resistances).
    """

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    a: tuple[float, ...]
    b: tuple[float, ...]
    held: dict[str, float]
    groups: dict[str, tuple[str, float]]
    matrix: str
    effect: JointEffect | None = None

    @classmethod
    def build(cls, tables: Mapping[str, Tabulated], *, matrix: str,
              resistance: ResistancePrior, inputs: Mapping[str, InputPrior | FilmPrior],
              model_form: ModelFormPrior, hold: Mapping[str, float] | None = None,
              effect: JointEffect | None = None) -> JointSpace:
        """The space of ``tables`` (module notes): their resistances over ``resistance``,
        the ``inputs`` with a non-zero sd (a film only where the tables carry its
        elasticity), one shared term per shipped system, and the model form per filler
        system where ``model_form.on``; ``hold`` fixes any of them (log10 R values for a
        resistance); ``effect``: a candidate effect's parameters added, or the prior of
        the input it frees widened (:mod:`.effect_terms`)."""
        lo, hi = resistance.log10_bounds
        spec: list[tuple[str, str, float, float]] = []
        for p in sorted({p for t in tables.values() for p in t.parameters}):
            spec.append((f"log10 {p}", "uniform", lo, hi))
        film_used = any("film_nm" in t.elasticity for t in tables.values())
        for name, pr in sorted(inputs.items()):
            if isinstance(pr, FilmPrior):
                if film_used:
                    spec.append(("film_nm", "uniform", pr.low_nm, pr.high_nm))
            elif pr.rel_sd > 0:
                spec.append((f"ln {pr.name}", "normal", 0.0, pr.rel_sd))
        if effect is not None:
            replaced, added = effect.space_entries({s[0]: s[1:] for s in spec})
            spec = [(s[0], *replaced[s[0]]) if s[0] in replaced else s for s in spec]
            spec += added
        groups = _groups(tables)
        stated: dict[str, float] = {}
        if model_form.on and model_form.hyper:
            spec.append(("tau_offset", "halfnormal", 0.0, model_form.offset_scale))
            spec.append(("tau_slope", "halfnormal", 0.0, model_form.slope_scale))
        elif model_form.on:
            stated = {"tau_offset": model_form.offset_scale,
                      "tau_slope": model_form.slope_scale}
        shipped = {t.group for t in tables.values() if t.system}
        for g in sorted({g for g, _ in groups.values()}):
            if model_form.on or g in shipped:
                spec.append((f"offset_{g}", "normal", 0.0, 1.0))
            if model_form.on and len({z for gg, z in groups.values() if gg == g}) > 1:
                spec.append((f"slope_{g}", "normal", 0.0, 1.0))
        held = dict(hold or {})
        unknown = sorted(set(held) - {s[0] for s in spec} - set(stated))
        held = {**stated, **held}
        if unknown:
            raise ValueError(f"hold: {unknown[0]!r} is no parameter of this space (have "
                             f"{', '.join(s[0] for s in spec)})")
        spec = [s for s in spec if s[0] not in held]
        if not spec:
            raise ValueError("hold: every parameter is held; nothing to sample")
        return cls(tuple(s[0] for s in spec), tuple(s[1] for s in spec),
                   tuple(s[2] for s in spec), tuple(s[3] for s in spec), held, groups, matrix,
                   effect)

    @property
    def dim(self) -> int:
        return len(self.names)

    def log_prior(self, theta: np.ndarray) -> np.ndarray:
        """Log prior density (N,) of the points ``theta`` (N, D); -inf outside."""
        uni, nor, half, a, b, const = self._prior_arrays
        x = theta.T
        terms = np.empty(x.shape)
        if uni.size:
            xu = x[uni]
            terms[uni] = np.where((xu >= a[uni]) & (xu <= b[uni]), const[uni], -np.inf)
        if nor.size:
            terms[nor] = -0.5 * ((x[nor] - a[nor]) / b[nor]) ** 2 - const[nor]
        if half.size:
            xh = x[half]
            terms[half] = np.where(xh >= 0, -0.5 * (xh / b[half]) ** 2 + const[half], -np.inf)
        out = np.zeros(theta.shape[0])
        for row in terms:           # parameter by parameter, the sum's order kept
            out += row
        return out

    @cached_property
    def _prior_arrays(self) -> tuple[np.ndarray, ...]:
        """(uniform, normal and half-normal parameters' indices, a, b, the log density's
        constant), the last three (D, 1)."""
        col = lambda v: np.asarray(v, dtype=float)[:, None]  # noqa: E731 - (D, 1)
        const = [-math.log(b - a) if k == "uniform" else
                 math.log(b * math.sqrt(2 * math.pi)) if k == "normal" else
                 math.log(math.sqrt(2 / math.pi) / b)
                 for k, a, b in zip(self.kinds, self.a, self.b)]
        kinds = np.array(self.kinds)
        return (np.flatnonzero(kinds == "uniform"), np.flatnonzero(kinds == "normal"),
                np.flatnonzero((kinds != "uniform") & (kinds != "normal")),
                col(self.a), col(self.b), col(const))

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` points from the prior, (n, D)."""
        out = np.empty((n, self.dim))
        for i, (kind, a, b) in enumerate(zip(self.kinds, self.a, self.b)):
            if kind == "uniform":
                out[:, i] = rng.uniform(a, b, n)
            elif kind == "normal":
                out[:, i] = rng.normal(a, b, n)
            else:
                out[:, i] = np.abs(rng.normal(0.0, b, n))
        return out

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """The prior transform of a point of the unit cube (nested sampling), (..., D)."""
        out = np.empty_like(u, dtype=float)
        for i, (kind, a, b) in enumerate(zip(self.kinds, self.a, self.b)):
            if kind == "uniform":
                out[..., i] = a + (b - a) * u[..., i]
            elif kind == "normal":
                out[..., i] = a + b * special.ndtri(u[..., i])
            else:
                out[..., i] = b * special.ndtri(0.5 + 0.5 * u[..., i])
        return out

    def to_open(self, theta: np.ndarray) -> np.ndarray:
        """The points ``theta`` (N, D) with each uniform parameter mapped from its prior's
        interval onto the real line (the logit of its place in the interval), the others as
        they are: the space :func:`refine`'s proposal is fitted in, where a resistance's
        posterior that fills its prior's range is a bell, not a box."""
        uni, lo, width = self._open_arrays
        y = np.array(theta, dtype=float, copy=True)
        u = np.clip((y[:, uni] - lo) / width, 1e-12, 1 - 1e-12)
        y[:, uni] = np.log(u) - np.log1p(-u)
        return y

    def from_open(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The inverse of :meth:`to_open`: the points (N, D) and the log of the map's
        Jacobian determinant ``ln |d theta / d y|`` (N,)."""
        uni, lo, width = self._open_arrays
        theta = np.array(y, dtype=float, copy=True)
        s = special.expit(y[:, uni])
        theta[:, uni] = lo + width * s
        return theta, self._log_jacobian(s, width)

    def log_jacobian(self, y: np.ndarray) -> np.ndarray:
        """``ln |d theta / d y|`` (N,) of :meth:`from_open` at the open points ``y`` (N, D),
        without the points themselves."""
        uni, _, width = self._open_arrays
        return self._log_jacobian(special.expit(y[:, uni]), width)

    @staticmethod
    def _log_jacobian(s: np.ndarray, width: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.sum(np.log(width) + np.log(s) + np.log1p(-s), axis=1)

    def inside(self, theta: np.ndarray) -> np.ndarray:
        """Whether each point (N, D) lies strictly inside every uniform prior's interval
        (where :meth:`to_open` is defined), (N,) bool."""
        uni, lo, width = self._open_arrays
        return np.all((theta[:, uni] > lo) & (theta[:, uni] < lo + width), axis=1)

    @cached_property
    def _open_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(the uniform parameters' indices, their lower ends, their widths)."""
        uni = np.flatnonzero(np.array(self.kinds) == "uniform")
        lo = np.array(self.a, dtype=float)[uni]
        return uni, lo, np.array(self.b, dtype=float)[uni] - lo

    def columns(self, theta: np.ndarray) -> dict[str, np.ndarray]:
        """Every parameter's column (N,) at the points ``theta``, the held ones too."""
        n = theta.shape[0]
        cols = {name: theta[:, i] for i, name in enumerate(self.names)}
        cols.update({k: np.full(n, float(v)) for k, v in self.held.items()})
        return cols


def system_means(tables: Mapping[str, Tabulated]) -> dict[str, float]:
    """Per filler system of ``tables`` its formulations' mean total filler fraction (the
    model-form slope's centre)."""
    by: dict[str, list[float]] = {}
    for t in tables.values():
        by.setdefault(t.group, []).append(sum(t.fractions.values()))
    return {g: float(np.mean(v)) for g, v in by.items()}


def _groups(tables: Mapping[str, Tabulated]) -> dict[str, tuple[str, float]]:
    """Per formulation its filler system and its total filler fraction about the system's
    mean, in :data:`FRACTION_UNIT`."""
    means = system_means(tables)
    return {f: (t.group, (sum(t.fractions.values()) - means[t.group]) / FRACTION_UNIT)
            for f, t in tables.items()}


#: Relative sd of a predicted sample density given the stated phase densities (ideal mixing;
#: the coupling agent's 4 vol% of the matrix at about 1.0 g/cm^3 moves a 60 vol% composite by
#: 0.05 %), added to the measured mean's standard error.
DENSITY_MODEL_SD = 0.001


def density_data(measurements: Measurements, tables: Mapping[str, Tabulated],
                 densities: Mapping[str, float] | None, matrix: str
                 ) -> dict[str, tuple[float, float, float, float]]:
    """Per single-filler formulation with a density column: (mean density, its standard
    error from the replicate scatter pooled over the filler's formulations, the filler's
    and the matrix's densities), g/cm^3; empty without the column or the densities."""
    col = "density_g_per_cm3"
    if densities is None or col not in measurements.auxiliary_columns:
        return {}
    rows = {}
    for f, t in tables.items():
        v = measurements.auxiliary_of(col, f)
        if len(t.fractions) != 1 or v is None or not np.isfinite(v).any():
            continue
        v = v[np.isfinite(v)]
        rows[f] = (next(iter(t.fractions)), v)
    out = {}
    for filler in sorted({r[0] for r in rows.values()}):
        mine = {f: v for f, (fl, v) in rows.items() if fl == filler}
        dof = sum(v.size - 1 for v in mine.values())
        if dof < 1:
            raise ValueError(f"measurements: the density of {filler} needs two samples of "
                             "one formulation at least (its replicate scatter is its noise)")
        sd = math.sqrt(sum(float(((v / v.mean() - 1) ** 2).sum()) for v in mine.values())
                       / dof)
        for f, v in mine.items():
            out[f] = (float(v.mean()), sd * float(v.mean()) / math.sqrt(v.size),
                      float(densities[filler]), float(densities[matrix]))
    return out


def thickness_series(measurements: Measurements, order: list[str]
                     ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per formulation measured at two thicknesses or more: (thicknesses m, the mean k at
    each, its standard error from the replicate scatter pooled over the formulation's
    thicknesses), thinnest first."""
    out = {}
    for f in order:
        t = (measurements.thickness_m or {}).get(f)
        if t is None:
            continue
        t = np.asarray(t, dtype=float)
        v = np.asarray(measurements.values[f], dtype=float)
        levels = np.unique(t)
        if levels.size < 2:
            continue
        groups = [v[t == x] for x in levels]
        dof = sum(g.size - 1 for g in groups)
        if dof < 1:
            continue
        sd = math.sqrt(sum(float(((g - g.mean()) ** 2).sum()) for g in groups) / dof)
        out[f] = (levels, np.array([g.mean() for g in groups]),
                  np.array([sd / math.sqrt(g.size) for g in groups]))
    return out


def _inverse_thickness(measurements: Measurements, order: list[str]) -> dict[str, float]:
    """Per formulation the mean of 1 / thickness of its samples, 1/m (where stated)."""
    if not measurements.thickness_m:
        return {}
    return {f: float(np.mean(1.0 / np.asarray(measurements.thickness_m[f], dtype=float)))
            for f in order if f in measurements.thickness_m}


class JointLikelihood:
    """The log likelihood of the measured means at points of a :class:`JointSpace`,
    vectorised over the points and the formulations (module notes; the tables of one shape
    are stacked and interpolated together)."""

    def __init__(self, tables: Mapping[str, Tabulated], measurements: Measurements,
                 space: JointSpace, *, scatter: Mapping[str, float],
                 densities: Mapping[str, float] | None = None,
                 matrix_conductivity: float | None = None) -> None:
        missing = sorted(set(tables) - set(measurements.formulations))
        if missing:
            raise ValueError(f"measurements: no measured values for {missing[0]!r}")
        self.tables = dict(tables)
        self.space = space
        self.scatter = dict(scatter)
        self.data = {f: (measurements.mean(f), measurements.standard_error(f),
                         measurements.values[f].size) for f in tables}
        self.density = density_data(measurements, tables, densities, space.matrix)
        self.series = thickness_series(measurements, list(tables))
        self._prepare()
        self.bound: BoundEffect | None = self._bound(
            matrix_conductivity, lambda: _inverse_thickness(measurements, self.order))

    def _bound(self, matrix_conductivity: float | None,
               inverse_thickness: Callable[[], Mapping[str, float]]) -> BoundEffect | None:
        """The space's effect bound to the tables (None without one)."""
        if self.space.effect is None:
            return None
        if matrix_conductivity is None:
            raise ValueError("matrix_conductivity: an effect's terms need the matrix's "
                             "nominal conductivity, W/(m K)")
        return self.space.effect.bind(
            self.order, {f: t.fractions for f, t in self.tables.items()},
            {f: t.parameters for f, t in self.tables.items()},
            matrix_conductivity=matrix_conductivity, inverse_thickness=inverse_thickness())

    @classmethod
    def predictor(cls, tables: Mapping[str, Tabulated], space: JointSpace, *,
                  scatter: Mapping[str, float],
                  matrix_conductivity: float | None = None) -> JointLikelihood:
        """The model of this likelihood for formulations without measurements (their
        conductivities and model variance only: :meth:`predictive_of_model`; no
        likelihood terms); a space with an effect binds it to ``tables`` (no sample
        thicknesses: a tester's effect takes its assumed one)."""
        self = cls.__new__(cls)
        self.tables = dict(tables)
        self.space = space
        self.scatter = dict(scatter)
        self.data = {f: (math.nan, 0.0, 1) for f in tables}
        self.density, self.series = {}, {}
        self._prepare()
        self.bound = self._bound(matrix_conductivity, dict)
        return self

    def predictive_of_model(self, cols: Mapping[str, np.ndarray]
                            ) -> tuple[np.ndarray, np.ndarray]:
        """(k, its variance without the measurement's), each (F, N) in :attr:`order`, at
        the parameter ``cols``: the RVE scatter, the level's own sd, the error bound, an
        effect's variance and the pooled packing sd, W/(m K) and (W/(m K))^2."""
        k, err, extra = self._evaluate(cols)
        v = (variance(0.0, k, err, self._scatter, self._model_sd) + extra * k ** 2
             + (self._pack * k) ** 2)
        return k, v

    def _prepare(self) -> None:
        tabs = list(self.tables.values())
        self.order = list(self.tables)
        by: dict[tuple, list[int]] = {}
        for i, t in enumerate(tabs):
            key = (len(t.parameters),) + tuple((a[0], a[-1], a.size) for a in t.axes)
            by.setdefault(key, []).append(i)
        self._stacks = []
        for key, idx in by.items():
            ts = [tabs[i] for i in idx]
            # log k, the error bound and the shared term on one first axis: one gather each
            values = np.stack([np.stack([np.asarray(getattr(t, a), float) for t in ts])
                               for a in ("log_k", "rel_err", "shared")])
            names = [[f"log10 {t.parameters[d]}" for t in ts] for d in range(key[0])]
            self._stacks.append((np.array(idx), key[0], ts[0].axes, names, values))
        self._fillers = sorted({x for t in tabs for x in t.elasticity if x != "film_nm"})
        self._s = np.array([[t.elasticity.get(x, 0.0) for x in self._fillers] for t in tabs]
                           ).reshape(len(tabs), len(self._fillers))
        self._film = np.array([t.elasticity.get("film_nm", 0.0) for t in tabs])
        self._system = np.array([t.system is not None for t in tabs], dtype=float)
        self._group = [self.space.groups[f][0] for f in self.order]
        self._z = np.array([self.space.groups[f][1] for f in self.order])
        # the formulations with a shared correction offset (and those with a slope too)
        known = set(self.space.names) | set(self.space.held)
        self._offset_rows = np.array([i for i, g in enumerate(self._group)
                                      if f"offset_{g}" in known], dtype=int)
        self._offset_names = [f"offset_{self._group[i]}" for i in self._offset_rows]
        sloped = [j for j, i in enumerate(self._offset_rows)
                  if f"slope_{self._group[i]}" in known]
        self._slope_at = np.array(sloped, dtype=int)
        self._slope_names = [f"slope_{self._group[self._offset_rows[j]]}" for j in sloped]
        col = lambda a: np.array(a, dtype=float)[:, None]  # noqa: E731 - (F, 1) columns
        self._mean = col([self.data[f][0] for f in self.order])
        self._se = col([self.data[f][1] for f in self.order])
        self._n = col([self.data[f][2] for f in self.order])
        self._scatter = col([self.scatter[t.group] for t in tabs])
        self._model_sd = col([t.model_sd for t in tabs])
        self._pack = col([t.packing[0] if t.packing else 0.0 for t in tabs])
        self._dof = col([t.packing[1] if t.packing else 1 for t in tabs])

    def _interp(self, stack, cols: Mapping[str, np.ndarray], shift: np.ndarray
                ) -> np.ndarray:
        """(3, F_stack, N): log k, the error bound and the shared term of one stack of
        tables, interpolated (multi)linearly at the points' resistances."""
        idx, dim, axes, names, values = stack
        n = shift.shape[-1]
        if dim == 0:
            return np.repeat(values[:, :, None], n, axis=2)
        at = [np.stack([cols[name] for name in names[d]]) + shift for d in range(dim)]
        lo = np.array([float(ax[0]) for ax in axes])
        step = np.array([float(ax[1] - ax[0]) for ax in axes])
        last = np.array([ax.size - 1 - 1e-9 for ax in axes])
        if dim == 1:
            return linear_1d(values, at[0], lo[0], step[0], last[0])
        return linear_2d(values, at[0], at[1], lo, step, last)

    def conductivities_all(self, cols: Mapping[str, np.ndarray]
                           ) -> tuple[np.ndarray, np.ndarray]:
        """(k, error bound), each (F, N) in :attr:`order`, at the parameter ``cols``, W/(m K),
        with the shared correction term, the model form and a candidate effect applied."""
        k, err, _ = self._evaluate(cols)
        return k, err

    def _evaluate(self, cols: Mapping[str, np.ndarray]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k, error bound, the effect's relative variance), each (F, N)."""
        n = next(iter(cols.values())).size
        zeros = np.zeros(n)
        F = len(self.order)
        bound = self.bound
        ln_lam = np.repeat(cols.get(f"ln k_{self.space.matrix}", zeros)[None, :], F, axis=0)
        if bound is not None:
            ln_lam = ln_lam + bound.ln_matrix_shift(cols, n)
        table = np.empty((3, F, n))
        for stack in self._stacks:
            table[:, stack[0]] = self._interp(stack, cols, ln_lam[stack[0]] / math.log(10))
        log_k, rel_err, shared = table
        ln_fac = (1 - self._s.sum(axis=1))[:, None] * ln_lam
        for j, filler in enumerate(self._fillers):
            ln_fac += self._s[:, j][:, None] * cols.get(f"ln k_{filler}", zeros)[None, :]
        film = cols.get("film_nm", zeros)[None, :]
        extra = np.zeros((F, n))
        if bound is not None:
            film = film * bound.film_factor(cols, n)
            log10_r = bound.log10_r(cols, ln_lam)
            log_k = log_k + bound.ln_k_shift(cols, log10_r)
            extra = bound.relative_variance(cols, log10_r)
        ln_fac += self._film[:, None] * film
        k = np.exp(log_k + ln_fac)
        err = rel_err * k
        tau = cols.get("tau_offset", 0.0)
        tau_s = cols.get("tau_slope", 0.0)
        rows = self._offset_rows
        if rows.size:
            scale = np.sqrt(self._system[rows][:, None] * shared[rows] ** 2 + tau ** 2)
            shift = scale * np.stack([cols[name] for name in self._offset_names])
            if self._slope_at.size:
                at = self._slope_at
                shift[at] = shift[at] + tau_s * np.stack(
                    [cols[name] for name in self._slope_names]) * self._z[rows[at]][:, None]
            k[rows] *= 1 + shift
        if bound is not None:
            seen = bound.apparent(k, cols)
            err, k = err * seen / k, seen
        return k, err, extra

    def conductivities(self, cols: Mapping[str, np.ndarray], f: str
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(k, error bound), each (N,), of formulation ``f`` (:meth:`conductivities_all`)."""
        k, err = self.conductivities_all(cols)
        i = self.order.index(f)
        return k[i], err[i]

    def terms(self, theta: np.ndarray) -> np.ndarray:
        """Each formulation's log-likelihood term, (F, N) in :attr:`order`, at the points
        ``theta`` (N, D): :func:`~itr_identify.inference.calibrate.log_likelihood` of the
        measured mean with :func:`~itr_identify.inference.calibrate.variance` (plus a
        candidate effect's own variance), the pooled packing variance counted as an
        estimate; with a density column, each formulation's density term added to its
        own (:func:`density_data`)."""
        cols = self.space.columns(np.atleast_2d(theta))
        k, err, extra = self._evaluate(cols)
        v = variance(self._se, k, err, self._scatter, self._model_sd) + extra * k ** 2
        out = log_likelihood(self._mean - k, v, self._se ** 2, self._n,
                             estimated=((self._pack * k) ** 2, self._dof))
        return out + self._density_terms(cols, k.shape[1]) + self._series_terms(cols, k)

    def _series_terms(self, cols: Mapping[str, np.ndarray], k: np.ndarray) -> np.ndarray:
        """(F, N) the Gaussian log likelihood of each thickness series' shape: the mean at
        each thickness over the mean at the thinnest, against the model's (1 without a
        tester's contact; the model's own errors multiply every thickness alike and cancel)."""
        out = np.zeros(k.shape)
        for i, f in enumerate(self.order):
            if f not in self.series:
                continue
            t, m, se = self.series[f]
            pred = (self.bound.series_shape(cols, f, k[i], t) if self.bound is not None
                    else np.ones((t.size - 1, k.shape[1])))
            obs = (m[1:] / m[0])[:, None]
            var = ((se[1:] ** 2 + (m[1:] / m[0]) ** 2 * se[0] ** 2) / m[0] ** 2)[:, None]
            out[i] = (-0.5 * ((obs - pred) ** 2 / var + np.log(2 * math.pi * var))).sum(axis=0)
        return out

    def _density_terms(self, cols: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """(F, N) the Gaussian log likelihood of each measured mean density."""
        out = np.zeros((len(self.order), n))
        if not self.density:
            return out
        if self.bound is not None:
            phi, voids = self.bound.composition(cols, n)
        else:
            phi = np.repeat(np.array([sum(self.tables[f].fractions.values())
                                      for f in self.order])[:, None], n, axis=1)
            voids = np.zeros_like(phi)
        for i, f in enumerate(self.order):
            if f not in self.density:
                continue
            mean, se, rho_filler, rho_matrix = self.density[f]
            rho = phi[i] * rho_filler + (1.0 - phi[i] - voids[i]) * rho_matrix
            var = se ** 2 + (DENSITY_MODEL_SD * rho) ** 2
            out[i] = -0.5 * ((mean - rho) ** 2 / var + np.log(2 * math.pi * var))
        return out

    def chi_square_terms(self, theta: np.ndarray) -> np.ndarray:
        """Each formulation's Gaussian chi-square term, (F, N) in :attr:`order`: the squared
        residual of the measured mean over the likelihood's variance plus the pooled
        packing variance (what :meth:`terms` counts, without the Student t's tails)."""
        k, v = self.predictive(theta)
        return (self._mean - k) ** 2 / v

    def predictive(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(model k, the variance of a measured mean about it), each (F, N) in
        :attr:`order`, W/(m K) and (W/(m K))^2: the likelihood's variance plus the pooled
        packing variance."""
        cols = self.space.columns(np.atleast_2d(theta))
        k, err, extra = self._evaluate(cols)
        v = (variance(self._se, k, err, self._scatter, self._model_sd) + extra * k ** 2
             + (self._pack * k) ** 2)
        return k, v

    def per_formulation(self, theta: np.ndarray) -> dict[str, np.ndarray]:
        """Each formulation's log-likelihood term (N,) at the points ``theta`` (N, D)."""
        return dict(zip(self.order, self.terms(theta)))

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        return self.terms(theta).sum(axis=0)

    def log_posterior(self, theta: np.ndarray) -> np.ndarray:
        """Unnormalised log posterior (N,) of the points ``theta`` (N, D)."""
        theta = np.atleast_2d(theta)
        lp = self.space.log_prior(theta)
        ok = np.isfinite(lp)
        if ok.all():
            return lp + self(theta)
        out = np.full(theta.shape[0], -np.inf)
        if ok.any():
            out[ok] = lp[ok] + self(theta[ok])
        return out


#: Autocorrelation times each parameter's chain must span after burn-in (emcee's rule of
#: thumb is 50) where the chain's draws are the posterior.
CHAIN_TAUS = 50
#: Autocorrelation times the chain spans after burn-in before it shapes the importance
#: proposal (:func:`refine`): its mean and covariance from walkers x 20 independent draws
#: (4,000 or more); where the importance draws are then worth :data:`TARGET_DRAWS`, they
#: are the posterior and the chain stops; else it runs on to :data:`CHAIN_TAUS`.
PROPOSAL_TAUS = 20
#: Independent draws the chain must be worth: the 5 % and 95 % quantiles of log10 R then
#: carry a Monte-Carlo error of a few tenths of a per cent of R, and a run twice as long
#: moves no interval end by more than about 1 %.
TARGET_DRAWS = 20000
#: Walkers: the likelihood is evaluated for the whole half-ensemble at once, so many walkers
#: cost little more per step than few, and the draws a step is worth grow with them.
WALKERS_PER_DIM = 16
WALKERS_MIN = 64
#: Steps of the first round (later rounds run what the rule is then expected to need), and
#: the most steps before the sampler says it did not converge.
ROUND_STEPS = 2000
MAX_STEPS = 100000


def weighted_quantile(x: np.ndarray, q, weights: np.ndarray | None = None) -> np.ndarray:
    """Quantiles ``q`` of the draws ``x`` with ``weights`` (None: equal), interpolated in
    the cumulative weight at each draw's centre."""
    if weights is None:
        return np.quantile(x, q)
    order = np.argsort(x)
    w = weights[order]
    c = (np.cumsum(w) - 0.5 * w) / w.sum()
    return np.interp(q, c, x[order])


@dataclass(frozen=True, eq=False)
class JointPosterior:
    """Draws of a joint posterior, weighted (frozen).

    Attributes
    ----------
    names : tuple of str
        The sampled parameters (columns of :attr:`samples`).
    samples : ndarray
        (S, D) the chain's draws after burn-in, walkers and steps flattened.
    weights : ndarray
        (S,) their normalised weights (equal for a chain's draws).
    held : dict
        Parameters held at a value.
    log_likelihood : ndarray
        (S,) the log likelihood of each draw.
    autocorr : dict
        The chain's integrated autocorrelation time per parameter, steps.
    acceptance : float
        Mean acceptance fraction of the walkers.
    walkers, steps, burn, seed : int
    converged : bool
        Whether the sampler met its rule (:func:`sample`): importance draws worth
        :data:`TARGET_DRAWS` from a chain spanning :data:`PROPOSAL_TAUS` autocorrelation
        times, or a chain spanning :data:`CHAIN_TAUS` and worth as many itself.
    effective_draws : float
        What the draws are worth in independent draws (walkers x steps over the longest
        autocorrelation time).
    log_evidence, log_evidence_se : float
        ``ln Z``, the data's likelihood averaged over the prior, and its Monte-Carlo
        standard error (:func:`refine`).
    source : str
        ``chain`` (the chain's draws, equal weights) or ``importance`` (:func:`refine`'s
        independent draws with their weights, used where they are worth
        :data:`TARGET_DRAWS`: the chain then only shapes their proposal).
    marginals : dict
        Per sampled name (``log10 R_...``) its Rao-Blackwell :class:`~.marginal.Marginal`
        (:func:`marginal_of`), which :meth:`quantile` reads where present.
    """

    names: tuple[str, ...]
    samples: np.ndarray
    weights: np.ndarray
    held: dict[str, float]
    log_likelihood: np.ndarray
    autocorr: dict[str, float]
    acceptance: float
    walkers: int
    steps: int
    burn: int
    seed: int
    converged: bool
    effective_draws: float = float("nan")
    log_evidence: float = float("nan")
    log_evidence_se: float = float("nan")
    source: str = "chain"
    marginals: dict[str, Marginal] = field(default_factory=dict)

    def column(self, name: str) -> np.ndarray:
        if name in self.held:
            return np.full(self.samples.shape[0], float(self.held[name]))
        if name not in self.names:
            raise ValueError(f"name: no parameter {name!r} (have {', '.join(self.names)})")
        return self.samples[:, self.names.index(name)]

    @property
    def resistances(self) -> list[str]:
        """The flat names of the sampled resistances."""
        return [n.split(" ", 1)[1] for n in self.names if n.startswith("log10 ")]

    def quantile(self, name: str, q) -> np.ndarray:
        """Quantiles of a parameter (its sampled scale: log10 R, ln k, nm, ...): from its
        Rao-Blackwell marginal where :attr:`marginals` has one, else the weighted draws'."""
        if name in self.marginals:
            return self.marginals[name].quantile(q)
        return weighted_quantile(self.column(name), q, self.weights)

    def point(self, resistance: str) -> float:
        """The posterior median of ln R (the point quoted), m^2 K/W."""
        return float(10 ** self.quantile(f"log10 {resistance}", 0.5))

    def interval(self, resistance: str, level: float = 0.9) -> tuple[float, float]:
        """The equal-tailed ``level`` credible interval of R, m^2 K/W."""
        a = (1 - level) / 2
        lo, hi = self.quantile(f"log10 {resistance}", [a, 1 - a])
        return float(10 ** lo), float(10 ** hi)

    def half_width_factor(self, resistance: str, level: float = 0.9) -> float:
        """``F = sqrt(hi / lo)``: the interval is the point times or over about F."""
        lo, hi = self.interval(resistance, level)
        return math.sqrt(hi / lo)

    def resample(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` row indices drawn by weight (systematic resampling): equal-weight draws."""
        rng = np.random.default_rng(seed)
        c = np.cumsum(self.weights)
        c /= c[-1]
        return np.minimum(np.searchsorted(c, (rng.uniform() + np.arange(n)) / n),
                          len(c) - 1)

    def counts(self, n: int, seed: int = 0) -> np.ndarray:
        """How often each row counts in about ``n`` draws by weight: ``floor(n w + u)``
        (``u`` uniform per row, seeded). Unlike :meth:`resample`, a change of the weights
        by rounding (another solver's tables) leaves the counts as they are."""
        u = np.random.default_rng(seed).uniform(size=self.weights.size)
        return np.floor(n * self.weights / self.weights.sum() + u).astype(int)

    def counted_rows(self, n: int, seed: int = 0) -> np.ndarray:
        """About ``n`` row indices by weight, each row :meth:`counts` times."""
        return np.repeat(np.arange(self.weights.size), self.counts(n, seed))

    def summary(self) -> dict[str, Any]:
        """Per resistance its point, interval and F; the sampler's diagnostics."""
        return {"parameters": {r: {"point": self.point(r), "interval_90": self.interval(r),
                                   "half_width_factor": self.half_width_factor(r),
                                   "unit": "m^2 K/W", "point_is": "posterior median of ln R",
                                   "quantiles_from": ("Rao-Blackwell marginal"
                                                      if f"log10 {r}" in self.marginals
                                                      else "weighted draws")}
                               for r in self.resistances},
                "sampler": {"library": "emcee", "walkers": self.walkers, "steps": self.steps,
                            "burn": self.burn, "seed": self.seed,
                            "acceptance": self.acceptance, "converged": self.converged,
                            "autocorr_steps": self.autocorr,
                            "effective_draws": self.effective_draws,
                            "log_evidence": self.log_evidence,
                            "log_evidence_se": self.log_evidence_se,
                            "draws_from": self.source}}


def marginal_of(likelihood: JointLikelihood, posterior: JointPosterior, name: str, *,
                draws: int = MARGINAL_DRAWS, grid: int = MARGINAL_GRID,
                seed: int = 0) -> Marginal:
    """The Rao-Blackwell marginal of sampled parameter ``name`` (:mod:`.marginal`): about
    ``draws`` of the posterior by weight (seeded), at each the exact conditional density over
    ``grid`` points of ``name``'s prior range (a normal's: +-8 sd; a half-normal's:
    0-8 scale), averaged."""
    sp = likelihood.space
    if name not in sp.names:
        raise ValueError(f"name: no sampled parameter {name!r} (have {', '.join(sp.names)})")
    j = sp.names.index(name)
    lo, hi = ((sp.a[j], sp.b[j]) if sp.kinds[j] == "uniform" else
              (sp.a[j] - 8 * sp.b[j], sp.a[j] + 8 * sp.b[j]) if sp.kinds[j] == "normal" else
              (0.0, 8 * sp.b[j]))
    # each draw counted floor(draws w + u) times, u uniform per draw (seeded): as many
    # draws as asked on average, each by its weight, and a count that a change of the
    # weights by rounding (another solver's tables, 1e-9) leaves as it is; a systematic
    # resampling would move a draw across its cut and the quantiles by 1e-4
    counts = posterior.counts(draws, seed=seed)
    keep = counts > 0
    return rao_blackwell(likelihood.log_posterior, posterior.samples[keep], j,
                         lo=float(lo), hi=float(hi), grid=grid, counts=counts[keep])


def with_marginals(likelihood: JointLikelihood, posterior: JointPosterior, *,
                   draws: int = MARGINAL_DRAWS) -> JointPosterior:
    """``posterior`` with the Rao-Blackwell marginals of its resistances attached (over
    about ``draws`` of its draws, seeded by the posterior's seed), which its points and
    intervals then read."""
    names = [n for n in posterior.names if n.startswith("log10 ")]
    return replace(posterior, marginals={
        n: marginal_of(likelihood, posterior, n, draws=draws, seed=posterior.seed + k)
        for k, n in enumerate(names)})


#: Importance draws of :func:`refine`, and per independent draw :func:`sample` targets (a
#: t fitted to the chain is worth about one draw in 15 on Table 3's posterior; 80 per target
#: makes the posterior worth about four times the target: with 20 the 95 % end of R_Al2O3
#: moved 2.2 % when the chain doubled, with 80 at most 0.9 %, for 20 s more per run).
REFINE_DRAWS = 400_000
REFINE_PER_TARGET = 80
#: Degrees of freedom and covariance inflation of the refinement's multivariate t, and its
#: rounds (each refits the proposal on the previous round's weighted draws).
REFINE_DF = 5
REFINE_INFLATE = 1.5
REFINE_ROUNDS = 2


def refine(likelihood: JointLikelihood, chain: np.ndarray, *, seed: int,
           draws: int = REFINE_DRAWS
           ) -> tuple[np.ndarray, np.ndarray, float, float, float, np.ndarray]:
    """Importance sampling from an even mixture of two multivariate t (``REFINE_DF`` dof)
    fitted to the chain's draws (their mean and covariance times ``REFINE_INFLATE``, refitted
    once on the weighted draws): one in the parameters themselves, one in the space's open
    coordinates (:meth:`JointSpace.to_open`: each uniform parameter on its logit, where a
    resistance whose posterior fills its prior's range is a bell, not a box). Each alone
    misses some of Table 3's posteriors (in the parameters the area posterior's draws are
    worth a few per cent of the target; on the logit alone the gap posterior's low 5 % end
    of R_AlN came out 6 % above a long chain's while its weights looked fine); the mixture
    covers both. ``draws`` points, each weighted by posterior over proposal, evaluated
    together. The mean weight is the evidence ``Z`` (the prior normalised), with its
    Monte-Carlo standard error; the weights' effective number says how far to trust it.
    Returns (draws, normalised weights, effective draws, ln Z, its standard error, the
    draws' log posterior) of the round with the most effective draws."""
    rng = np.random.default_rng(seed + 7919)
    space = likelihood.space
    parts = [_fitted(chain), _fitted(space.to_open(chain))]
    best = None
    for _ in range(REFINE_ROUNDS):   # population Monte Carlo: refit on the weighted draws
        out = _importance(likelihood, parts, rng, draws)
        if best is None or out[2] > best[2]:
            best = out
        x, w = out[0], out[1]
        parts = [_fitted(x, w), _fitted(space.to_open(x), w)]
    return best


def _fitted(x: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(centre, Cholesky factor of the covariance times ``REFINE_INFLATE``) of the draws
    ``x`` (N, D) with weights ``w`` (None: equal)."""
    mu = x.mean(axis=0) if w is None else w @ x
    d = x - mu
    cov = np.atleast_2d(np.cov(x, rowvar=False) if w is None else (d * w[:, None]).T @ d)
    dim = mu.size
    cov = REFINE_INFLATE * cov + 1e-12 * np.eye(dim) * np.trace(cov) / dim
    return mu, np.linalg.cholesky(cov)


def _t_logpdf(y: np.ndarray, mu: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """Log density (N,) of the multivariate t (``REFINE_DF`` dof) of centre ``mu`` and
    scale ``chol chol^T`` at the rows of ``y``."""
    from scipy.linalg import solve_triangular

    dim = mu.size
    r2 = np.sum(solve_triangular(chol, (y - mu).T, lower=True) ** 2, axis=0)
    return (special.gammaln((REFINE_DF + dim) / 2) - special.gammaln(REFINE_DF / 2)
            - 0.5 * dim * math.log(REFINE_DF * math.pi) - np.sum(np.log(np.diag(chol)))
            - 0.5 * (REFINE_DF + dim) * np.log1p(r2 / REFINE_DF))


def _importance(likelihood: JointLikelihood, parts: list[tuple[np.ndarray, np.ndarray]],
                rng: np.random.Generator, draws: int
                ) -> tuple[np.ndarray, np.ndarray, float, float, float, np.ndarray]:
    """One round of :func:`refine` with its two t (``parts``: in the parameters, in the
    open coordinates), half the draws from each."""
    space = likelihood.space
    (mu_x, l_x), (mu_y, l_y) = parts
    dim = mu_x.size
    half = draws // 2
    z = rng.standard_normal((draws, dim))
    u = rng.chisquare(REFINE_DF, draws) / REFINE_DF
    x = np.vstack([mu_x + (z[:half] @ l_x.T) / np.sqrt(u[:half])[:, None],
                   space.from_open(mu_y + (z[half:] @ l_y.T) / np.sqrt(u[half:])[:, None])[0]])
    inside = space.inside(x)
    y = space.to_open(x)
    with np.errstate(divide="ignore", invalid="ignore"):
        open_part = np.where(inside, _t_logpdf(y, mu_y, l_y) - space.log_jacobian(y), -np.inf)
        logq = np.logaddexp(_t_logpdf(x, mu_x, l_x), open_part) - math.log(2)
    logp = np.concatenate(list(map_chunks(likelihood.log_posterior, x, chunk=20000)))
    with np.errstate(invalid="ignore"):
        logw = np.where(np.isfinite(logp), logp - logq, -np.inf)
    top = np.max(logw)
    w = np.exp(logw - top)
    mean_w = w.mean()
    ln_z = top + math.log(mean_w)
    se = float(w.std(ddof=1) / math.sqrt(draws) / mean_w)
    w /= w.sum()
    return x, w, float(1 / np.sum(w ** 2)), ln_z, se, logp


def _autocorr(chain: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time per parameter, steps (emcee's estimator, its
    short-chain warning silenced: the caller's rule decides)."""
    import logging

    import emcee

    log = logging.getLogger("emcee.autocorr")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        return emcee.autocorr.integrated_time(chain, quiet=True)
    finally:
        log.setLevel(level)


def _start(likelihood: JointLikelihood, rng: np.random.Generator, walkers: int
           ) -> np.ndarray:
    """Walkers' start: the best of many prior draws by posterior, with their spread (the
    top 2 ``walkers`` draws, ``walkers`` of them at random)."""
    draws = likelihood.space.draw(rng, 200 * walkers)
    lp = likelihood.log_posterior(draws)
    top = np.argsort(lp)[::-1][:2 * walkers]
    return draws[rng.choice(top, walkers, replace=False)]


def sample(likelihood: JointLikelihood, *, seed: int = 0, walkers: int | None = None,
           steps: int | None = None, burn: int | None = None,
           progress: bool = False, marginals: bool = True,
           evidence_draws: int | None = None,
           marginal_draws: int = MARGINAL_DRAWS) -> JointPosterior:
    """Sample the posterior of ``likelihood`` (its space's priors) with emcee: ``walkers``
    (default :data:`WALKERS_PER_DIM` per dimension, at least :data:`WALKERS_MIN`)
    differential-evolution walkers, seeded; by default a first round of :data:`ROUND_STEPS`
    steps, then rounds of what the autocorrelation says the rule needs (after a burn-in of
    a third of the steps). Once every parameter's chain spans :data:`PROPOSAL_TAUS`
    autocorrelation times, a t fitted to it is the proposal of importance sampling
    (:func:`refine`, ``evidence_draws`` draws, default :data:`REFINE_PER_TARGET` x
    :data:`TARGET_DRAWS`); where its weighted draws are worth :data:`TARGET_DRAWS`
    independent ones they are the posterior (``source`` ``importance``) and the chain
    stops; else the chain runs on until it spans :data:`CHAIN_TAUS` autocorrelation times
    and is worth :data:`TARGET_DRAWS` draws itself (walkers x steps over the longest
    autocorrelation time; ``source`` ``chain``, or ``importance`` where a refit on the
    longer chain reaches the target), at most :data:`MAX_STEPS` (then ``converged`` is
    False and the caller says so). ``steps``: run exactly that many after ``burn`` (the
    chain's draws are then the posterior; the importance draws give the evidence). The
    resistances' marginals are then attached (:func:`with_marginals`, over
    ``marginal_draws`` draws) unless ``marginals`` is False (a posterior whose resistance
    quantiles nobody quotes). ``progress``: a bar
    over the steps whose total is, after each round, the steps the rule is expected to
    need (so its ETA     is the sampler's)."""
    import emcee

    space = likelihood.space
    dim = space.dim
    walkers = walkers or max(WALKERS_MIN, WALKERS_PER_DIM * dim + dim % 2)
    rng = np.random.default_rng(seed)
    start = _start(likelihood, rng, walkers)
    sampler = emcee.EnsembleSampler(walkers, dim, likelihood.log_posterior, vectorize=True,
                                    moves=[(emcee.moves.DEMove(), 1.0)])
    sampler.random_state = np.random.RandomState(seed).get_state()
    evidence_draws = evidence_draws or REFINE_PER_TARGET * TARGET_DRAWS
    run = _run_chain(likelihood, sampler, start, seed=seed, steps=steps, burn=burn,
                     evidence_draws=evidence_draws, progress=progress)
    post = _chain_posterior(likelihood, sampler, run, seed=seed,
                            evidence_draws=evidence_draws)
    return with_marginals(likelihood, post, draws=marginal_draws) if marginals else post


@dataclass(frozen=True, eq=False)
class _ChainRun:
    """Where :func:`_run_chain` stopped: the steps run (``total``), burnt (``discard``) and
    kept, the autocorrelation time per parameter (steps), what the kept draws are worth,
    whether the rule was met, the importance draws (:func:`refine`'s tuple, None before
    the chain spans :data:`PROPOSAL_TAUS`) and the step they were drawn at, and whether a
    fixed number of steps was asked (``fixed``)."""

    total: int
    discard: int
    kept: int
    tau: np.ndarray
    worth: float
    converged: bool
    refined: tuple | None
    refined_at: int
    fixed: bool


def _run_chain(likelihood: JointLikelihood, sampler: Any, start: np.ndarray, *, seed: int,
               steps: int | None, burn: int | None, evidence_draws: int,
               progress: bool) -> _ChainRun:
    """Run ``sampler`` from ``start`` by the rule of :func:`sample` (``steps`` after
    ``burn`` exactly where given); the importance draws are made once the chain spans
    :data:`PROPOSAL_TAUS` autocorrelation times, and end the run where they are worth
    :data:`TARGET_DRAWS`."""
    from tqdm.auto import tqdm

    walkers = sampler.nwalkers
    state, total, n = start, 0, ROUND_STEPS
    target = steps + (burn or 0) if steps is not None else None
    refined, refined_at = None, 0   # the importance draws, once the chain spans PROPOSAL_TAUS
    bar = tqdm(total=target or ROUND_STEPS, desc="joint posterior", unit="step",
               disable=not progress, leave=False)
    while True:
        n = n if target is None else target - total
        state = sampler.run_mcmc(state, n, progress=False)
        total += n
        bar.update(n)
        discard = burn if burn is not None else total // 3
        tau = _autocorr(sampler.get_chain(discard=discard))
        kept = total - discard
        worth = walkers * kept / max(float(np.max(tau)), 1.0)
        converged = bool(np.all(kept >= CHAIN_TAUS * tau) and worth >= TARGET_DRAWS)
        if target is None and refined is None and np.all(kept >= PROPOSAL_TAUS * tau):
            refined = refine(likelihood, sampler.get_chain(discard=discard, flat=True),
                             seed=seed, draws=evidence_draws)
            refined_at = total
            if refined[2] >= TARGET_DRAWS:     # the draws the posterior is read from
                converged = True
                break
        if target is not None or converged or total >= MAX_STEPS:
            break
        n = _next_round(total, tau, walkers, proposal=refined is not None)
        bar.total = total + n
        bar.set_postfix(tau=f"{np.max(tau):.0f}", worth=f"{worth:.0f}")
        bar.refresh()
    bar.close()
    return _ChainRun(total, discard, kept, tau, worth, converged, refined, refined_at,
                     fixed=target is not None)


def _next_round(total: int, tau: np.ndarray, walkers: int, *, proposal: bool) -> int:
    """Steps of the chain's next round: what the rule needs at the autocorrelation times
    ``tau`` (the kept draws are two thirds of the total), run in one go (each check of the
    autocorrelation costs a pass over the chain), at least :data:`ROUND_STEPS`, at most up
    to :data:`MAX_STEPS`: a proposal's chain first, the chain's own rule where its
    importance draws (made: ``proposal``) fell short."""
    need = 1.5 * (max(CHAIN_TAUS * float(np.max(tau)),
                      TARGET_DRAWS * float(np.max(tau)) / walkers)
                  if proposal else PROPOSAL_TAUS * float(np.max(tau)))
    return int(min(MAX_STEPS - total, max(ROUND_STEPS, 1.1 * need - total)))


def _chain_posterior(likelihood: JointLikelihood, sampler: Any, run: _ChainRun, *,
                     seed: int, evidence_draws: int) -> JointPosterior:
    """The posterior of a finished run: the importance draws where they are worth
    :data:`TARGET_DRAWS` (a run of no fixed length), else the chain's kept draws with equal
    weights; the importance draws (made again on the whole chain where those of the run
    fell short before its end) give the evidence either way."""
    space = likelihood.space
    chain = sampler.get_chain(discard=run.discard, flat=True)
    logp = sampler.get_log_prob(discard=run.discard, flat=True)
    ll = logp - space.log_prior(chain)
    refined = run.refined
    if refined is None or (refined[2] < TARGET_DRAWS and run.refined_at < run.total):
        refined = refine(likelihood, chain, seed=seed, draws=evidence_draws)
    x, w, ess, ln_z, ln_z_se, logp_x = refined
    weights = np.full(chain.shape[0], 1.0 / chain.shape[0])
    worth, source = run.worth, "chain"
    if not run.fixed and ess >= TARGET_DRAWS:
        # independent draws that the chain's own need not match: where they are worth the
        # target, they are the posterior (their error is the weights' effective number)
        keep = w > 0
        chain, weights = x[keep], w[keep] / w[keep].sum()
        ll = logp_x[keep] - space.log_prior(chain)
        worth, source = ess, "importance"
    return JointPosterior(space.names, chain, weights, dict(space.held), ll,
                          dict(zip(space.names, map(float, run.tau))),
                          float(np.mean(sampler.acceptance_fraction)), sampler.nwalkers,
                          run.kept, run.discard, seed, run.converged, worth, ln_z, ln_z_se,
                          source)
