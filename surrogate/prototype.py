"""The paper's prototypical-function surrogate: kappa = f(k_filler, R_fp, R_ff, ...).

Section 2.5 of the paper fits, per formulation, a closed-form model built from "prototypical
functions" of one variable (after Shen et al., who list no library). This module follows the
recipe with a library of its own, :data:`LIBRARY`, of twelve one-variable shapes (ranked by
BIC rather than the paper's plain R^2 at every step: on a weak feature plain R^2 keeps the
three-parameter shapes that fit noise and drops the linear one that holds the trend):

==============  ===========================================  ======================================
name            term g(u) (u: the standardised variable)     why
==============  ===========================================  ======================================
linear          b u                                          first-order trend
quadratic       b u + c u^2                                  curvature
cubic           b u + c u^2 + d u^3                          inflexion
exp             b exp(c u)                                   growth / decay
logistic        b / (1 + exp(-c (u - d)))                    the S-curve of k_eff in log R between
                                                             the perfect and the insulating limit
tanh            b tanh(c (u - d))                            symmetric S-curve
arctan          b arctan(c (u - d))                          S-curve with slow tails
gauss           b exp(-c (u - d)^2)                          a bump
softplus        b log(1 + exp(c (u - d)))                    a kink between two slopes
series          b / (1 + c x / x_ref)                        a resistance in series (x raw)
power           b (x / x_ref)^c                              a scaling law (x raw)
log             b ln(x / x_ref)                              Maxwell-like conductivity dependence
==============  ===========================================  ======================================

A feature is taken on a log scale (t = log10 x) when its name is a resistance or contact
conductance of the package's flat naming (``R_``, ``Rff_``, ``Gc_``) or, for unnamed features,
when it is positive and spans more than a decade; u = (t - mean) / std over the training
data. x_ref is the geometric mean of the raw feature.

Fitting (:meth:`PrototypeRegressor.fit`): (1) per feature, every library shape is fitted alone
(``y ~ a + g(u)``) and the best ``n_best_per_feature`` are kept; (2) for every
non-empty subset of features, every combination of the kept shapes is fitted jointly with
:func:`scipy.optimize.curve_fit`, both as a sum ``a + sum_j g_j(u_j)`` and as a product
``a (1 + g_1(u_1)) (1 + g_2(u_2)) ...`` (the sum started by backfitting the terms one at a
time), and the best ``n_best_per_subset`` per subset are kept; (3) the final model is the
kept candidate of lowest BIC (R^2 with a penalty of its parameter count). It is stored as
JSON with its readable expression (:meth:`to_expression`); loading never unpickles.
"""

from __future__ import annotations

import itertools
import json
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit

__all__ = ["PrototypeRegressor", "LIBRARY", "Shape"]


@dataclass(frozen=True)
class Shape:
    """One library function: ``term(u, x_rel, *params)``; its initial guesses; its text."""

    name: str
    n_params: int
    term: Callable[..., np.ndarray]
    guesses: tuple[tuple[float, ...], ...]
    text: str  # format with b, c, d and the variable names u, x


def _lin(u, x, b):
    return b * u


def _quad(u, x, b, c):
    return b * u + c * u * u


def _cubic(u, x, b, c, d):
    return b * u + c * u * u + d * u * u * u


def _exp(u, x, b, c):
    return b * np.exp(np.clip(c * u, -50, 50))


def _logistic(u, x, b, c, d):
    return b / (1.0 + np.exp(np.clip(-c * (u - d), -50, 50)))


def _tanh(u, x, b, c, d):
    return b * np.tanh(c * (u - d))


def _arctan(u, x, b, c, d):
    return b * np.arctan(c * (u - d))


def _gauss(u, x, b, c, d):
    return b * np.exp(-np.clip(c * (u - d) ** 2, -50, 50))


def _softplus(u, x, b, c, d):
    return b * np.logaddexp(0.0, c * (u - d))


def _series(u, x, b, c):
    return b / (1.0 + np.abs(c) * x)


def _power(u, x, b, c):
    return b * np.power(x, c)


def _log(u, x, b):
    return b * np.log(x)


