"""The paper's baselines (XGBoost, SVR, MLP) and its precision check (issue 11)."""

import numpy as np
import pytest
from refusals import refuses

from itr_surrogate.baselines import (
    BASELINES,
    make_baseline,
    max_relative_error,
    precision_check,
    r2_score,
)
from itr_surrogate.prototype import PrototypeRegressor

NAMES = ["k_Al2O3", "R_Al2O3_silicone"]
K_GRID = [20.0, 25.0, 30.0, 35.0, 40.0]
R_GRID = [1e-8, 5e-8, 1e-7, 5e-7, 1e-6, 5e-6, 1e-5, 5e-5]


def law(X):
    """A k_eff-like law: an S-curve in log R_fp plus a linear conductivity term."""
    u = (np.log10(X[:, 1]) + 6.15) / 1.07
    return 0.4 + 1.2 / (1.0 + np.exp(2.0 * (u - 0.3))) + 0.01 * (X[:, 0] - 30.0)


def grid():
    return np.array([(k, r) for k in K_GRID for r in R_GRID])


def held_out(n=200, seed=1):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(20, 40, n), 10 ** rng.uniform(-8, np.log10(5e-5), n)])


@pytest.mark.parametrize("name", BASELINES)
def test_each_baseline_learns_the_table4_grid(name):
    X = grid()
    model = make_baseline(name, feature_names=NAMES, seed=0).fit(X, law(X))
    Xt = held_out()
    assert r2_score(law(Xt), model.predict(Xt)) > 0.9  # XGBoost: steps between grid values


def test_xgboost_is_flat_inside_one_grid_step_and_the_prototype_is_not():
    X = grid()
    y = law(X)
    values = np.linspace(2.0e-8, 2.9e-8, 10)  # the paper's check, inside [1e-8, 5e-8]
    base = {"k_Al2O3": 30.0}
    xgb = make_baseline("xgboost", feature_names=NAMES).fit(X, y)
    flat = precision_check(xgb.predict, feature_names=NAMES, base=base,
                           feature="R_Al2O3_silicone", values=values)
    proto = PrototypeRegressor(feature_names=NAMES).fit(X, y)
    moving = precision_check(proto.predict, feature_names=NAMES, base=base,
                             feature="R_Al2O3_silicone", values=values)
    true_change = float((law(np.array([[30.0, 2.9e-8]])) - law(np.array([[30.0, 2.0e-8]])))[0]
                        / law(np.array([[30.0, 2.0e-8]]))[0])
    assert flat["distinct"] == 1 and flat["relative_change"] == 0.0
    assert moving["distinct"] == 10
    assert moving["relative_change"] == pytest.approx(true_change, rel=0.05)


def test_metrics_match_their_formulas():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    p = np.array([1.1, 1.9, 3.0, 4.2])
    assert r2_score(y, p) == pytest.approx(1 - (0.01 + 0.01 + 0 + 0.04) / 5.0)
    assert max_relative_error(y, p) == pytest.approx(0.1)


@pytest.mark.parametrize("call,argument", [
    (lambda: make_baseline("forest", feature_names=NAMES), "name"),
    (lambda: make_baseline("svr", feature_names=NAMES, seed=-1), "seed"),
    (lambda: precision_check(lambda X: X[:, 0], feature_names=NAMES, base={},
                             feature="R_Al2O3_silicone", values=[1e-8]), "base"),
    (lambda: precision_check(lambda X: X[:, 0], feature_names=NAMES, base={},
                             feature="k_AlN", values=[1.0]), "feature"),
])
def test_bad_input_names_the_argument(call, argument):
    with refuses(ValueError, argument):
        call()
