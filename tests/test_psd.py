"""Lognormal size distributions: Table 1 statistics, Hatch-Choate, histogram fits."""

import math

import numpy as np
import pytest
from refusals import refuses
from scipy import integrate

from itr_fv.materials.paper_data import TABLE1
from itr_fv.materials.psd import (
    LogNormalPSD,
    fit_histogram,
    fit_sample,
    fit_truncated_sample,
    histogram_from_sample,
    phi_rcp_lognormal,
    plot_histogram_fit,
)


def test_table1_mean_and_sd_eq2_eq3():
    # Table 1: E[D] and SD[D] follow from mu, sigma by Eq. (2)-(3)
    assert TABLE1["Al2O3"].mean_um == pytest.approx(2.95, abs=0.005)
    assert TABLE1["Al2O3"].sd_um == pytest.approx(1.06, abs=0.005)
    # AlN: 4.154 / 2.681 from the rounded mu, sigma of Table 1 (printed 4.17 / 2.70)
    assert TABLE1["AlN"].mean_um == pytest.approx(4.17, abs=0.02)
    assert TABLE1["AlN"].sd_um == pytest.approx(2.70, abs=0.03)


def test_pdf_normalised_and_matches_cdf():
    p = TABLE1["AlN"]
    total, _ = integrate.quad(lambda d: float(p.pdf(d)), 0, np.inf, limit=200)
    assert total == pytest.approx(1.0, rel=1e-7)
    part, _ = integrate.quad(lambda d: float(p.pdf(d)), 0, 5.0)
    assert part == pytest.approx(float(p.cdf(5.0)), rel=1e-8)
    assert float(p.ppf(p.cdf(7.3))) == pytest.approx(7.3, rel=1e-12)


def test_hatch_choate_volume_weighting():
    n = TABLE1["Al2O3"]
    v = n.to_volume()
    assert v.mu == pytest.approx(1.02 + 3 * 0.35 ** 2)
    assert v.sigma == n.sigma and v.basis == "volume"
    assert v.to_number().mu == pytest.approx(n.mu)
    # volume density = D^3 f_n(D) / E[D^3]
    d = np.array([0.7, 2.0, 3.3, 9.0])
    expected = d ** 3 * n.pdf(d) / n.moment_um(3)
    np.testing.assert_allclose(v.pdf(d), expected, rtol=1e-12)
    # mean particle volume of the number distribution
    assert n.mean_particle_volume_um3() == pytest.approx(
        math.pi / 6 * math.exp(3 * 1.02 + 4.5 * 0.35 ** 2))


def test_truncated_moment_matches_quadrature():
    p = TABLE1["AlN"]
    lo, hi = 0.625, 40 / 3
    num, _ = integrate.quad(lambda d: d ** 3 * float(p.pdf(d)), lo, hi)
    mass = float(p.cdf(hi) - p.cdf(lo))
    assert p.truncated_moment_um(3, lo, hi) == pytest.approx(num / mass, rel=1e-8)
    nl, nh = p.mass_outside(lo, hi, 0.0)
    assert nl == pytest.approx(float(p.cdf(lo))) and nh == pytest.approx(1 - float(p.cdf(hi)))
    vl, vh = p.mass_outside(lo, hi, 3.0)
    assert vh == pytest.approx(1 - float(p.to_volume().cdf(hi)))


@pytest.mark.parametrize("name", ["Al2O3", "AlN"])
@pytest.mark.parametrize("basis", ["number", "volume"])
def test_fit_histogram_recovers_table1_from_sample(name, basis):
    """Acceptance 5: a histogram sampled from Table 1 gives mu, sigma back within 0.02."""
    target = TABLE1[name]
    rng = np.random.default_rng(7)
    d = target.sample(200_000, rng)
    edges = np.geomspace(0.1, 200.0, 61)  # analyser-like log bins
    pct = histogram_from_sample(d, edges, basis)
    fit = fit_histogram(edges, pct, basis=basis)
    assert fit.number.mu == pytest.approx(target.mu, abs=0.02)
    assert fit.number.sigma == pytest.approx(target.sigma, abs=0.02)
    assert fit.psd.basis == basis
    assert fit.r2 > 0.99
    assert fit.max_cum_dev_percent < 1.0