#: The twelve one-variable shapes (see the module docstring).
LIBRARY: dict[str, Shape] = {s.name: s for s in (
    Shape("linear", 1, _lin, ((1.0,), (-1.0,)), "{b}*{u}"),
    Shape("quadratic", 2, _quad, ((1.0, 0.1), (-1.0, -0.1)), "({b}*{u} + {c}*{u}^2)"),
    Shape("cubic", 3, _cubic, ((1.0, 0.1, 0.01), (-1.0, 0.1, -0.01)),
          "({b}*{u} + {c}*{u}^2 + {d}*{u}^3)"),
    Shape("exp", 2, _exp, ((1.0, 0.5), (1.0, -0.5), (-1.0, 0.5)), "{b}*exp({c}*{u})"),
    Shape("logistic", 3, _logistic, ((1.0, 2.0, 0.0), (-1.0, 2.0, 0.0), (1.0, -2.0, 0.0)),
          "{b}/(1 + exp(-{c}*({u} - {d})))"),
    Shape("tanh", 3, _tanh, ((1.0, 1.0, 0.0), (-1.0, 1.0, 0.0)), "{b}*tanh({c}*({u} - {d}))"),
    Shape("arctan", 3, _arctan, ((1.0, 1.0, 0.0), (-1.0, 1.0, 0.0)),
          "{b}*arctan({c}*({u} - {d}))"),
    Shape("gauss", 3, _gauss, ((1.0, 0.5, 0.0), (-1.0, 0.5, 0.0)),
          "{b}*exp(-{c}*({u} - {d})^2)"),
    Shape("softplus", 3, _softplus, ((1.0, 1.0, 0.0), (-1.0, 1.0, 0.0), (1.0, -1.0, 0.0)),
          "{b}*log(1 + exp({c}*({u} - {d})))"),
    Shape("series", 2, _series, ((1.0, 1.0), (1.0, 0.1), (1.0, 10.0)),
          "{b}/(1 + |{c}|*{x})"),
    Shape("power", 2, _power, ((1.0, 0.5), (1.0, -0.5)), "{b}*{x}^{c}"),
    Shape("log", 1, _log, ((1.0,), (-1.0,)), "{b}*ln({x})"),
)}

_LOG_PREFIXES = ("R_", "Rff_", "Gc_")


@dataclass(frozen=True)
class _Candidate:
    """A fitted model: combiner, (feature, shape) terms, parameters, R^2 and BIC."""

    combiner: str
    terms: tuple[tuple[int, str], ...]
    params: tuple[float, ...]
    r2: float
    bic: float


