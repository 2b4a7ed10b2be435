"""The paper's baseline regressors (Section 3.3) and its precision check.

The paper compares its prototypical-function model with XGBoost, support-vector regression
(SVR) and an artificial neural network (ANN), and rejects XGBoost on a *precision check*:
with the filler conductivity and one resistance fixed, moving the other resistance inside
one grid step (2.0e-8 ... 2.9e-8 m^2 K/W) leaves XGBoost's prediction unchanged, since a
tree ensemble is piecewise constant between the training values.

:func:`make_baseline` builds each as a scikit-learn estimator on the same features as
:class:`~itr_surrogate.prototype.PrototypeRegressor` (flat parameter names; resistances on a
log10 scale, every feature and the target standardised), so that one train/test split
serves all. The models live for a study; they are not saved (the surrogates a user loads
are the prototype model's JSON and the reduced basis's npz).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from itr_fv.materials.parameters import is_log_scaled

__all__ = ["BASELINES", "make_baseline", "precision_check", "r2_score", "max_relative_error"]

#: The baselines, by the names the study and the command line use.
BASELINES = ("xgboost", "svr", "mlp")


def _log_columns(feature_names: Sequence[str]) -> np.ndarray:
    return np.array([is_log_scaled(n) for n in feature_names])


def make_baseline(name: str, *, feature_names: Sequence[str], seed: int = 0):
    """A scikit-learn regressor for ``X`` with columns ``feature_names`` (flat names).

    Parameters
    ----------
    name : {"xgboost", "svr", "mlp"}
        XGBoost (400 trees of depth 4, learning rate 0.05), an RBF support-vector regressor
        (C = 10, epsilon = 0.01 on the standardised target) or a multilayer perceptron (two
        hidden layers of 32 tanh units, L-BFGS).
    feature_names : sequence of str
        Columns of X; resistances and contact conductances enter as log10.
    seed : int
        Seed of the model's random steps.

    Raises
    ------
    ValueError
        For an unknown name, or ``"xgboost"`` without the xgboost package (naming the
        package to install).
    """
    from sklearn.compose import TransformedTargetRegressor
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import FunctionTransformer, StandardScaler

    if name not in BASELINES:
        raise ValueError(f"name: expected one of {BASELINES}, got {name!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: expected a whole number >= 0, got {seed!r}")
    log = _log_columns(list(feature_names))

    def to_features(X):
        X = np.asarray(X, dtype=np.float64)
        return np.where(log, np.log10(np.where(log, X, 1.0)), X)

    if name == "xgboost":
        try:
            import xgboost
        except ImportError:
            raise ValueError("name: 'xgboost' needs the xgboost package "
                             "(pip install xgboost-cpu)") from None
        model = xgboost.XGBRegressor(n_estimators=400, max_depth=4, learning_rate=0.05,
                                     random_state=int(seed), n_jobs=1)
    elif name == "svr":
        from sklearn.svm import SVR

        model = SVR(kernel="rbf", C=10.0, epsilon=0.01, gamma="scale")
    else:
        from sklearn.neural_network import MLPRegressor

        model = MLPRegressor(hidden_layer_sizes=(32, 32), activation="tanh", solver="lbfgs",
                             max_iter=5000, random_state=int(seed))
    pipe = make_pipeline(FunctionTransformer(to_features), StandardScaler(), model)
    return TransformedTargetRegressor(regressor=pipe, transformer=StandardScaler())


def r2_score(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """Coefficient of determination ``1 - SS_res / SS_tot``."""
    y_true = np.asarray(y_true, dtype=np.float64)
    y_pred = np.asarray(y_pred, dtype=np.float64)
    return float(1.0 - np.sum((y_true - y_pred) ** 2) / np.sum((y_true - y_true.mean()) ** 2))


def max_relative_error(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    """``max |y_pred - y_true| / |y_true|``."""
    y_true = np.asarray(y_true, dtype=np.float64)
    return float(np.max(np.abs(np.asarray(y_pred) - y_true) / np.abs(y_true)))


def precision_check(predict: Callable[[np.ndarray], np.ndarray], *,
                    feature_names: Sequence[str], base: dict[str, float], feature: str,
                    values: Sequence[float]) -> dict:
    """The paper's precision check: predictions while one feature moves inside a grid step.

    Parameters
    ----------
    predict : callable
        ``predict(X) -> y`` for X with columns ``feature_names``.
    feature_names : sequence of str
        Columns of X.
    base : dict
        Value of every other feature.
    feature : str
        The feature that moves (the paper: a resistance from 2.0e-8 to 2.9e-8 m^2 K/W).
    values : sequence of float
        Its values, inside one step of the training grid.

    Returns
    -------
    dict
        ``values``, ``predictions``, ``distinct`` (number of different predictions, to a
        relative 1e-12) and ``relative_change`` ((last - first) / first).
    """
    names = list(feature_names)
    if feature not in names:
        raise ValueError(f"feature: {feature!r} is not one of {names}")
    missing = [n for n in names if n != feature and n not in base]
    if missing:
        raise ValueError(f"base: no value for {missing[0]!r}")
    values = np.asarray(values, dtype=np.float64)
    X = np.empty((values.size, len(names)))
    for j, n in enumerate(names):
        X[:, j] = values if n == feature else base[n]
    y = np.asarray(predict(X), dtype=np.float64).ravel()
    distinct = 1 + int(np.sum(np.abs(np.diff(np.sort(y))) > 1e-12 * np.abs(y).max()))
    return {"values": values.tolist(), "predictions": y.tolist(), "distinct": distinct,
            "relative_change": float((y[-1] - y[0]) / y[0])}