def test_fit_histogram_exact_bins_and_partial_range():
    p = LogNormalPSD(2.0, 0.4, "volume")
    edges = np.geomspace(3.0, 30.0, 25)  # does not cover the whole distribution
    pct = 80.0 * np.diff(p.cdf(edges)) / (p.cdf(edges[-1]) - p.cdf(edges[0]))
    fit = fit_histogram(edges, pct, basis="volume")
    assert fit.psd.mu == pytest.approx(2.0, abs=1e-6)
    assert fit.psd.sigma == pytest.approx(0.4, abs=1e-6)
    assert fit.number.mu == pytest.approx(2.0 - 3 * 0.16, abs=1e-6)
    assert fit.r2 == pytest.approx(1.0, abs=1e-10)


def test_fit_sample_and_truncated_fit():
    p = TABLE1["AlN"]
    rng = np.random.default_rng(3)
    d = p.sample(50_000, rng, 0.625, 40 / 3)
    mu, s = fit_sample(d)
    assert s < p.sigma - 0.01  # truncation narrows the plain fit
    mu_t, s_t = fit_truncated_sample(d, 0.625, 40 / 3)
    assert mu_t == pytest.approx(p.mu, abs=0.02)
    assert s_t == pytest.approx(p.sigma, abs=0.02)


def test_stratified_sample_is_even():
    p = TABLE1["Al2O3"]
    d = p.sample(400, np.random.default_rng(1), stratified=True)
    mu, s = fit_sample(d)
    assert mu == pytest.approx(p.mu, abs=0.01) and s == pytest.approx(p.sigma, abs=0.01)
    assert np.all(d > 0)


def test_phi_rcp_estimate():
    assert phi_rcp_lognormal(0.0) == pytest.approx(0.6435, abs=1e-4)
    assert phi_rcp_lognormal(0.35) == pytest.approx(0.68, abs=0.005)
    assert phi_rcp_lognormal(0.59) == pytest.approx(0.72, abs=0.01)
    s = np.linspace(0, 1.5, 31)
    assert np.all(np.diff([phi_rcp_lognormal(x) for x in s]) > 0)


def test_plot_histogram_fit(tmp_path):
    p = TABLE1["Al2O3"]
    edges = np.geomspace(0.3, 40.0, 40)
    d = p.sample(20_000, np.random.default_rng(0))
    fit = fit_histogram(edges, histogram_from_sample(d, edges, "volume"), basis="volume")
    out = plot_histogram_fit(fit, str(tmp_path / "fig2.png"), title="Al2O3", sample_um=d[:2000])
    data = open(out, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


@pytest.mark.parametrize("kwargs, arg", [
    (dict(mu=1.0, sigma=0.0), "sigma"),
    (dict(mu=1.0, sigma=-0.3), "sigma"),
    (dict(mu=float("nan"), sigma=0.3), "mu"),
    (dict(mu=1.0, sigma=0.3, basis="mass"), "basis"),
])
def test_bad_distribution(kwargs, arg):
    with pytest.raises(ValueError, match=arg):
        LogNormalPSD(**kwargs)


def test_bad_histogram():
    e = np.geomspace(1, 10, 5)
    with refuses(ValueError, "basis"):
        fit_histogram(e, np.ones(4), basis="mass")
    with refuses(ValueError, "edges_um"):
        fit_histogram(e[::-1], np.ones(4), basis="number")
    with refuses(ValueError, "edges_um"):
        fit_histogram(np.r_[0.0, e[1:]], np.ones(4), basis="number")
    with refuses(ValueError, "percent"):
        fit_histogram(e, np.ones(3), basis="number")
    with refuses(ValueError, "percent"):
        fit_histogram(e, -np.ones(4), basis="number")
    with refuses(ValueError, "d_um"):
        fit_sample(np.array([1.0, -2.0, 3.0]))
    with pytest.raises(ValueError, match="sigma"):
        phi_rcp_lognormal(-0.1)
