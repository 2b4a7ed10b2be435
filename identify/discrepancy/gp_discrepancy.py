"""A model-form error term for the base model: a Gaussian-process discrepancy in the filler
fraction (Kennedy and O'Hagan's formulation), used when no candidate effect is named.

Per measurement group ``i`` of filler ``f`` at filler fraction ``phi_i`` (vol%),

    ln m_i = ln k_f(phi_i; R_f) + delta_f(phi_i) + e_i                 (dimensionless),

``k_f`` the base model (forward tables, replica factor included), ``R_f`` the filler's
filler-matrix resistance (m^2 K/W) and ``delta_f`` a zero-mean Gaussian process per filler
with the squared-exponential covariance

    cov(delta_f(phi), delta_f(phi')) = s^2 exp(-(phi - phi')^2 / (2 l^2)),

the two fillers independent, ``s`` and ``l`` shared. The error ``e`` holds the replicate
error of the group mean (relative, ``se_i / m_i``) and one RVE error per formulation
(relative scatter of the replicas), shared by its groups.

Priors: ``R_f`` log-uniform on the calibration grid; ``s`` log-uniform on
:data:`AMPLITUDE_RANGE` (0.3 % to 25 %: a model that misses every formulation by more than a
quarter is not what this term is for; the bound keeps the term from absorbing any data), ``l``
log-uniform on :data:`LENGTH_RANGE` vol% (from the spacing of the formulations to beyond their
span). Everything reported is integrated over the posterior on that grid: the resistances
(posterior median and 5-95 % quantiles, so the interval contains the reported value), ``s``,
and predictions (a Gaussian mixture). :func:`leave_one_out` measures whether the predictive
intervals hold: each formulation predicted from the others.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special

from .fit import Group, _interp, pooled_scatter
from .tables import ForwardTables, resistance_name

__all__ = ["AMPLITUDE_RANGE", "LENGTH_RANGE", "ModelFormFit", "fit_model_form",
           "leave_one_out", "LeaveOneOut"]

#: Prior range of the discrepancy's amplitude ``s`` (standard deviation of ln k).
AMPLITUDE_RANGE = (0.003, 0.25)
#: Prior range of the discrepancy's correlation length ``l``, vol% of filler.
LENGTH_RANGE = (2.0, 30.0)


def _amplitudes(n: int = 17) -> np.ndarray:
    return np.geomspace(*AMPLITUDE_RANGE, n)


def _lengths(n: int = 7) -> np.ndarray:
    return np.geomspace(*LENGTH_RANGE, n)


@dataclass
class _Data:
    """Per group: filler index, fraction (vol%), ln of the measured mean, relative variance
    of the mean, formulation, the base model's ln k on the fine resistance axis."""

    fillers: list[str]
    filler_of: np.ndarray
    phi: np.ndarray
    y: np.ndarray
    rel_var: np.ndarray
    formulation: list[str]
    ln_model: np.ndarray          # (groups, fine R)
    scatter: dict[str, float]
    log_r: np.ndarray             # fine axis, log10 m^2 K/W

    def take(self, sel: np.ndarray) -> "_Data":
        return _Data(self.fillers, self.filler_of[sel], self.phi[sel], self.y[sel],
                     self.rel_var[sel], [f for f, s in zip(self.formulation, sel) if s],
                     self.ln_model[sel], self.scatter, self.log_r)


def _data(tables: ForwardTables, groups: Sequence[Group]) -> _Data:
    st = tables.settings
    logr = np.log10(np.asarray(st.r_grid_m2K_per_W))
    fine = np.linspace(logr[0], logr[-1], st.fine_points)
    fillers = sorted({g.filler for g in groups})
    scatter = pooled_scatter(tables, groups)
    curves = {}
    for g in groups:
        if g.formulation not in curves:
            level = np.asarray(tables.level(g.formulation, None, 10 ** fine))
            curves[g.formulation] = np.log(level * _interp(
                logr, np.zeros(1), tables.base[g.formulation], None, fine, np.zeros(1))[:, 0])
    return _Data(fillers, np.array([fillers.index(g.filler) for g in groups]),
                 np.array([g.fraction * 100 for g in groups]),
                 np.log([g.mean for g in groups]),
                 np.array([(g.standard_error / g.mean) ** 2 for g in groups]),
                 [g.formulation for g in groups],
                 np.array([curves[g.formulation] for g in groups]), scatter, fine)


def _noise(d: _Data, idx: np.ndarray) -> np.ndarray:
    """Covariance of the errors ``e`` of the groups ``idx`` (one filler)."""
    fl = d.fillers[d.filler_of[idx[0]]]
    same = np.array([[d.formulation[a] == d.formulation[b] for b in idx] for a in idx])
    return np.diag(d.rel_var[idx]) + d.scatter[fl] ** 2 * same


