"""Bayesian calibration of interface resistances on reduced-basis forward models.

The likelihood of one formulation's measured mean ``m`` given parameters ``theta`` is a
Student t (:func:`log_likelihood`: the replicate variance is estimated from few replicates,
its degrees of freedom by Welch-Satterthwaite) of squared scale

    v(theta) = s^2 / n  +  (sigma_rve k(theta))^2  +  e(theta)^2,

``s^2 / n`` the replicate variance of the mean (:mod:`itr_identify.inference.measurements`)
(plus ``(u k)^2``, ``u`` the model level's relative uncertainty: in a later stage the spread
of its k_iso over the earlier stages' posterior, see :mod:`itr_identify.inference.pipeline`,
and the faithful correction's, :mod:`itr_identify.forward.fidelity`), ``sigma_rve`` the relative
RVE-to-RVE scatter of the k_iso of one RVE
(:attr:`itr_identify.forward.model.ForwardModel.rve_scatter`, pooled over a filler system),
``k`` the forward model's k_iso (the first replica's reduced basis scaled to the replica
mean) and ``e`` its certified error bound. The RVE term is an upper bound of that
part of the error: the replica mean misses the ensemble mean by ``sigma_rve / sqrt(R)``.
The prior is log-uniform over the reduced-basis box.

The posterior is evaluated on a dense grid in log10 R (no sampler to tune or converge): one
over the prior, then one of as many points over the region that holds the posterior, stage
by stage as the paper's hierarchy: first each single-filler system (its ``R_<f>_silicone``
and, under the area parametrisation, ``Rff_<f>_<f>``), then each two-filler system for its
new parameter with the earlier stages' posterior samples carried along (a *cut* posterior:
the hybrids do not feed back into the single-filler parameters). A stage may add at most
two parameters.

Per parameter the result holds the best value (the grid point of highest posterior), the
posterior median and 90 % credible interval (:func:`credible_interval`: equal-tailed, moved
just far enough to hold the best value, so a best value is always inside its interval; where
the posterior piles up at an end of the prior the interval is one-sided) and how far the data
determine it (:meth:`Posterior.determination`: one rule for the headline's flags and the
identifiability statements); per stage the correlation of log10 values and an
identifiability statement: the parameters the data do not determine, and the principal
directions of the posterior covariance whose spread is more than half the prior's
(combinations the data do not separate).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.special import gammaln

from ..forward.model import ForwardModel
from .marginal import Marginal
from .measurements import Measurements

__all__ = [
    "DETERMINATIONS",
    "EDGE_FACTOR",
    "UNDETERMINED_DECADES",
    "UNIDENTIFIED_RATIO",
    "Posterior",
    "Stage",
    "StageResult",
    "calibrate",
    "credible_interval",
    "log_likelihood",
    "pooled_scatter",
    "residuals",
    "stages_of",
    "variance",
]

#: Depth (in log-likelihood) of the region that the second, refined grid covers.
REFINE_DEPTH = 25.0

#: A principal direction whose posterior spread exceeds this fraction of the prior's is
#: reported as not determined by the data.
UNIDENTIFIED_RATIO = 0.5

#: An interval end or best value within this factor of a prior end counts as at that end.
EDGE_FACTOR = 1.5
#: A 90 % interval wider than this many decades determines nothing worth quoting.
UNDETERMINED_DECADES = 2.0
#: How far the data determine one parameter (:meth:`Posterior.determination`), the first
#: that applies: its best value at an end of the prior (within :data:`EDGE_FACTOR`: the data
#: pull it out of the range searched); its 90 % interval reaching both ends of the prior or
#: wider than :data:`UNDETERMINED_DECADES` decades; reaching one end (bounded on one side
#: only); none of these.
DETERMINATIONS = ("at the prior's edge", "undetermined", "bounded on one side", "determined")


def _weighted_quantile(x: np.ndarray, q, w: np.ndarray) -> np.ndarray:
    order = np.argsort(x)
    ws = w[order]
    c = (np.cumsum(ws) - 0.5 * ws) / ws.sum()
    return np.interp(q, c, x[order])


def credible_interval(log_samples: np.ndarray, best_log10: float | None = None,
                      level: float = 0.9) -> tuple[float, float]:
    """The ``level`` credible interval of 1-D log10 samples, in log10: the equal-tailed one,
    or, where ``best_log10`` (the best point's value) lies outside it, the interval of the
    same mass moved just far enough to hold it.

    The best point is the grid point of highest joint posterior (in a later stage: given the
    earlier stages' best values), not a summary of the samples. Where the posterior piles
    up at an end of the prior, that point is the prior's end while the equal-tailed interval
    stops a tail short of it; where the joint maximum lies in a tail of the marginal (a
    ridge), it can lie outside too. Moving the interval keeps its mass and puts the best value
    inside; when the move reaches the samples' end the interval is one-sided (from the
    ``1 - level`` quantile up to the best value, or from the best value to the ``level``
    quantile)."""
    x = np.asarray(log_samples, dtype=np.float64)
    a = (1 - level) / 2
    lo, hi = (float(v) for v in np.quantile(x, [a, 1 - a]))
    if best_log10 is None or lo <= best_log10 <= hi:
        return lo, hi
    b = float(best_log10)
    if b > hi:
        above = min(float(np.mean(x > b)), a)          # the upper tail that may stay
        lo, hi = (float(v) for v in np.quantile(x, [1 - level - above, 1 - above]))
        return lo, max(hi, b)
    below = min(float(np.mean(x < b)), a)
    lo, hi = (float(v) for v in np.quantile(x, [below, below + level]))
    return min(lo, b), hi


def _reach(lo: float, hi: float, prior: tuple[float, float]) -> tuple[bool, bool]:
    """Whether an interval (m^2 K/W) reaches the prior's lower and upper end."""
    return lo <= prior[0] * EDGE_FACTOR, hi >= prior[1] / EDGE_FACTOR


@dataclass(frozen=True)
class Stage:
    """One step of the hierarchy: formulations of one filler system and the parameters
    they identify (the others come from earlier stages)."""

    system: tuple[str, ...]
    formulations: tuple[str, ...]
    new: tuple[str, ...]
    carried: tuple[str, ...]


def stages_of(models: Mapping[str, ForwardModel]) -> list[Stage]:
    """The hierarchy for a set of forward models: single-filler systems first, then
    systems of two fillers. ValueError if a stage would add more than two parameters."""
    systems: dict[tuple[str, ...], list[str]] = {}
    for name, m in models.items():
        systems.setdefault(tuple(sorted(m.fractions)), []).append(name)
    out, known = [], []
    for system in sorted(systems, key=lambda s: (len(s), s)):
        forms = tuple(systems[system])
        params = models[forms[0]].parameters
        new = tuple(p for p in params if p not in known)
        carried = tuple(p for p in params if p in known)
        if len(new) > 2:
            raise ValueError(f"measurements: the system {'+'.join(system)} would identify "
                             f"{len(new)} parameters at once ({', '.join(new)}); measure its "
                             "single-filler formulations too")
        out.append(Stage(system, forms, new, carried))
        known += list(new)
    return out


def pooled_scatter(models: Sequence[ForwardModel]) -> float:
    """Root-mean-square relative RVE scatter of k_iso over a filler system's formulations."""
    return float(math.sqrt(np.mean([m.rve_scatter ** 2 for m in models])))


@dataclass(frozen=True, eq=False)
class StageResult:
    """What one stage of :func:`calibrate` found.

    Attributes
    ----------
    system : tuple of str
        The stage's filler system, e.g. ``("Al2O3",)`` or ``("Al2O3", "AlN")``.
    formulations : tuple of str
        The measured formulations of that system whose likelihood the stage evaluates.
    parameters : tuple of str
        Flat names of the parameters this stage identifies (values in m^2 K/W); empty
        where the stage has nothing new to identify and only tests the earlier stages.
    carried : tuple of str
        Flat names of the parameters taken from the earlier stages' posterior.
    rve_scatter : float
        Relative RVE-to-RVE scatter of k_iso pooled over the formulations
        (:func:`pooled_scatter`), dimensionless (a fraction of k_iso).
    log_likelihood_best : float
        The stage's log-likelihood (nats) at the best point: the earlier stages' best
        values and this stage's grid point of highest likelihood.
    identifiability : dict
        ``system`` ("+"-joined filler names), ``directions`` (per principal direction of
        the posterior covariance of log10 values: ``combination``, text;
        ``posterior_to_prior_sd``, dimensionless; ``determined``, bool) and ``statement``,
        text.
    axes_log10 : tuple of ndarray or None
        Per parameter, the refined grid's axis, log10 of m^2 K/W (``grid_points`` values
        each); None where ``parameters`` is empty.
    density : ndarray or None
        Marginal posterior mass per grid point over ``axes_log10`` (one axis per
        parameter, sums to 1), dimensionless; None where ``parameters`` is empty.
    """

    system: tuple[str, ...]
    formulations: tuple[str, ...]
    parameters: tuple[str, ...]
    carried: tuple[str, ...]
    rve_scatter: float
    log_likelihood_best: float
    identifiability: dict[str, Any]
    axes_log10: tuple[np.ndarray, ...] | None = None
    density: np.ndarray | None = None

    def to_dict(self) -> dict:
        """The JSON-ready form: lists of names and numbers, ``axes_log10`` and ``density``
        only where the stage identifies parameters."""
        out: dict[str, Any] = {"system": list(self.system),
                               "formulations": list(self.formulations),
                               "parameters": list(self.parameters),
                               "carried": list(self.carried), "rve_scatter": self.rve_scatter}
        if self.axes_log10 is not None:
            out["axes_log10"] = [a.tolist() for a in self.axes_log10]
        if self.density is not None:
            out["density"] = self.density.tolist()
        out["log_likelihood_best"] = self.log_likelihood_best
        out["identifiability"] = copy.deepcopy(self.identifiability)
        return out


@dataclass(frozen=True, eq=False)
class Posterior:
    """Calibrated parameters (flat names, m^2 K/W), frozen: a changed posterior is a new
    one (:func:`dataclasses.replace`).

    Attributes
    ----------
    names : list of str
    samples : ndarray (S, P)
        Posterior samples of log10 values.
    best : dict
        Highest-posterior values found on the grid.
    stages : list of StageResult
        Per stage: system, formulations, parameters, grid, marginal density,
        identifiability, log-likelihood at the best point.
    prior : (float, float)
        The log-uniform prior's range, m^2 K/W.
    model_form_sd : float
        The relative model-form error the likelihood carried (0: none;
        :mod:`itr_identify.inference.misfit`).
    log_evidence : float
        Log of the data's likelihood averaged over the prior, summed over the stages (a
        stage with no parameter of its own: its likelihood at the best values); what
        :mod:`itr_identify.inference.nuisance` weighs inputs by.
    weighted : (ndarray, ndarray), optional
        A joint posterior's weighted draws (log10 values, weights).
    marginals : dict, optional
        Per flat name its Rao-Blackwell marginal of log10 R (:mod:`.marginal`), which the
        median and interval read where present.
    """

    names: list[str]
    samples: np.ndarray
    best: dict[str, float]
    prior: tuple[float, float]
    stages: list[StageResult] = field(default_factory=list)
    model_form_sd: float = 0.0
    log_evidence: float = 0.0
    weighted: tuple[np.ndarray, np.ndarray] | None = None
    marginals: dict[str, Marginal] | None = None

    def _marginal_quantiles(self, name: str, q) -> np.ndarray | None:
        """Quantiles of log10 ``name`` from its Rao-Blackwell marginal, where it has one."""
        if self.marginals and name in self.marginals:
            return self.marginals[name].quantile(q)
        return None

    def median(self, name: str) -> float:
        m = self._marginal_quantiles(name, 0.5)
        if m is not None:
            return float(10 ** m)
        if self.weighted is not None:
            x, w = self.weighted
            return float(10 ** _weighted_quantile(x[:, self.names.index(name)], 0.5, w))
        return float(10 ** np.median(self.samples[:, self.names.index(name)]))

    def interval(self, name: str, level: float = 0.9) -> tuple[float, float]:
        """Credible interval, m^2 K/W: equal-tailed, moved where needed to hold the best
        value (:func:`credible_interval`), so ``lo <= best[name] <= hi`` always; from the
        weighted draws where the posterior has them (:attr:`weighted`: a joint posterior's
        importance draws, log10 values and weights; :attr:`samples` are then draws by
        weight, for what needs equal-weight draws), from the Rao-Blackwell marginal where
        it has one (:attr:`marginals`, log10 scale)."""
        best = self.best.get(name)
        a = (1 - level) / 2
        m = self._marginal_quantiles(name, [a, 1 - a])
        if m is not None or self.weighted is not None:
            if m is None:
                x, w = self.weighted
                m = _weighted_quantile(x[:, self.names.index(name)], [a, 1 - a], w)
            lo, hi = (float(v) for v in m)
            lo, hi = float(10 ** lo), float(10 ** hi)
            return ((min(lo, best), max(hi, best)) if best is not None else (lo, hi))
        x = self.samples[:, self.names.index(name)]
        lo, hi = credible_interval(x, None if best is None else math.log10(best), level)
        lo, hi = float(10 ** lo), float(10 ** hi)
        if best is not None:                 # exactly, past the round trip through log10
            lo, hi = min(lo, best), max(hi, best)
        return lo, hi

    def prior_ends(self, name: str) -> tuple[bool, bool]:
        """Whether the 90 % interval of ``name`` reaches the prior's lower and upper end
        (within :data:`EDGE_FACTOR`)."""
        return _reach(*self.interval(name), self.prior)

    def determination(self, name: str) -> str:
        """How far the data determine ``name``: one of :data:`DETERMINATIONS`. The one
        rule behind the headline's flags and the stages' identifiability statements."""
        p_lo, p_hi = self.prior
        best = self.best[name]
        if best <= p_lo * EDGE_FACTOR or best >= p_hi / EDGE_FACTOR:
            return DETERMINATIONS[0]
        lo, hi = self.interval(name)
        low_end, high_end = _reach(lo, hi, self.prior)
        if (low_end and high_end) or math.log10(hi / lo) > UNDETERMINED_DECADES:
            return DETERMINATIONS[1]
        if low_end or high_end:
            return DETERMINATIONS[2]
        return DETERMINATIONS[3]

    def describe(self, name: str) -> str | None:
        """:meth:`determination` of ``name`` as a phrase; None where it is determined."""
        d = self.determination(name)
        if d == DETERMINATIONS[3]:
            return None
        low_end, high_end = self.prior_ends(name)
        prior = f"the prior ({self.prior[0]:g} - {self.prior[1]:g} m^2 K/W)"
        if d == DETERMINATIONS[0]:
            end = "lower" if self.best[name] <= self.prior[0] * EDGE_FACTOR else "upper"
            side = "above" if end == "lower" else "below"
            return (f"{name} is bounded from {side} only: its best value lies at the {end} "
                    f"end of {prior}, the data pull it out of the range searched")
        if d == DETERMINATIONS[1]:
            return (f"{name} is undetermined: its 90 % interval "
                    + ("reaches both ends of " + prior if low_end and high_end else
                       f"spans more than {UNDETERMINED_DECADES:g} decades"))
        end, side = ("upper", "below") if high_end else ("lower", "above")
        return (f"{name} is bounded from {side} only: its 90 % interval reaches the {end} "
                f"end of {prior}")

    def central(self) -> dict[str, float]:
        """A central point of the posterior, m^2 K/W: the sample nearest the marginal
        medians (in log10, each parameter scaled by its posterior standard deviation).

        Where the data leave a ridge (the per-area parametrisation's R_si / Rff), the best
        grid point can lie anywhere along it, and a later stage held there fits its own
        parameter to that end of the ridge; the medians sit where most of the posterior
        mass is, and the nearest sample is a point the posterior holds (the medians of a
        ridge that bends back, or of separate modes, need not be)."""
        x = self.samples
        sd = x.std(axis=0)
        z = (x - np.median(x, axis=0)) / np.where(sd > 0, sd, 1.0)
        row = x[int(np.argmin((z ** 2).sum(axis=1)))]
        return {n: float(10 ** v) for n, v in zip(self.names, row)}

    def correlation(self) -> np.ndarray:
        """Correlation matrix of the log10 samples (P, P)."""
        if self.samples.shape[1] == 1:
            return np.ones((1, 1))
        return np.corrcoef(self.samples, rowvar=False)

    def log_likelihood_best(self) -> float:
        return float(sum(s.log_likelihood_best for s in self.stages))

    def to_dict(self) -> dict:
        params = {}
        for n in self.names:
            lo, hi = self.interval(n)
            params[n] = {"best": self.best[n], "median": self.median(n), "interval_90": [lo, hi],
                         "unit": "m^2 K/W"}
        return {"parameters": params,
                "correlation_log10": {"names": self.names,
                                      "matrix": np.round(self.correlation(), 4).tolist()},
                "identifiability": [s.identifiability for s in self.stages],
                "prior_m2K_per_W": list(self.prior),
                "log_likelihood_best": self.log_likelihood_best()}


def _grid(prior: tuple[float, float], n: int) -> np.ndarray:
    return np.linspace(math.log10(prior[0]), math.log10(prior[1]), n)


#: Gauss-Hermite nodes of the shared correction term's marginalisation (per system, centred
#: and scaled on the term's Gaussian conditional posterior, so that a term the data pin
#: down to a fraction of its prior width is integrated as accurately as a loose one).
SHARED_NODES = 9


def _stage_loglike(models: Mapping[str, ForwardModel], stage: Stage, meas: Measurements,
                   columns: dict[str, np.ndarray], scatter: float,
                   model_form_sd: float = 0.0) -> np.ndarray:
    """The stage's log likelihood per row of ``columns``: independent Student t terms per
    formulation, except that the formulations of one shipped system share its correction
    term ``delta ~ N(0, 1)`` (each moved by ``shared_sd * delta``), integrated out once per
    system (:func:`_shared_marginal`)."""
    groups: dict[str | None, list[str]] = {}
    for f in stage.formulations:   # a model without a shipped correction has no such term
        groups.setdefault(getattr(models[f], "shared_system", None), []).append(f)
    total = 0.0
    for system, forms in groups.items():
        if system is None:
            for f in forms:
                k, err = models[f].predict(columns)
                total = total + _one_loglike(models[f], meas, f, k, err, scatter,
                                             model_form_sd)
        else:
            total = total + _shared_marginal(models, forms, meas, columns, scatter,
                                             model_form_sd)
    return total


def _shared_marginal(models: Mapping[str, ForwardModel], forms: Sequence[str],
                     meas: Measurements, columns: dict[str, np.ndarray], scatter: float,
                     model_form_sd: float) -> np.ndarray:
    """``log int prod_f t_f(m_f | k_f (1 + u_f delta)) phi(delta) d delta`` per row: Gauss-
    Hermite nodes placed on the Gaussian approximation of delta's conditional posterior
    (precision ``P = 1 + sum (u_f k_f)^2 / v_f``, mean ``sum u_f k_f r_f / v_f / P``) and
    weighted by ``phi / q`` (importance form, exact for the Gaussian limit)."""
    pred = {f: models[f].predict(columns) for f in forms}
    u = {f: models[f].shared_sd(columns) for f in forms}
    prec, lin = 1.0, 0.0
    for f in forms:
        k, err = pred[f]
        v = variance(meas.standard_error(f), k, err, scatter, models[f].model_sd,
                     model_form_sd)
        a = u[f] * k
        prec = prec + a ** 2 / v
        lin = lin + a * (meas.mean(f) - k) / v
    mu, sd = lin / prec, 1 / np.sqrt(prec)
    nodes, weights = np.polynomial.hermite_e.hermegauss(SHARED_NODES)
    terms = []
    for z, w in zip(nodes, weights):
        delta = mu + sd * z
        ll = math.log(w / math.sqrt(2 * math.pi)) - 0.5 * delta ** 2 + np.log(sd) \
            + 0.5 * z ** 2   # log(w) + log phi(delta) - log q(delta), q = N(mu, sd^2)
        for f in forms:
            k, err = pred[f]
            ll = ll + _one_loglike(models[f], meas, f, k * (1 + u[f] * delta), err, scatter,
                                   model_form_sd)
        terms.append(ll)
    stack = np.stack(np.broadcast_arrays(*terms))
    top = stack.max(axis=0)
    return top + np.log(np.exp(stack - top).sum(axis=0))


def _one_loglike(model: ForwardModel, meas: Measurements, f: str, k: np.ndarray,
                 err: np.ndarray, scatter: float, model_form_sd: float) -> np.ndarray:
    """One formulation's Student t term at the model's ``k`` (W/(m K)); the shipped
    correction's packing term counts as estimated with its pooled degrees of freedom."""
    se = meas.standard_error(f)
    v = variance(se, k, err, scatter, model.model_sd, model_form_sd)
    pack = getattr(model, "packing_dof", None)
    extra = None if pack is None else ((pack[0] * k) ** 2, pack[1])
    return log_likelihood(meas.mean(f) - k, v, se ** 2, meas.values[f].size, estimated=extra)


def log_likelihood(residual: np.ndarray, v: np.ndarray, v_measured: float | np.ndarray,
                   n: int | np.ndarray, *,
                   estimated: tuple[np.ndarray, int | np.ndarray] | None = None) -> np.ndarray:
    """Log density of ``residual`` (W/(m K)) under a Student t of scale ``sqrt(v)`` whose
    degrees of freedom follow from ``v_measured`` (the squared standard error, estimated
    from ``n`` replicates, ``n - 1`` degrees of freedom) and the rest of ``v`` (taken as
    known) by Welch-Satterthwaite: ``nu = v^2 / (v_measured^2 / (n - 1))``. With the
    replicate variance estimated from four samples, a Gaussian would take a sample variance
    that came out small at face value and weigh that formulation too much; the t keeps the
    uncertainty of the estimate (for ``nu -> inf`` it is the Gaussian). ``estimated``: one
    more part of ``v`` that is an estimate, (its variance, its degrees of freedom), e.g. the
    shipped correction's pooled packing variance; it joins the sum's denominator."""
    v = np.asarray(v, dtype=np.float64)
    denom = np.asarray(v_measured, dtype=np.float64) ** 2 / (np.asarray(n) - 1)
    if estimated is not None:
        denom = denom + np.asarray(estimated[0]) ** 2 / np.maximum(estimated[1], 1)
    nu = np.minimum(v ** 2 / np.maximum(denom, 1e-300), 1e6)
    z2 = residual ** 2 / v
    return (gammaln((nu + 1) / 2) - gammaln(nu / 2) - 0.5 * np.log(nu * math.pi * v)
            - 0.5 * (nu + 1) * np.log1p(z2 / nu))


def variance(standard_error: float, k: np.ndarray, err: np.ndarray, scatter: float,
             model_sd: float = 0.0, model_form_sd: float = 0.0) -> np.ndarray:
    """Likelihood variance, (W/(m K))^2: replicate variance of the mean, RVE scatter, the
    model level's relative uncertainty ``model_sd`` (earlier stages' spread and faithful
    correction, :attr:`ForwardModel.model_sd`), the relative model-form error
    ``model_form_sd`` (:mod:`itr_identify.inference.misfit`) and the surrogate's error
    bound."""
    rel2 = scatter ** 2 + model_sd ** 2 + model_form_sd ** 2
    return standard_error ** 2 + rel2 * k ** 2 + err ** 2


def residuals(models: Mapping[str, ForwardModel], measurements: Measurements,
              values: Mapping[str, float], model_form_sd: float = 0.0
              ) -> dict[str, tuple[float, float, float]]:
    """Per formulation at the parameter ``values`` (m^2 K/W): measured mean, model k_iso and
    its marginal likelihood variance (:func:`variance`, plus the shipped correction's term
    shared by the system, :meth:`ForwardModel.shared_sd`), W/(m K) and (W/(m K))^2."""
    out = {}
    for stage in stages_of(models):
        s = pooled_scatter([models[f] for f in stage.formulations])
        for f in stage.formulations:
            m = models[f]
            cols = {p: np.array([values[p]]) for p in m.parameters}
            k, err = m.predict(cols)
            v = variance(measurements.standard_error(f), k, err, s, m.model_sd, model_form_sd)
            if getattr(m, "shared_system", None) is not None:
                v = v + (m.shared_sd(cols) * k) ** 2
            out[f] = (measurements.mean(f), float(k[0]), float(v[0]))
    return out


def _identifiability(names: Sequence[str], log_samples: np.ndarray,
                     prior: tuple[float, float]) -> dict:
    prior_sd = (math.log10(prior[1]) - math.log10(prior[0])) / math.sqrt(12)
    cov = np.atleast_2d(np.cov(log_samples, rowvar=False))
    w, V = np.linalg.eigh(cov)
    directions = []
    for j in range(len(w) - 1, -1, -1):
        ratio = math.sqrt(max(w[j], 0.0)) / prior_sd
        v = V[:, j] / V[np.argmax(np.abs(V[:, j])), j]
        combo = " ".join(f"{c:+.2f} log10({n})" for c, n in zip(v, names) if abs(c) > 0.05)
        directions.append({"combination": combo, "posterior_to_prior_sd": ratio,
                           "determined": ratio <= UNIDENTIFIED_RATIO})
    return {"directions": directions}


def _statement(post: Posterior, names: Sequence[str], directions: Sequence[dict]) -> dict:
    """Per parameter its :meth:`Posterior.determination` and the stage's statement, which
    says "every parameter and combination is determined" only where every parameter is
    determined (the headline's flags, the same rule) and every direction is."""
    parameters = {n: post.determination(n) for n in names}
    parts = [t for t in (post.describe(n) for n in names) if t is not None]
    bad = [d["combination"] for d in directions if not d["determined"]]
    if bad:
        parts.append("the data do not separate: " + "; ".join(bad) +
                     f" (posterior spread > {UNIDENTIFIED_RATIO:g} of the prior's)")
    if not parts:
        text = "every parameter and combination is determined by the data"
    else:
        good = [n for n, d in parameters.items() if d == DETERMINATIONS[3]]
        text = "; ".join(parts) + (
            f"; determined: {', '.join(good)}" if good else "")
    return {"parameters": parameters, "statement": text}


def calibrate(models: Mapping[str, ForwardModel], measurements: Measurements, *,
              grid_points: int = 121, carried_samples: int = 256, n_samples: int = 4000,
              seed: int = 0, model_form_sd: float = 0.0,
              prior: tuple[float, float] | None = None) -> Posterior:
    """Posterior of the interface parameters of ``models`` given ``measurements``.

    Parameters
    ----------
    models : mapping of formulation to a built ForwardModel
        Every formulation must be measured (two replicates at least).
    measurements : Measurements
    grid_points : int
        Grid points per parameter and stage (log10 spacing over the prior).
    carried_samples : int
        Earlier-stage posterior samples crossed with a later stage's grid.
    n_samples : int
        Posterior samples kept (jittered uniformly inside their grid cell).
    seed : int
        Seed of the sampling.
    model_form_sd : float
        Relative model-form error added to every formulation's likelihood variance (>= 0;
        :mod:`itr_identify.inference.misfit` chooses it).
    prior : (float, float), optional
        The log-uniform prior's range of every resistance, m^2 K/W, inside the models'
        reduced-basis box (``settings.prior_m2K_per_W``; default: that box). The
        identification passes its resistance prior (:mod:`.priors`), the one the joint
        posterior has.

    Returns
    -------
    Posterior
    """
    prior = _checked_prior(models, measurements, grid_points=grid_points,
                           model_form_sd=model_form_sd, prior=prior)
    rng = np.random.default_rng(seed)
    names: list[str] = []
    samples = np.zeros((n_samples, 0))
    best: dict[str, float] = {}
    stages_out: list[StageResult] = []
    log_evidence = 0.0
    for stage in stages_of(models):
        scatter = pooled_scatter([models[f] for f in stage.formulations])
        if not stage.new:
            # nothing new to identify: these formulations only test the earlier stages
            result = _predicted_stage(models, stage, measurements, best, scatter=scatter,
                                      model_form_sd=model_form_sd)
            log_evidence += result.log_likelihood_best
            stages_out.append(result)
            continue
        fit = _calibrate_stage(models, stage, measurements, rng, samples=samples, best=best,
                               known=names, scatter=scatter, prior=prior,
                               grid_points=grid_points, carried_samples=carried_samples,
                               n_samples=n_samples, model_form_sd=model_form_sd)
        log_evidence += fit.log_evidence
        samples = fit.samples
        best.update(fit.best)
        names += list(stage.new)
        stages_out.append(fit.result)
    post = Posterior(names, samples, best, tuple(prior), model_form_sd=float(model_form_sd),
                     log_evidence=log_evidence)
    return _with_statements(post, stages_out)


def _checked_prior(models: Mapping[str, ForwardModel], measurements: Measurements, *,
                   grid_points: int, model_form_sd: float,
                   prior: tuple[float, float] | None) -> tuple[float, float]:
    """The arguments of :func:`calibrate` checked (ValueError naming the one at fault) and
    its prior range, m^2 K/W: ``prior``, or the models' reduced-basis box where None."""
    if not (isinstance(model_form_sd, (int, float)) and 0 <= model_form_sd < 1):
        raise ValueError(f"model_form_sd: expected a relative error in [0, 1), got "
                         f"{model_form_sd!r}")
    if not models:
        raise ValueError("models: expected at least one formulation")
    for f in models:
        if f not in measurements.values:
            raise ValueError(f"measurements: formulation {f!r} has a forward model but no "
                             f"measurement (measured: {measurements.formulations})")
    if not isinstance(grid_points, int) or grid_points < 5:
        raise ValueError(f"grid_points: expected a whole number >= 5, got {grid_points!r}")
    box = tuple(next(iter(models.values())).settings.prior_m2K_per_W)
    prior = box if prior is None else (float(prior[0]), float(prior[1]))
    if not (box[0] * (1 - 1e-12) <= prior[0] < prior[1] <= box[1] * (1 + 1e-12)):
        raise ValueError(f"prior: {prior[0]:g} - {prior[1]:g} m^2 K/W must lie inside the "
                         f"models' reduced-basis box {box[0]:g} - {box[1]:g}")
    return prior


def _predicted_stage(models: Mapping[str, ForwardModel], stage: Stage,
                     measurements: Measurements, best: Mapping[str, float], *,
                     scatter: float, model_form_sd: float) -> StageResult:
    """A stage with no parameter of its own: its formulations predicted at the earlier
    stages' ``best`` values (m^2 K/W), their log-likelihood there (nats) its evidence."""
    at_best = {p: np.array([best[p]]) for p in best}
    ll = float(_stage_loglike(models, stage, measurements, at_best, scatter,
                              model_form_sd)[0])
    return StageResult(
        system=tuple(stage.system), formulations=tuple(stage.formulations), parameters=(),
        carried=tuple(stage.carried), rve_scatter=scatter, log_likelihood_best=ll,
        identifiability={"system": "+".join(stage.system), "directions": [],
                         "statement": "no parameter of its own: predicted from the earlier "
                                      "stages"})


@dataclass(frozen=True, eq=False)
class _StageFit:
    """What :func:`_calibrate_stage` adds to the posterior: the stage's result, every
    stage's samples so far (log10 values, the new parameters' columns last), the new
    parameters' best values (m^2 K/W) and the stage's log evidence (nats)."""

    result: StageResult
    samples: np.ndarray
    best: dict[str, float]
    log_evidence: float


def _calibrate_stage(models: Mapping[str, ForwardModel], stage: Stage,
                     measurements: Measurements, rng: np.random.Generator, *,
                     samples: np.ndarray, best: Mapping[str, float], known: Sequence[str],
                     scatter: float, prior: tuple[float, float], grid_points: int,
                     carried_samples: int, n_samples: int,
                     model_form_sd: float) -> _StageFit:
    """One stage with parameters of its own (``stage.new``): a grid over the prior, then the
    same number of points over the region that holds the posterior (log-likelihood within
    :data:`REFINE_DEPTH` of its maximum, one cell added), each crossed with up to
    ``carried_samples`` rows of the earlier stages' ``samples`` (columns ``known``)."""
    if stage.carried:
        pick = rng.choice(samples.shape[0], size=min(carried_samples, samples.shape[0]),
                          replace=False)
        prev = samples[pick]                                       # (s, known)
    else:
        prev = np.zeros((1, 0))
    carried = list(known) if stage.carried else []
    axes = [_grid(prior, grid_points)] * len(stage.new)
    G, ll, shape = _stage_grid(models, stage, measurements, axes, prev, carried,
                               scatter=scatter, model_form_sd=model_form_sd)
    axes = _refined_axes(axes, G, ll, grid_points)
    G, ll, shape = _stage_grid(models, stage, measurements, axes, prev, carried,
                               scatter=scatter, model_form_sd=model_form_sd)
    steps = np.array([a[1] - a[0] for a in axes])
    # the prior's mass of the refined cells: the likelihood beyond them is below
    # exp(-REFINE_DEPTH) of its peak (averaged over the carried samples)
    top = float(ll.max())
    width = math.log10(prior[1]) - math.log10(prior[0])
    log_evidence = (top + math.log(float(np.exp(ll - top).sum(axis=1).mean()))
                    + float(np.sum(np.log(steps / width))))
    S, g = ll.shape
    w = np.exp(ll - ll.max())
    pick = rng.choice(S * g, size=n_samples, p=(w / w.sum()).ravel())
    si, gi = np.divmod(pick, g)
    jitter = rng.uniform(-0.5, 0.5, size=(n_samples, len(stage.new))) * steps
    new_samples = np.clip(G[gi] + jitter, [a[0] for a in axes], [a[-1] for a in axes])
    if stage.carried:
        samples = np.hstack([prev[si], new_samples])
        # the best point: earlier stages' best values, this stage's grid
        line = {p: np.full(g, best[p]) for p in known}
        line.update({p: 10 ** G[:, j] for j, p in enumerate(stage.new)})
        ll_best = _stage_loglike(models, stage, measurements, line, scatter, model_form_sd)
    else:
        # independent of the earlier stages: pair the rows as they come
        samples = np.hstack([samples, new_samples])
        ll_best = ll[0]
    bg = int(np.argmax(ll_best))
    marg = w.sum(axis=0).reshape(shape)
    result = StageResult(
        system=tuple(stage.system), formulations=tuple(stage.formulations),
        parameters=tuple(stage.new), carried=tuple(stage.carried), rve_scatter=scatter,
        log_likelihood_best=float(ll_best[bg]),
        identifiability={"system": "+".join(stage.system),
                         **_identifiability(stage.new, new_samples, prior)},
        axes_log10=tuple(np.array(a) for a in axes), density=marg / marg.sum())
    return _StageFit(result, samples, {p: float(10 ** G[bg, j])
                                       for j, p in enumerate(stage.new)}, log_evidence)


def _stage_grid(models: Mapping[str, ForwardModel], stage: Stage, measurements: Measurements,
                axes: Sequence[np.ndarray], prev: np.ndarray, carried: Sequence[str], *,
                scatter: float, model_form_sd: float
                ) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """The stage's log-likelihood on the grid of ``axes`` (log10 of the new parameters)
    crossed with the carried rows ``prev`` (log10 values of ``carried``): the grid points
    (g, new), the log-likelihood (rows of ``prev``, g) and the grid's shape."""
    mesh = np.meshgrid(*axes, indexing="ij")
    G = np.stack([m.ravel() for m in mesh], axis=1)          # (g, new)
    columns = {}
    for j, p in enumerate(carried):
        columns[p] = np.repeat(10 ** prev[:, j], G.shape[0])
    for j, p in enumerate(stage.new):
        columns[p] = np.tile(10 ** G[:, j], prev.shape[0])
    ll = _stage_loglike(models, stage, measurements, columns, scatter, model_form_sd)
    return G, ll.reshape(prev.shape[0], G.shape[0]), mesh[0].shape


def _refined_axes(axes: Sequence[np.ndarray], G: np.ndarray, ll: np.ndarray,
                  grid_points: int) -> list[np.ndarray]:
    """Axes of ``grid_points`` each over the region of the grid ``G`` whose log-likelihood
    ``ll`` (best over the carried rows) lies within :data:`REFINE_DEPTH` of its maximum,
    one cell of the first grid added on each side, inside the first grid's range."""
    keep = (ll.max(axis=0) > ll.max() - REFINE_DEPTH)
    lo_p, hi_p = axes[0][0], axes[0][-1]
    step0 = axes[0][1] - axes[0][0]
    return [np.linspace(max(lo_p, G[keep, j].min() - step0),
                        min(hi_p, G[keep, j].max() + step0), grid_points)
            for j in range(len(axes))]


def _with_statements(post: Posterior, stages: Sequence[StageResult]) -> Posterior:
    """``post`` with ``stages``, each stage that identifies parameters with its statement
    (:func:`_statement`): the statements judge each parameter by the posterior's own
    intervals and flags."""
    return dataclasses.replace(post, stages=[
        st if not st.parameters else dataclasses.replace(
            st, identifiability={**st.identifiability, **_statement(
                post, st.parameters, st.identifiability["directions"])})
        for st in stages])
