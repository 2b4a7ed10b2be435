"""The Rao-Blackwell marginal (identify/inference/marginal.py) against analytic marginals."""

import numpy as np
import pytest
from refusals import refuses
from scipy import stats

from itr_identify.inference.marginal import Marginal, rao_blackwell


def test_quantiles_of_a_gridded_normal_are_the_normals():
    x = np.linspace(-8, 8, 801)
    m = Marginal(x, 3.0 * stats.norm.pdf(x, loc=0.5, scale=1.2))   # unnormalised on purpose
    np.testing.assert_allclose(m.quantile([0.05, 0.5, 0.95]),
                               stats.norm.ppf([0.05, 0.5, 0.95], loc=0.5, scale=1.2),
                               atol=2e-3)
    assert m.mode == pytest.approx(0.5, abs=0.02)
    back = Marginal.from_dict(m.to_dict())
    np.testing.assert_allclose(back.density, m.density)


def test_the_average_of_conditionals_of_a_correlated_normal_is_its_marginal():
    """x, y standard normals with correlation 0.8: the conditional of x given y is
    N(0.8 y, 0.36); averaged over draws of y it is N(0, 1), whose 5 % point is -1.645."""
    rho = 0.8
    cov = np.array([[1.0, rho], [rho, 1.0]])
    inv = np.linalg.inv(cov)

    def log_post(t):
        return -0.5 * np.einsum("ni,ij,nj->n", t, inv, t)

    theta = np.random.default_rng(3).multivariate_normal([0, 0], cov, size=4000)
    m = rao_blackwell(log_post, theta, 0, lo=-7.0, hi=7.0, grid=401)
    np.testing.assert_allclose(m.quantile([0.05, 0.5, 0.95]), [-1.645, 0.0, 1.645],
                               atol=0.05)


def test_a_flat_tail_is_integrated_not_counted():
    """A density flat below 0 down to the grid's end at -3 and a half-normal above: the
    exact 5 % point of that shape is where its CDF reaches 0.05."""
    x = np.linspace(-3, 4, 1401)
    d = np.where(x < 0, 1.0, np.exp(-0.5 * x ** 2))
    m = Marginal(x, d)
    mass = 3.0 + np.sqrt(np.pi / 2)
    assert float(m.quantile(0.05)) == pytest.approx(-3 + 0.05 * mass, abs=2e-3)


@pytest.mark.parametrize("bad, match", [
    ({"x": np.array([0.0, 1.0]), "density": np.array([1.0, 1.0])}, "x"),
    ({"x": np.array([0.0, 2.0, 1.0]), "density": np.ones(3)}, "x"),
    ({"x": np.arange(4.0), "density": np.array([0.0, -1.0, 1.0, 1.0])}, "density"),
])
def test_bad_grids_are_refused(bad, match):
    with refuses(ValueError, match):
        Marginal(**bad)