def _kernel(a: np.ndarray, b: np.ndarray, s: float, length: float) -> np.ndarray:
    return s ** 2 * np.exp(-0.5 * ((a[:, None] - b[None, :]) / length) ** 2)


def _log_evidence(d: _Data, amplitudes: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """ln p(data of filler f | R_f, s, l): shape (fillers, amplitudes, lengths, fine R)."""
    out = np.zeros((len(d.fillers), amplitudes.size, lengths.size, d.log_r.size))
    for f in range(len(d.fillers)):
        idx = np.flatnonzero(d.filler_of == f)
        if idx.size == 0:
            continue
        resid = d.y[idx, None] - d.ln_model[idx]                  # (n, fine R)
        noise = _noise(d, idx)
        for a, s in enumerate(amplitudes):
            for b, ln in enumerate(lengths):
                c = noise + (_kernel(d.phi[idx], d.phi[idx], s, ln) if s > 0 else 0.0)
                chol = np.linalg.cholesky(c)
                z = np.linalg.solve(chol, resid)
                out[f, a, b] = (-0.5 * np.einsum("ij,ij->j", z, z)
                                - np.log(np.diag(chol)).sum() - 0.5 * idx.size
                                * math.log(2 * math.pi))
    return out


def _posterior(ev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Log weights over (amplitude, length) (normalised) and, per filler, the log weights
    of R given them: (a, l) and (fillers, a, l, R)."""
    per_filler = special.logsumexp(ev, axis=3)                   # (f, a, l)
    hyper = per_filler.sum(axis=0)
    hyper = hyper - special.logsumexp(hyper)
    cond = ev - per_filler[..., None]                            # ln p(R_f | s, l)
    return hyper, cond


@dataclass
class ModelFormFit:
    """The base model with the model-form term, calibrated on every group.

    Attributes
    ----------
    resistances : dict of name to (median, 5 %, 95 %)
        Posterior of each filler-matrix resistance, m^2 K/W.
    amplitude : (float, float, float)
        Posterior median, 5 % and 95 % of ``s`` (relative, standard deviation of ln k).
    length_vol_percent : float
        Posterior median of ``l``, vol%.
    log_evidence : float
        ln of the marginal likelihood (over the priors' grid).
    """

    resistances: dict[str, tuple[float, float, float]]
    amplitude: tuple[float, float, float]
    length_vol_percent: float
    log_evidence: float

    @property
    def at_prior_edge(self) -> bool:
        """Whether the amplitude's posterior median sits at the prior's upper end: the model
        misses by more than the term is meant to carry, and its resistances are not to be
        used."""
        return self.amplitude[0] >= AMPLITUDE_RANGE[1] * (1 - 1e-9)

    def to_dict(self) -> dict:
        return {"resistances_median_5_95": {k: list(v) for k, v in self.resistances.items()},
                "amplitude_median_5_95": list(self.amplitude),
                "length_vol_percent_median": self.length_vol_percent,
                "log_evidence": self.log_evidence, "at_prior_edge": self.at_prior_edge,
                "prior": {"amplitude": list(AMPLITUDE_RANGE),
                          "length_vol_percent": list(LENGTH_RANGE)}}


def _quantiles(axis: np.ndarray, log_w: np.ndarray, qs: Sequence[float]) -> list[float]:
    w = np.exp(log_w - log_w.max())
    c = np.cumsum(w) / w.sum()
    return [float(axis[min(np.searchsorted(c, q), axis.size - 1)]) for q in qs]


def fit_model_form(tables: ForwardTables, groups: Sequence[Group], *,
                   amplitudes: np.ndarray | None = None) -> ModelFormFit:
    """Calibrate the base model with the model-form term on ``groups``.

    ``amplitudes`` (the grid of ``s``) defaults to :data:`AMPLITUDE_RANGE`'s; a
    one-element ``[0.0]`` gives the base model without the term."""
    amps = _amplitudes() if amplitudes is None else np.asarray(amplitudes, dtype=float)
    lengths = _lengths() if amps.max() > 0 else np.array([LENGTH_RANGE[0]])
    d = _data(tables, groups)
    ev = _log_evidence(d, amps, lengths)
    hyper, cond = _posterior(ev)
    log_z = float(special.logsumexp(special.logsumexp(ev, axis=3).sum(axis=0))
                  - math.log(amps.size * lengths.size))
    res = {}
    for f, fl in enumerate(d.fillers):
        joint = special.logsumexp(hyper[..., None] + cond[f], axis=(0, 1))
        q = _quantiles(d.log_r, joint, (0.5, 0.05, 0.95))
        res[resistance_name(fl, tables.settings.system.matrix)] = tuple(float(10 ** x) for x in q)
    amp_w = special.logsumexp(hyper, axis=1)
    len_w = special.logsumexp(hyper, axis=0)
    return ModelFormFit(res, tuple(_quantiles(amps, amp_w, (0.5, 0.05, 0.95))),
                        _quantiles(lengths, len_w, (0.5,))[0], log_z)


def _conditional(train: _Data, idx: np.ndarray, phi: float, s: float, length: float
                 ) -> tuple[np.ndarray, float]:
    """Gaussian-process regression of ``delta`` at ``phi`` (vol%) from the training
    groups ``idx`` of one filler: the weights ``w`` of the conditional mean
    ``w . (y - ln k_model)`` and the conditional variance of ``delta``."""
    if idx.size == 0:
        return np.zeros(0), s ** 2
    c = _noise(train, idx) + _kernel(train.phi[idx], train.phi[idx], s, length)
    kx = _kernel(train.phi[idx], np.array([phi]), s, length)[:, 0]
    w = np.linalg.solve(c, kx)
    return w, float(s ** 2 - kx @ w)


def _predict(train: _Data, test: _Data, amps: np.ndarray, lengths: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """5 % and 95 % of the predictive distribution of ln m for the groups of ``test``,
    from ``train``: a Gaussian mixture over (s, l, R)."""
    ev = _log_evidence(train, amps, lengths)
    hyper, cond = _posterior(ev)
    lo, hi = np.zeros(test.y.size), np.zeros(test.y.size)
    for i in range(test.y.size):
        f = test.filler_of[i]
        fl = test.fillers[f]
        idx = np.flatnonzero(train.filler_of == f)
        means, variances, logw = [], [], []
        noise_var = test.rel_var[i] + train.scatter[fl] ** 2
        for a, s in enumerate(amps):
            for b, ln in enumerate(lengths):
                weights, latent_var = _conditional(train, idx, test.phi[i], s, ln)
                means.append(test.ln_model[i]
                             + weights @ (train.y[idx, None] - train.ln_model[idx]))
                variances.append(np.full(train.log_r.size, latent_var + noise_var))
                logw.append(hyper[a, b] + cond[f, a, b])
        m, v, w = (np.concatenate(x) for x in (means, variances, logw))
        w = np.exp(w - special.logsumexp(w))
        grid = np.linspace((m - 5 * np.sqrt(v)).min(), (m + 5 * np.sqrt(v)).max(), 4001)
        cdf = (w[None, :] * special.ndtr((grid[:, None] - m[None, :])
                                         / np.sqrt(v)[None, :])).sum(axis=1)
        lo[i], hi[i] = np.interp([0.05, 0.95], cdf, grid)
    return lo, hi


@dataclass
class LeaveOneOut:
    """Each formulation predicted from the others.

    Attributes
    ----------
    labels : list of str
        Groups in order.
    measured, low, high, centre : ndarray
        Measured mean and the 90 % predictive interval (5 %, 95 %) and its centre
        (geometric mean of the ends), W/(m K).
    """

    labels: list[str]
    measured: np.ndarray
    low: np.ndarray
    high: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        return np.sqrt(self.low * self.high)

    @property
    def covered(self) -> np.ndarray:
        return (self.low <= self.measured) & (self.measured <= self.high)

    @property
    def coverage(self) -> float:
        return float(self.covered.mean())

    @property
    def relative_error(self) -> np.ndarray:
        """``centre / measured - 1`` per group."""
        return self.centre / self.measured - 1

    def to_dict(self) -> dict:
        return {"labels": self.labels, "measured": self.measured.tolist(),
                "low_5": self.low.tolist(), "high_95": self.high.tolist(),
                "covered": self.covered.tolist(), "coverage": self.coverage,
                "mean_abs_error": float(np.abs(self.relative_error).mean()),
                "max_abs_error": float(np.abs(self.relative_error).max())}


def leave_one_out(tables: ForwardTables, groups: Sequence[Group], *,
                  with_term: bool = True) -> LeaveOneOut:
    """Leave-one-formulation-out predictions: every group of a formulation predicted from
    the groups of the other formulations, with the model-form term (``with_term``) or by the
    base model alone (its resistances refitted, their uncertainty and the replicate and RVE
    errors in the interval)."""
    d = _data(tables, groups)
    amps = _amplitudes() if with_term else np.zeros(1)
    lengths = _lengths() if with_term else np.array([LENGTH_RANGE[0]])
    lo, hi = np.zeros(d.y.size), np.zeros(d.y.size)
    for f in dict.fromkeys(d.formulation):
        test = np.array([x == f for x in d.formulation])
        a, b = _predict(d.take(~test), d.take(test), amps, lengths)
        lo[test], hi[test] = np.exp(a), np.exp(b)
    return LeaveOneOut([g.label for g in groups], np.exp(d.y), lo, hi)
