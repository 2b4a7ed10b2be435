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

The maximum is found by Nelder-Mead from the best of the prior's draws and the best few
draws of a posterior, where one is given (scipy.optimize, a well-kept optimiser; the log
posterior is the joint likelihood's own, cheap and vectorised).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import minimize

from .joint import JointLikelihood
from .model_form import MISFIT_P, chi_square_p

__all__ = ["STARTS", "describe", "fit_with_inputs_free"]

#: Starting points of the optimiser (the best prior draws by posterior).
STARTS = 4
#: Prior draws the starts are chosen from.
PRIOR_DRAWS = 20000


def _maximum(likelihood: JointLikelihood, seed: int) -> np.ndarray:
    """The highest-posterior point of ``likelihood``'s space (Nelder-Mead from the
    :data:`STARTS` best of :data:`PRIOR_DRAWS` prior draws)."""
    rng = np.random.default_rng(seed)
    draws = likelihood.space.draw(rng, PRIOR_DRAWS)
    lp = likelihood.log_posterior(draws)
    best, best_val = None, -np.inf

    def neg(t: np.ndarray) -> float:
        v = float(likelihood.log_posterior(t[None, :])[0])
        return -v if np.isfinite(v) else 1e300

    for x0 in draws[np.argsort(lp)[::-1][:STARTS]]:
        res = minimize(neg, x0, method="Nelder-Mead",
                       options={"maxiter": 40000, "maxfev": 40000, "xatol": 1e-10,
                                "fatol": 1e-13, "adaptive": True})
        if -res.fun > best_val:
            best, best_val = res.x, -res.fun
    return best


def fit_with_inputs_free(likelihood: JointLikelihood, *, seed: int = 0) -> dict[str, Any]:
    """The chi-square test of ``likelihood``'s model (built without the model form) at its
    highest-posterior point (module notes).

    Returns
    -------
    dict
        ``chi2``, ``dof``, ``p``, ``misfit`` (p below :data:`~.model_form.MISFIT_P`),
        ``chi2_data`` and ``chi2_inputs`` (the two sums), ``inputs_sd`` (each normal
        input's distance from its prior's centre in its sds, signed), ``at`` (the point:
        log10 R, ln k ratios, nm, shared terms in sd), ``per_formulation`` (each one's
        term).
    """
    space = likelihood.space
    if any(n.startswith(("tau_", "slope_")) for n in space.names):
        raise ValueError("likelihood: build it without the model form (ModelFormPrior(on="
                         "False)); this test is of the model alone")
    theta = _maximum(likelihood, seed)
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
