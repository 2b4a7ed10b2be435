"""The prototypical-function surrogate (issue 11, first part): recovery, JSON, bad input."""

import json

import numpy as np
import pytest
from refusals import refuses

from itr_surrogate.prototype import LIBRARY, PrototypeRegressor


def sample(n: int, seed: int):
    """k_eff-like data: an S-curve in log R_fp (from the perfect to the resistive limit)
    plus a linear conductivity term, both shapes of the library."""
    rng = np.random.default_rng(seed)
    k = rng.uniform(20.0, 40.0, n)
    r = 10.0 ** rng.uniform(-8.0, -4.3, n)
    u = (np.log10(r) + 6.15) / 1.07
    y = 0.4 + 1.2 / (1.0 + np.exp(2.0 * (u - 0.3))) + 0.01 * (k - 30.0)
    return np.column_stack([k, r]), y


@pytest.fixture(scope="module")
def fitted():
    X, y = sample(200, 0)
    return PrototypeRegressor(feature_names=["k_Al2O3", "R_Al2O3_silicone"]).fit(X, y)


def test_library_has_twelve_shapes_and_resistances_go_on_a_log_scale(fitted):
    assert len(LIBRARY) == 12
    assert fitted.log_scale_ == [False, True]


def test_a_model_from_the_library_is_recovered_on_held_out_samples(fitted):
    Xt, yt = sample(500, 1)
    assert fitted.r2_ > 0.9999
    assert fitted.score(Xt, yt) > 0.9999
    names = {name for _, name in fitted.model_["terms"]}
    assert names & {"logistic", "tanh", "arctan"}  # the S-curve in log R
    assert "R_Al2O3_silicone" in fitted.to_expression()


def test_json_round_trip_predicts_identically_and_holds_no_code(fitted, tmp_path):
    Xt, _ = sample(100, 2)
    path = fitted.save(tmp_path / "model.json")
    doc = json.loads(path.read_text())  # plain JSON, readable expression inside
    assert doc["format"] == "itr-prototype-regressor" and "k_eff =" in doc["expression"]
    again = PrototypeRegressor.load(path)
    np.testing.assert_array_equal(again.predict(Xt), fitted.predict(Xt))
    doc["model"]["terms"][0][1] = "__import__('os')"
    with refuses(ValueError, "text"):
        PrototypeRegressor.from_json(json.dumps(doc))
    with refuses(ValueError, "text"):
        PrototypeRegressor.from_json("[1, 2]")


@pytest.mark.parametrize("call,argument", [
    (lambda m: m.fit(np.array([[1.0, np.nan]]), [1.0]), "X"),
    (lambda m: m.fit(np.ones(3), np.ones(3)), "X"),
    (lambda m: m.fit(np.ones((3, 2)), np.ones(2)), "y"),
    (lambda m: m.predict(np.ones((2, 2))), "PrototypeRegressor"),
    (lambda m: PrototypeRegressor(n_best_per_feature=0).fit(np.ones((3, 1)), np.ones(3)),
     "n_best_per_feature"),
])
def test_bad_input_names_the_argument(call, argument):
    with refuses(ValueError, argument):
        call(PrototypeRegressor())


def test_predict_checks_the_feature_count(fitted):
    with refuses(ValueError, "X"):
        fitted.predict(np.ones((4, 3)))
