"""Lognormal particle-size distributions (paper Sec. 2.1, Eq. 1-3, Table 1).

A distribution is described by ``mu`` and ``sigma``, the mean and standard deviation of
``ln(D / 1 um)``, together with its *basis*: ``"number"`` (the fraction of particles, as in
Table 1 of the paper) or ``"volume"`` (the fraction of particle volume, what a laser
diffraction analyser such as the Malvern Mastersizer reports). For a lognormal the two are
related by the Hatch-Choate conversion ``mu_v = mu_n + 3 sigma^2`` (same ``sigma``).

Diameters are in micrometres throughout this module (names end in ``_um``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import optimize, special

from ..checks import finite_number as _finite

__all__ = ["LogNormalPSD", "HistogramFit", "fit_histogram", "fit_sample",
           "fit_truncated_sample", "histogram_from_sample", "phi_rcp_lognormal",
           "plot_histogram_fit"]

_BASES = ("number", "volume")


def _check_basis(basis: str, argument: str = "basis") -> str:
    if basis not in _BASES:
        raise ValueError(f"{argument}: expected 'number' or 'volume', got {basis!r}")
    return basis


@dataclass(frozen=True)
class LogNormalPSD:
    """Lognormal diameter distribution, Eq. (1) of the paper.

    Parameters
    ----------
    mu : float
        Mean of ``ln(D / 1 um)`` (dimensionless; Table 1 labels it "um").
    sigma : float
        Standard deviation of ``ln(D / 1 um)``, > 0 (Table 1 labels it "um^2").
    basis : {"number", "volume"}
        Whether the density counts particles or particle volume.
    """

    mu: float
    sigma: float
    basis: str = "number"

    def __post_init__(self) -> None:
        _finite(self.mu, "mu")
        s = _finite(self.sigma, "sigma")
        if s <= 0:
            raise ValueError(f"sigma must be > 0, got {s!r}")
        _check_basis(self.basis)

    # ------------------------------------------------------------ conversions
    def to_number(self) -> "LogNormalPSD":
        """Number-weighted equivalent (Hatch-Choate: ``mu_n = mu_v - 3 sigma^2``)."""
        if self.basis == "number":
            return self
        return LogNormalPSD(self.mu - 3.0 * self.sigma ** 2, self.sigma, "number")

    def to_volume(self) -> "LogNormalPSD":
        """Volume-weighted equivalent (Hatch-Choate: ``mu_v = mu_n + 3 sigma^2``)."""
        if self.basis == "volume":
            return self
        return LogNormalPSD(self.mu + 3.0 * self.sigma ** 2, self.sigma, "volume")

    def to_basis(self, basis: str) -> "LogNormalPSD":
        """Equivalent distribution in ``basis`` ("number" or "volume")."""
        return self.to_number() if _check_basis(basis) == "number" else self.to_volume()

    # ------------------------------------------------------------ statistics
    @property
    def mean_um(self) -> float:
        """Arithmetic mean diameter in this basis, um: ``E[D] = exp(mu + sigma^2/2)`` (Eq. 2)."""
        return math.exp(self.mu + 0.5 * self.sigma ** 2)

    @property
    def sd_um(self) -> float:
        """Arithmetic standard deviation, um: ``SD[D] = E[D] sqrt(exp(sigma^2) - 1)`` (Eq. 3)."""
        return self.mean_um * math.sqrt(math.expm1(self.sigma ** 2))

    @property
    def median_um(self) -> float:
        """Median diameter in this basis, um (``exp(mu)``)."""
        return math.exp(self.mu)

    def moment_um(self, k: float) -> float:
        """Raw moment ``E[D^k]`` in this basis, um^k."""
        return math.exp(k * self.mu + 0.5 * (k * self.sigma) ** 2)

    def mean_particle_volume_um3(self) -> float:
        """Mean particle volume of the number-weighted distribution, um^3."""
        return math.pi / 6.0 * self.to_number().moment_um(3.0)

    # ------------------------------------------------------------ functions
    def _z(self, d_um: np.ndarray) -> np.ndarray:
        d = np.asarray(d_um, dtype=np.float64)
        with np.errstate(divide="ignore"):
            return (np.log(np.where(d > 0, d, 0.0)) - self.mu) / self.sigma

    def pdf(self, d_um: np.ndarray | float) -> np.ndarray:
        """Density in D, 1/um (Eq. 1)."""
        d = np.asarray(d_um, dtype=np.float64)
        z = self._z(d)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.exp(-0.5 * z ** 2) / (np.where(d > 0, d, 1.0) * self.sigma
                                           * math.sqrt(2 * math.pi))
        return np.where(d > 0, out, 0.0)

    def cdf(self, d_um: np.ndarray | float) -> np.ndarray:
        """Cumulative fraction below ``d_um`` (in this basis)."""
        d = np.asarray(d_um, dtype=np.float64)
        return np.where(d > 0, special.ndtr(self._z(d)), 0.0)

    def ppf(self, q: np.ndarray | float) -> np.ndarray:
        """Diameter at cumulative fraction ``q``, um."""
        return np.exp(self.mu + self.sigma * special.ndtri(np.asarray(q, dtype=np.float64)))

    def truncated_moment_um(self, k: float, d_lo_um: float, d_hi_um: float) -> float:
        """``E[D^k | d_lo <= D <= d_hi]`` in this basis, um^k."""
        zl = (math.log(d_lo_um) - self.mu) / self.sigma if d_lo_um > 0 else -np.inf
        zh = (math.log(d_hi_um) - self.mu) / self.sigma if np.isfinite(d_hi_um) else np.inf
        p = special.ndtr(zh) - special.ndtr(zl)
        if p <= 0:
            raise ValueError("d_lo_um/d_hi_um: the truncation interval holds no probability")
        pk = special.ndtr(zh - k * self.sigma) - special.ndtr(zl - k * self.sigma)
        return self.moment_um(k) * float(pk) / float(p)

    def mass_outside(self, d_lo_um: float, d_hi_um: float, k: float = 0.0) -> tuple[float, float]:
        """Share of the k-th moment below ``d_lo_um`` and above ``d_hi_um``.

        ``k = 0`` gives the fractions of this basis' measure, ``k = 3`` (for a number
        basis) the fractions of the particle volume.
        """
        zl = (math.log(d_lo_um) - self.mu) / self.sigma - k * self.sigma if d_lo_um > 0 \
            else -np.inf
        zh = (math.log(d_hi_um) - self.mu) / self.sigma - k * self.sigma \
            if np.isfinite(d_hi_um) else np.inf
        return float(special.ndtr(zl)), float(special.ndtr(-zh))

    def sample(self, n: int, rng: np.random.Generator, d_lo_um: float = 0.0,
               d_hi_um: float = math.inf, stratified: bool = False) -> np.ndarray:
        """``n`` diameters (um) drawn in this basis, truncated to ``[d_lo_um, d_hi_um]``.

        Inverse-CDF sampling. With ``stratified=True`` the probability range is split into
        ``n`` equal strata and one diameter is drawn uniformly inside each (then the order
        is shuffled): every diameter still has the target distribution, but the sample's
        histogram, mean and spread scatter far less than with independent draws (Latin
        hypercube sampling in one dimension).
        """
        zl = (math.log(d_lo_um) - self.mu) / self.sigma if d_lo_um > 0 else -np.inf
        zh = (math.log(d_hi_um) - self.mu) / self.sigma if np.isfinite(d_hi_um) else np.inf
        fl, fh = float(special.ndtr(zl)), float(special.ndtr(zh))
        n = int(n)
        if stratified:
            q = (np.arange(n) + rng.uniform(size=n)) / n
            u = rng.permutation(fl + (fh - fl) * q)
        else:
            u = rng.uniform(fl, fh, size=n)
        return np.exp(self.mu + self.sigma * special.ndtri(u))

    def truncated_cdf(self, d_lo_um: float, d_hi_um: float):
        """CDF (callable of D in um) of this distribution truncated to ``[d_lo, d_hi]``."""
        fl = float(self.cdf(d_lo_um)) if d_lo_um > 0 else 0.0
        fh = float(self.cdf(d_hi_um)) if np.isfinite(d_hi_um) else 1.0

        def cdf(d: np.ndarray) -> np.ndarray:
            return np.clip((self.cdf(d) - fl) / (fh - fl), 0.0, 1.0)
        return cdf


def phi_rcp_lognormal(sigma: float) -> float:
    """Random-close-packing fraction of lognormally distributed hard spheres.

    Empirical fit of R. S. Farr, "Random close packing fractions of lognormal
    distributions of hard spheres", Powder Technology 245 (2013) 28-34 (arXiv:1306.1442),
    to the one-dimensional packing model of Farr & Groot, J. Chem. Phys. 131, 244104 (2009)::

        phi = 1 - 0.57 exp(-s) + 0.2135 exp(-0.57 s / 0.2135)
              + 0.0019 (cos(2 pi (1 - exp(-0.75 s^0.7 - 0.025 s^4))) - 1)

    with ``s`` the standard deviation of ``ln D`` (the same for number and volume
    weighting). It gives 0.6435 for monodisperse spheres, 0.680 at ``s = 0.35`` (Table 1
    Al2O3) and 0.725 at ``s = 0.59`` (AlN). Stated accuracy about +-0.01 against 3-D
    simulations for ``s`` up to about 1; it is an estimate of the jamming limit, not a
    guarantee that a given algorithm reaches it.

    Parameters
    ----------
    sigma : float
        Standard deviation of ``ln D``, >= 0.

    Returns
    -------
    float
        Estimated random-close-packing volume fraction.
    """
    s = _finite(sigma, "sigma")
    if s < 0:
        raise ValueError(f"sigma must be >= 0, got {s!r}")
    return (1.0 - 0.57 * math.exp(-s) + 0.2135 * math.exp(-0.57 * s / 0.2135)
            + 0.0019 * (math.cos(2.0 * math.pi * (1.0 - math.exp(-0.75 * s ** 0.7
                                                                  - 0.025 * s ** 4))) - 1.0))


# --------------------------------------------------------------------------- fits
def fit_sample(d_um: np.ndarray) -> tuple[float, float]:
    """Maximum-likelihood lognormal fit of individual diameters (um).

    Returns ``(mu, sigma)``: mean and (population, ``ddof=0``) standard deviation of
    ``ln(D / 1 um)``.
    """
    d = np.asarray(d_um, dtype=np.float64)
    if d.ndim != 1 or d.size < 2:
        raise ValueError("d_um: need at least two diameters")
    if not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise ValueError("d_um: diameters must be finite and > 0 (um)")
    ln = np.log(d)
    return float(ln.mean()), float(ln.std())


def fit_truncated_sample(d_um: np.ndarray, d_lo_um: float, d_hi_um: float
                         ) -> tuple[float, float]:
    """Maximum-likelihood fit of a lognormal truncated to ``[d_lo_um, d_hi_um]``.

    Use it on diameters drawn from a truncated distribution (as the RVE generator does):
    it estimates the parameters of the *untruncated* parent. Returns ``(mu, sigma)``.
    """
    d = np.asarray(d_um, dtype=np.float64)
    mu0, s0 = fit_sample(d)
    ln = np.log(d)
    a = math.log(d_lo_um) if d_lo_um > 0 else -np.inf
    b = math.log(d_hi_um) if np.isfinite(d_hi_um) else np.inf

    def nll(p: np.ndarray) -> float:
        mu, ls = p
        s = math.exp(ls)
        z = (ln - mu) / s
        mass = special.ndtr((b - mu) / s) - special.ndtr((a - mu) / s)
        if mass <= 0:
            return 1e300
        return float(0.5 * np.sum(z * z) + ln.size * (math.log(s) + math.log(mass)))

    res = optimize.minimize(nll, np.array([mu0, math.log(s0)]), method="Nelder-Mead",
                            options={"xatol": 1e-7, "fatol": 1e-9, "maxiter": 4000})
    return float(res.x[0]), float(math.exp(res.x[1]))


@dataclass(frozen=True)
class HistogramFit:
    """Result of :func:`fit_histogram`.

    Attributes
    ----------
    psd : LogNormalPSD
        Fitted distribution in the basis of the histogram.
    number : LogNormalPSD
        The same, number-weighted (Hatch-Choate), as Table 1 and the RVE generator use.
    r2 : float
        Coefficient of determination of the bin percentages.
    rmse_percent : float
        Root-mean-square residual of the bin percentages, percentage points.
    max_cum_dev_percent : float
        Largest deviation of the cumulative curves, percentage points (a KS-like distance).
    edges_um, percent : ndarray
        The histogram that was fitted (percent renormalised to the data's own sum).
    basis : str
        Basis of the histogram.
    """

    psd: LogNormalPSD
    number: LogNormalPSD
    r2: float
    rmse_percent: float
    max_cum_dev_percent: float
    edges_um: np.ndarray
    percent: np.ndarray
    basis: str

    def predicted_percent(self) -> np.ndarray:
        """Bin percentages of the fitted distribution (same normalisation as the data)."""
        return _bin_percent(self.psd.mu, self.psd.sigma, self.edges_um, float(self.percent.sum()))


def _bin_percent(mu: float, sigma: float, edges: np.ndarray, total: float) -> np.ndarray:
    z = (np.log(edges) - mu) / sigma
    cdf = special.ndtr(z)
    mass = cdf[-1] - cdf[0]
    return total * np.diff(cdf) / max(mass, 1e-300)


def fit_histogram(edges_um: Sequence[float] | np.ndarray, percent: Sequence[float] | np.ndarray,
                  basis: str) -> HistogramFit:
    """Fit a lognormal to a size analyser's histogram.

    Least squares on the bin percentages; the model's bin content is the lognormal's
    probability in the bin, conditional on the histogram's range (so a histogram that does
    not cover all of the distribution is fitted consistently).

    Parameters
    ----------
    edges_um : array, shape (K + 1,)
        Increasing bin edges, um, > 0.
    percent : array, shape (K,)
        Percentage in each bin (need not sum exactly to 100).
    basis : {"number", "volume"}
        What the percentages count: ``"volume"`` for a laser-diffraction analyser
        (Mastersizer), ``"number"`` for counted particles.

    Returns
    -------
    HistogramFit
        Fitted parameters (in the histogram's basis and number-weighted) and goodness of
        fit.
    """
    _check_basis(basis)
    e = np.asarray(edges_um, dtype=np.float64)
    p = np.asarray(percent, dtype=np.float64)
    if e.ndim != 1 or e.size < 3:
        raise ValueError("edges_um: need at least three bin edges")
    if p.shape != (e.size - 1,):
        raise ValueError(f"percent: expected {e.size - 1} values (one per bin), got {p.shape}")
    if not np.all(np.isfinite(e)) or np.any(e <= 0):
        raise ValueError("edges_um: bin edges must be finite and > 0 (um)")
    if np.any(np.diff(e) <= 0):
        raise ValueError("edges_um: bin edges must increase")
    if not np.all(np.isfinite(p)) or np.any(p < 0) or p.sum() <= 0:
        raise ValueError("percent: values must be finite, >= 0 and not all zero")
    total = float(p.sum())
    lc = 0.5 * (np.log(e[:-1]) + np.log(e[1:]))
    w = p / total
    mu0 = float(np.sum(w * lc))
    s0 = float(math.sqrt(max(np.sum(w * (lc - mu0) ** 2), 1e-4)))

    def resid(x: np.ndarray) -> np.ndarray:
        return _bin_percent(x[0], math.exp(x[1]), e, total) - p

    sol = optimize.least_squares(resid, np.array([mu0, math.log(s0)]), method="lm",
                                 xtol=1e-12, ftol=1e-12)
    mu, sigma = float(sol.x[0]), float(math.exp(sol.x[1]))
    pred = _bin_percent(mu, sigma, e, total)
    ss_res = float(np.sum((pred - p) ** 2))
    ss_tot = float(np.sum((p - p.mean()) ** 2))
    psd = LogNormalPSD(mu, sigma, basis)
    return HistogramFit(psd=psd, number=psd.to_number(),
                        r2=1.0 - ss_res / ss_tot if ss_tot > 0 else 1.0,
                        rmse_percent=math.sqrt(ss_res / p.size),
                        max_cum_dev_percent=float(np.max(np.abs(np.cumsum(pred - p)))),
                        edges_um=e, percent=p, basis=basis)


def histogram_from_sample(d_um: np.ndarray, edges_um: np.ndarray, basis: str) -> np.ndarray:
    """Percent per bin of individual diameters, counted by number or by volume (``D^3``)."""
    _check_basis(basis)
    d = np.asarray(d_um, dtype=np.float64)
    w = d ** 3 if basis == "volume" else np.ones_like(d)
    h, _ = np.histogram(d, bins=np.asarray(edges_um, dtype=np.float64), weights=w)
    return 100.0 * h / w.sum()


def plot_histogram_fit(fit: HistogramFit, path: str, title: str | None = None,
                       sample_um: np.ndarray | None = None) -> str:
    """Histogram and fitted lognormal, as in the paper's Fig. 2; written as a PNG.

    Parameters
    ----------
    fit : HistogramFit
        From :func:`fit_histogram`.
    path : str
        Output file (PNG).
    title : str, optional
        Figure title.
    sample_um : ndarray, optional
        Diameters of generated particles (um) to overlay, histogrammed on the same bins
        and basis (the paper's comparison of model and measurement).

    Returns
    -------
    str
        ``path``.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    e = fit.edges_um
    fig, ax = plt.subplots(figsize=(6.0, 4.0), dpi=120)
    ax.bar(e[:-1], fit.percent, width=np.diff(e), align="edge", color="0.75",
           edgecolor="0.4", linewidth=0.5, label=f"histogram ({fit.basis})")
    ax.plot(np.sqrt(e[:-1] * e[1:]), fit.predicted_percent(), "r-", lw=1.6,
            label=(f"lognormal fit: $\\mu$ = {fit.psd.mu:.3f}, $\\sigma$ = "
                   f"{fit.psd.sigma:.3f}\n(number: $\\mu$ = {fit.number.mu:.3f}); "
                   f"$R^2$ = {fit.r2:.4f}"))
    if sample_um is not None and len(sample_um):
        hs = histogram_from_sample(sample_um, e, fit.basis) * fit.percent.sum() / 100.0
        ax.plot(np.sqrt(e[:-1] * e[1:]), hs, "bo", ms=3, label="generated particles")
    ax.set_xscale("log")
    ax.set_xlabel("particle diameter D (µm)")
    ax.set_ylabel(f"{fit.basis} density (% per bin)")
    if title:
        ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    from ..io import atomic_path
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=Path(path).suffix.lstrip(".") or "png")
    plt.close(fig)
    return path
