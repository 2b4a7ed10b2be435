"""The fit's test where the inputs may move: the model alone, without a model-form term,
at its highest-posterior point over the resistances *and* the uncertain inputs.

At the stated inputs a fit can fail only because the matrix is 8 % more conductive than its
datasheet says; the joint posterior lets it be, at a price the prior sets. The test that
belongs to that model is therefore taken where the posterior without the model form
(:class:`~.priors.ModelFormPrior` ``on=False``: the resistances, the conductivities, the
film and the shipped corrections' shared terms) is highest, and it counts both prices:

    chi2 = sum_f (mean_f - k_f)^2 / (v_f + (p_f k_f)^2)  +  sum_i ((x_i - m_i) / s_i)^2

over the formulations ``f`` (the likelihood's variance ``v`` and the pooled packing sd
``p``) and the normal-prior inputs ``i`` (a conductivity's ln ratio, a shared correction
term). Each input adds a datum (its prior) and a parameter, so the degrees of freedom are
the formulations less the parameters with flat priors (the resistances, a film). A uniform
film has no prior price.

The maximum is climbed by L-BFGS-B within the priors' bounds (central differences, every
point of a gradient in one vectorised call of the joint likelihood) and polished by
Nelder-Mead, from the best of the prior's draws and of a posterior's, where one is given
(scipy.optimize, a well-kept optimiser).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import minimize

from .joint import JointLikelihood
from .misfit import MISFIT_P, chi_square_p

__all__ = ["STARTS", "describe", "fit_with_inputs_free"]

#: Starting points of the optimiser (the best prior draws by posterior).
STARTS = 4
#: Prior draws the starts are chosen from.
PRIOR_DRAWS = 20000


def _bounds(space) -> list[tuple[float | None, float | None]]:
    """Each parameter's bounds (a uniform prior's range, a half-normal's 0)."""
    return [(a, b) if kind == "uniform" else (0.0, None) if kind == "halfnormal"
            else (None, None) for kind, a, b in zip(space.kinds, space.a, space.b)]


def _climb(likelihood: JointLikelihood, x0: np.ndarray, *, polish: bool = False
           ) -> tuple[np.ndarray, float]:
    """The highest posterior near ``x0``: L-BFGS-B within the priors' bounds on central
    differences (all 2 D + 1 points of a gradient in one vectorised call of the posterior),
    then, with ``polish``, Nelder-Mead where a bound's one-sided difference leaves it
    short."""
    space = likelihood.space
    bounds = _bounds(space)
    lo = np.array([-np.inf if b[0] is None else b[0] for b in bounds])
    hi = np.array([np.inf if b[1] is None else b[1] for b in bounds])
    h = 1e-6 * np.maximum(1.0, np.abs(x0))

    def neg(t: np.ndarray) -> float:
        v = float(likelihood.log_posterior(t[None, :])[0])
        return -v if np.isfinite(v) else 1e300

    def value_and_gradient(t: np.ndarray) -> tuple[float, np.ndarray]:
        up, dn = np.minimum(t + h, hi), np.maximum(t - h, lo)
        eye = np.eye(t.size)
        pts = np.vstack([t[None, :], t + (up - t)[:, None] * eye, t - (t - dn)[:, None] * eye])
        lp = likelihood.log_posterior(pts)
        if not np.all(np.isfinite(lp)):
            return 1e300, np.zeros(t.size)
        width = up - dn
        grad = (lp[1:t.size + 1] - lp[t.size + 1:]) / np.where(width > 0, width, 1.0)
        return -float(lp[0]), -grad

    res = minimize(value_and_gradient, x0, jac=True, method="L-BFGS-B", bounds=bounds,
                   options={"maxiter": 2000, "ftol": 1e-15, "gtol": 1e-9})
    if not polish:
        return res.x, -float(res.fun)
    out = minimize(neg, res.x, method="Nelder-Mead",
                   options={"maxfev": 4000, "xatol": 1e-10, "fatol": 1e-13, "adaptive": True})
    return (out.x, -out.fun) if -out.fun >= -res.fun else (res.x, -float(res.fun))


