"""The design space of ``itr design``: its grid, names, interpolation and choice (no solves)."""

import numpy as np
import pytest
from refusals import refuses

from itr_identify.inference.design_space import DesignSpace, choose, costs, lagrange_weights


def test_lagrange_weights_reproduce_a_quadratic_exactly():
    nodes = [0.55, 0.60, 0.65]
    x = np.linspace(0.5, 0.7, 9)
    f = lambda t: 3.0 - 2.0 * t + 7.5 * t ** 2  # noqa: E731
    w = lagrange_weights(nodes, x)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(w @ f(np.array(nodes)), f(x), rtol=1e-12)


def test_two_filler_interpolation_is_exact_on_a_biquadratic():
    space = DesignSpace(("Al2O3", "AlN"), (0.50, 0.65))
    f = lambda s, t: 0.2 + s * t + 0.3 * s ** 2 - 1.1 * t ** 2  # noqa: E731
    at = np.array([[f(s, t)] for s, t in space.anchors()])           # (9, 1)
    shares, totals = space.shares(), space.totals()
    got = space.interpolate(at, shares, totals)[..., 0]
    np.testing.assert_allclose(got, f(shares[:, None], totals[None, :]), atol=1e-12)


def test_grid_and_names():
    space = DesignSpace(("Al2O3", "AlN"), (0.50, 0.65), total_step=0.005, share_step=0.25)
    assert space.totals().size == 31 and space.totals()[0] == 0.5 and space.totals()[-1] == 0.65
    np.testing.assert_allclose(space.shares(), [1.0, 0.75, 0.5, 0.25, 0.0])
    assert [space.name(s, t) for s, t in space.anchors()][:4] == [
        "Al2O3-50", "Al2O3-57.5", "Al2O3-65", "Al2O3-25-AlN-25"]
    assert space.name(0.0, 0.6) == "AlN-60"
    assert space.name(0.75, 0.6) == "Al2O3-45-AlN-15"
    one = DesignSpace(("AlN",), (0.6, 0.6))
    assert one.anchors() == [(1.0, 0.6)] and one.name(1.0, 0.6) == "AlN-60"


@pytest.mark.parametrize("kwargs, argument", [
    ({"fillers": ("Al2O3", "AlN", "ZnO"), "total": (0.5, 0.6)}, "fillers"),
    ({"fillers": ("AlN", "AlN"), "total": (0.5, 0.6)}, "fillers"),
    ({"fillers": ("AlN",), "total": (0.6, 0.5)}, "total"),
    ({"fillers": ("AlN",), "total": (0.5, 0.8)}, "total"),
    ({"fillers": ("AlN",), "total": (0.5, 0.6), "total_step": 0.0}, "total_step"),
])
def test_a_bad_space_is_refused(kwargs, argument):
    with refuses(ValueError, argument):
        DesignSpace(**kwargs)


def test_choose_finds_the_least_filler_reaching_the_target():
    # k = 4 t exactly (no spread): 2.0 W/(m K) is first reached at t = 0.5
    space = DesignSpace(("Al2O3",), (0.40, 0.60), total_step=0.01)
    shares, totals = space.shares(), space.totals()
    draws = np.repeat((4.0 * totals)[None, :, None], 50, axis=2)
    choice, p, c = choose(space, draws, shares, totals, target=2.0, probability=0.95)
    assert choice.total == pytest.approx(0.50) and choice.name == "Al2O3-50"
    assert p[0, totals < 0.495].max() == 0 and p[0, totals > 0.495].min() == 1
    # with spread: normal sd 0.1 about 4 t; P >= 0.95 needs 4 t >= 2 + 1.645 * 0.1
    rng = np.random.default_rng(0)
    noisy = (4.0 * totals)[None, :, None] + 0.1 * rng.standard_normal((1, totals.size, 40000))
    choice, p, _ = choose(space, noisy, shares, totals, target=2.0, probability=0.95)
    assert choice.total == pytest.approx(0.55, abs=1e-9)       # (2 + 0.1645) / 4 = 0.541
    assert p[0, 14] < 0.95 <= p[0, 15]                          # 0.54 misses, 0.55 reaches
    # P >= 0.95 is the 5 % quantile at or above the target
    assert choice.interval[0] >= 2.0 and choice.median == pytest.approx(2.2, abs=0.01)


def test_a_stated_cost_prefers_the_cheaper_filler():
    # both fillers give k = 4 t; AlN costs three times Al2O3: the cheapest is Al2O3 alone
    space = DesignSpace(("Al2O3", "AlN"), (0.40, 0.60), total_step=0.01, share_step=0.25)
    shares, totals = space.shares(), space.totals()
    draws = np.broadcast_to((4.0 * totals)[None, :, None], (shares.size, totals.size, 10))
    c = costs(space, shares, totals, {"AlN": 3.0})
    np.testing.assert_allclose(c[:, 10], [50, 75, 100, 125, 150])
    choice, _, _ = choose(space, draws, shares, totals, target=2.0, probability=0.95,
                          cost={"AlN": 3.0})
    assert choice.name == "Al2O3-50" and choice.cost == pytest.approx(50)


def test_nothing_reaching_the_target_is_said():
    space = DesignSpace(("Al2O3",), (0.40, 0.60))
    shares, totals = space.shares(), space.totals()
    draws = np.ones((1, totals.size, 10))
    choice, p, _ = choose(space, draws, shares, totals, target=2.0, probability=0.95)
    assert choice is None and p.max() == 0


class _Residuals:
    """A likelihood's face that formulation_sd reads: model k and variance at the draws,
    and the measured means."""

    def __init__(self, means, k, v):
        self.order = [f"F{i}" for i in range(len(means))]
        self.data = {f: (m, 0.0, 4) for f, m in zip(self.order, means)}
        self._k, self._v = np.asarray(k, float), np.asarray(v, float)

    def predictive(self, theta):
        n = theta.shape[0]
        return np.repeat(self._k[:, None], n, axis=1), np.repeat(self._v[:, None], n, axis=1)


def test_formulation_sd_brings_the_chi_square_to_its_degrees_of_freedom():
    from itr_identify.inference.predictive import formulation_sd

    # four formulations, model k 1 and sd 0.1 each, every mean 0.3 off: chi-square 36 on
    # 4 - 1 = 3 dof; 4 * 0.09 / (0.01 + s^2) = 3 gives s^2 = 0.11
    lik = _Residuals([1.3, 0.7, 1.3, 0.7], [1, 1, 1, 1], [0.01] * 4)
    assert formulation_sd(lik, np.zeros((5, 2)), fitted=1) == pytest.approx(0.11 ** 0.5,
                                                                            rel=1e-9)
    # a fit that passes its test leaves no misfit term
    ok = _Residuals([1.05, 0.95, 1.0, 1.0], [1, 1, 1, 1], [0.01] * 4)
    assert formulation_sd(ok, np.zeros((5, 2)), fitted=1) == 0.0