class PrototypeRegressor:
    """Closed-form surrogate from prototypical one-variable functions (scikit-learn style).

    Parameters
    ----------
    n_best_per_feature : int
        Shapes kept per feature after the one-variable fits (the paper: 3).
    n_best_per_subset : int
        Combinations kept per feature subset (the paper: 3).
    feature_names : sequence of str, optional
        Names of the columns of X (the package's flat names, e.g. ``R_Al2O3_silicone``):
        they decide the log scale and appear in :meth:`to_expression`.
    maxfev : int
        Function evaluations per ``curve_fit``.

    Attributes
    ----------
    feature_names_in_ : list of str
    log_scale_ : list of bool
        Whether each feature enters as log10.
    center_, scale_ : ndarray
        Standardisation of the (log) features.
    x_ref_ : ndarray
        Geometric mean of each raw feature (the shapes on raw x use x / x_ref).
    model_ : dict
        The chosen model: ``combiner``, ``terms`` [(feature index, shape name)], ``params``.
    r2_ : float
        R^2 of the chosen model on the training data.
    candidates_ : list of dict
        Every kept candidate with its R^2 and BIC (for the report).
    """

    def __init__(self, n_best_per_feature: int = 3, n_best_per_subset: int = 3,
                 feature_names: Sequence[str] | None = None, maxfev: int = 2000) -> None:
        self.n_best_per_feature = n_best_per_feature
        self.n_best_per_subset = n_best_per_subset
        self.feature_names = feature_names
        self.maxfev = maxfev

    # ------------------------------------------------------------------ checks
    def _check_params(self) -> None:
        for key in ("n_best_per_feature", "n_best_per_subset", "maxfev"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{key}: expected a whole number >= 1, got {v!r}")

    @staticmethod
    def _check_X(X, n_features: int | None = None) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or X.shape[0] == 0:
            raise ValueError(f"X: expected a 2-D array (n_samples, n_features), got shape "
                             f"{X.shape}")
        if not np.all(np.isfinite(X)):
            raise ValueError("X: holds NaN or infinite values")
        if n_features is not None and X.shape[1] != n_features:
            raise ValueError(f"X: expected {n_features} features, got {X.shape[1]}")
        return X

    # -------------------------------------------------------------- transforms
    def _setup(self, X: np.ndarray) -> None:
        p = X.shape[1]
        names = list(self.feature_names) if self.feature_names is not None else \
            [f"x{j}" for j in range(p)]
        if len(names) != p:
            raise ValueError(f"feature_names: {len(names)} names for {p} features")
        positive = np.all(X > 0, axis=0)
        self.feature_names_in_ = names
        self.log_scale_ = [bool(positive[j] and (names[j].startswith(_LOG_PREFIXES) or
                                                 (self.feature_names is None and
                                                  X[:, j].max() > 10 * X[:, j].min())))
                           for j in range(p)]
        t = self._t(X)
        self.center_ = t.mean(axis=0)
        self.scale_ = np.where(t.std(axis=0) > 0, t.std(axis=0), 1.0)
        self.x_ref_ = np.array([math.exp(np.log(X[:, j]).mean()) if positive[j] else 1.0
                                for j in range(p)])

    def _t(self, X: np.ndarray) -> np.ndarray:
        t = X.copy()
        for j, lg in enumerate(self.log_scale_):
            if lg:
                t[:, j] = np.log10(X[:, j])
        return t

    def _variables(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = (self._t(X) - self.center_) / self.scale_
        with np.errstate(invalid="ignore", divide="ignore"):
            x = X / self.x_ref_
        return u, x

    # ------------------------------------------------------------------ models
    @staticmethod
    def _evaluate(combiner: str, terms, params, u: np.ndarray, x: np.ndarray) -> np.ndarray:
        a = params[0]
        k = 1
        parts = []
        for j, name in terms:
            shape = LIBRARY[name]
            parts.append(shape.term(u[:, j], x[:, j], *params[k:k + shape.n_params]))
            k += shape.n_params
        if combiner == "sum":
            return a + np.sum(parts, axis=0)
        out = np.full(u.shape[0], a)
        for g in parts:
            out = out * (1.0 + g)
        return out

    def _fit_one(self, combiner: str, terms, u, x, y, starts) -> _Candidate | None:
        def f(_, *p):
            return self._evaluate(combiner, terms, p, u, x)

        best = None
        for p0 in starts:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", OptimizeWarning)
                warnings.simplefilter("ignore", RuntimeWarning)
                try:
                    p, _ = curve_fit(f, None, y, p0=p0, maxfev=self.maxfev)
                except (RuntimeError, ValueError, TypeError):
                    continue
            pred = f(None, *p)
            if not np.all(np.isfinite(pred)):
                continue
            sse = float(np.sum((y - pred) ** 2))
            if best is None or sse < best[1]:
                best = (p, sse)
        if best is None:
            return None
        p, sse = best
        n = y.size
        sst = float(np.sum((y - y.mean()) ** 2)) or 1.0
        bic = n * math.log(max(sse, 1e-300) / n) + len(p) * math.log(n)
        return _Candidate(combiner, tuple(terms), tuple(float(v) for v in p), 1 - sse / sst,
                          bic)

    def _backfit_start(self, terms, u, x, y, singles: dict) -> list[float]:
        """Additive start by backfitting: each term (strongest one-variable fit first) is
        fitted alone to what the terms before it leave of y."""
        order = sorted(range(len(terms)), key=lambda i: -singles.get(terms[i], ((), 0.0))[1])
        resid = y.copy()
        intercept = 0.0
        found: dict[int, tuple] = {}
        for i in order:
            c = self._fit_one("sum", (terms[i],), u, x, resid,
                              self._starts("sum", (terms[i],), {}, resid))
            if c is None:
                return []
            found[i] = c.params[1:]
            intercept += c.params[0]
            resid = resid - self._evaluate("sum", (terms[i],), c.params, u, x)
        return [intercept, *itertools.chain.from_iterable(found[i] for i in range(len(terms)))]

    def _starts(self, combiner: str, terms, singles: dict, y: np.ndarray,
                backfit: list[float] | None = None) -> list[list[float]]:
        """Initial parameters: a backfitted start, and the library guesses."""
        a0 = float(y.mean())
        span = float(y.std()) or 1.0
        starts = [backfit] if backfit and combiner == "sum" else []
        for combo in itertools.product(*(LIBRARY[n].guesses for _, n in terms)):
            scale = span if combiner == "sum" else 0.5
            p = [a0]
            for g in combo:
                p += [g[0] * scale, *g[1:]]
            starts.append(p)
            if len(starts) >= 3:
                break
        return starts

    # ------------------------------------------------------------------- API
    def fit(self, X, y) -> "PrototypeRegressor":
        """Fit the surrogate to samples ``X`` (n, p) and targets ``y`` (n,)."""
        self._check_params()
        X = self._check_X(X)
        y = np.asarray(y, dtype=np.float64).ravel()
        if y.size != X.shape[0] or not np.all(np.isfinite(y)):
            raise ValueError(f"y: expected {X.shape[0]} finite values, got {y.size}")
        self._setup(X)
        u, x = self._variables(X)
        p = X.shape[1]
        singles, kept = {}, {}
        for j in range(p):
            fits = []
            for name in LIBRARY:
                if name in ("series", "power", "log") and not np.all(X[:, j] > 0):
                    continue
                c = self._fit_one("sum", ((j, name),), u, x, y,
                                  self._starts("sum", ((j, name),), {}, y))
                if c is not None:
                    singles[(j, name)] = (c.params, c.r2)
                    fits.append(c)
            fits.sort(key=lambda c: c.bic)  # R^2 alone always prefers 3-parameter shapes
            kept[j] = [c.terms[0][1] for c in fits[: self.n_best_per_feature]]
        candidates = []
        for size in range(1, p + 1):
            for subset in itertools.combinations(range(p), size):
                fits = []
                for names in itertools.product(*(kept[j] for j in subset)):
                    terms = tuple(zip(subset, names))
                    back = self._backfit_start(terms, u, x, y, singles) if size > 1 else \
                        [singles[terms[0]][0][0], *singles[terms[0]][0][1:]]
                    for combiner in (("sum", "product") if size > 1 else ("sum",)):
                        c = self._fit_one(combiner, terms, u, x, y,
                                          self._starts(combiner, terms, singles, y, back))
                        if c is not None:
                            fits.append(c)
                fits.sort(key=lambda c: -c.r2)
                candidates += fits[: self.n_best_per_subset]
        if not candidates:
            raise RuntimeError("fit: no candidate model could be fitted to these data")
        best = min(candidates, key=lambda c: c.bic)
        self.model_ = {"combiner": best.combiner, "terms": [list(t) for t in best.terms],
                       "params": list(best.params)}
        self.r2_ = best.r2
        self.candidates_ = [{"combiner": c.combiner, "terms": [list(t) for t in c.terms],
                             "r2": c.r2, "bic": c.bic} for c in sorted(candidates,
                                                                       key=lambda c: c.bic)]
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "model_"):
            raise ValueError("PrototypeRegressor: not fitted yet; call fit(X, y) first")

    def predict(self, X) -> np.ndarray:
        """Predicted targets for samples ``X`` (n, p)."""
        self._check_fitted()
        X = self._check_X(X, len(self.feature_names_in_))
        u, x = self._variables(X)
        m = self.model_
        return self._evaluate(m["combiner"], [tuple(t) for t in m["terms"]], m["params"], u, x)

    def score(self, X, y) -> float:
        """R^2 of the prediction on ``(X, y)``."""
        y = np.asarray(y, dtype=np.float64).ravel()
        pred = self.predict(X)
        return float(1.0 - np.sum((y - pred) ** 2) / np.sum((y - y.mean()) ** 2))

    # ------------------------------------------------------------ expression
    def to_expression(self, target: str = "k_eff", digits: int = 6) -> str:
        """The fitted model as readable text, with the definitions of its variables."""
        self._check_fitted()
        m = self.model_
        params = m["params"]

        def num(v: float) -> str:
            return f"{v:.{digits}g}"

        def minus(v: float) -> str:  # "u - d" with the sign folded in
            return f"- {num(v)}" if v >= 0 else f"+ {num(-v)}"

        k = 1
        parts, defs = [], []
        for j, name in (tuple(t) for t in m["terms"]):
            shape = LIBRARY[name]
            p = params[k:k + shape.n_params]
            k += shape.n_params
            fmt = dict(zip("bcd", (num(v) for v in p)))
            u, xv = f"u{j}", f"x{j}"
            text = shape.text.format(u=u, x=xv, **fmt).replace(f"{u} - {fmt.get('d')})",
                                                                 f"{u} {minus(p[-1])})")
            parts.append(text)
            feat = self.feature_names_in_[j]
            if "{u}" in shape.text:
                base = f"log10({feat})" if self.log_scale_[j] else feat
                defs.append(f"{u} = ({base} {minus(self.center_[j])}) / "
                            f"{num(self.scale_[j])}")
            if "{x}" in shape.text:
                defs.append(f"{xv} = {feat} / {num(self.x_ref_[j])}")
        if m["combiner"] == "sum":
            body = " + ".join([num(params[0]), *parts]).replace("+ -", "- ")
        else:
            body = num(params[0]) + "".join(f" * (1 + {p})" for p in parts)
        return f"{target} = {body}\nwhere " + "; ".join(sorted(set(defs)))

    # ------------------------------------------------------------------ JSON
    def to_json(self) -> str:
        """JSON text of the fitted model (plain numbers and names; no code)."""
        self._check_fitted()
        return json.dumps({
            "format": "itr-prototype-regressor", "version": 1,
            "params": {"n_best_per_feature": self.n_best_per_feature,
                       "n_best_per_subset": self.n_best_per_subset, "maxfev": self.maxfev},
            "feature_names": self.feature_names_in_, "log_scale": self.log_scale_,
            "center": self.center_.tolist(), "scale": self.scale_.tolist(),
            "x_ref": self.x_ref_.tolist(), "model": self.model_, "r2": self.r2_,
            "expression": self.to_expression()}, indent=2)

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_json` to ``path`` atomically."""
        from itr_fv.io import write_text

        return write_text(path, self.to_json() + "\n")

    @classmethod
    def from_json(cls, text: str) -> "PrototypeRegressor":
        """A fitted regressor from :meth:`to_json` text (shapes looked up by name)."""
        d = json.loads(text)
        if not isinstance(d, dict) or d.get("format") != "itr-prototype-regressor":
            raise ValueError("text: not a PrototypeRegressor JSON document")
        for _, name in d["model"]["terms"]:
            if name not in LIBRARY:
                raise ValueError(f"text: unknown shape {name!r} (library: {sorted(LIBRARY)})")
        reg = cls(**d["params"], feature_names=d["feature_names"])
        reg.feature_names_in_ = list(d["feature_names"])
        reg.log_scale_ = [bool(v) for v in d["log_scale"]]
        reg.center_ = np.array(d["center"], dtype=np.float64)
        reg.scale_ = np.array(d["scale"], dtype=np.float64)
        reg.x_ref_ = np.array(d["x_ref"], dtype=np.float64)
        reg.model_ = d["model"]
        reg.r2_ = float(d["r2"])
        return reg

    @classmethod
    def load(cls, path: str | Path) -> "PrototypeRegressor":
        return cls.from_json(Path(path).read_text())

    def __repr__(self) -> str:
        return (f"PrototypeRegressor(n_best_per_feature={self.n_best_per_feature}, "
                f"n_best_per_subset={self.n_best_per_subset})")