def _maximum(likelihood: JointLikelihood, seed: int,
             starts: np.ndarray | None = None) -> np.ndarray:
    """The highest-posterior point of ``likelihood``'s space, climbed (:func:`_climb`) from
    the :data:`STARTS` best of :data:`PRIOR_DRAWS` prior draws and of ``starts`` (a
    posterior's draws, where given)."""
    rng = np.random.default_rng(seed)
    draws = likelihood.space.draw(rng, PRIOR_DRAWS)
    if starts is not None:
        draws = np.vstack([draws, np.asarray(starts, dtype=float)])
    lp = likelihood.log_posterior(draws)
    best, best_val = None, -np.inf
    for x0 in draws[np.argsort(lp)[::-1][:STARTS]]:
        x, val = _climb(likelihood, x0)
        if val > best_val:
            best, best_val = x, val
    return _climb(likelihood, best, polish=True)[0]


def fit_with_inputs_free(likelihood: JointLikelihood, *, seed: int = 0,
                         starts: np.ndarray | None = None) -> dict[str, Any]:
    """The chi-square test of ``likelihood``'s model (built without the model form) at its
    highest-posterior point (module notes); ``starts``: a posterior's draws to climb from
    besides the prior's best.

    Returns
    -------
    dict
        ``chi2``, ``dof``, ``p``, ``misfit`` (p below :data:`~.misfit.MISFIT_P`),
        ``chi2_data`` and ``chi2_inputs`` (the two sums), ``inputs_sd`` (each normal
        input's distance from its prior's centre in its sds, signed), ``at`` (the point:
        log10 R, ln k ratios, nm, shared terms in sd), ``per_formulation`` (each one's
        term).
    """
    space = likelihood.space
    if any(n.startswith(("tau_", "slope_")) for n in space.names):
        raise ValueError("likelihood: build it without the model form (ModelFormPrior(on="
                         "False)); this test is of the model alone")
    theta = _maximum(likelihood, seed, starts)
    terms = likelihood.chi_square_terms(theta[None, :])[:, 0]
    inputs = {n: float((theta[i] - space.a[i]) / space.b[i])
              for i, n in enumerate(space.names) if space.kinds[i] == "normal"}
    flat = sum(1 for kind in space.kinds if kind == "uniform")
    dof = max(len(terms) - flat, 1)
    chi2_inputs = float(sum(z ** 2 for z in inputs.values()))
    chi2 = float(terms.sum()) + chi2_inputs
    p = chi_square_p(chi2, dof)
    return {"chi2": chi2, "dof": dof, "p": p, "misfit": p < MISFIT_P,
            "threshold_p": MISFIT_P, "chi2_data": float(terms.sum()),
            "chi2_inputs": chi2_inputs, "inputs_sd": inputs,
            "at": dict(zip(space.names, map(float, theta))),
            "per_formulation": dict(zip(likelihood.order, map(float, terms))),
            "what": "the highest-posterior point of the model without the model form, the "
                    "inputs free within their priors (their prior terms counted)"}


def describe(record: dict[str, Any]) -> str:
    """One line: the test, and where the inputs went (in their prior sds)."""
    moved = ", ".join(f"{n.replace('ln ', '')} {z:+.1f} sd"
                      for n, z in sorted(record["inputs_sd"].items(), key=lambda kv: -abs(kv[1]))
                      if abs(z) >= 1.0)
    return (f"with the inputs free (no model form): chi-square {record['chi2']:.1f} on "
            f"{record['dof']} dof (data {record['chi2_data']:.1f}, inputs "
            f"{record['chi2_inputs']:.1f}), p = {record['p']:.2g}"
            + (f"; inputs beyond 1 sd: {moved}" if moved else ""))
