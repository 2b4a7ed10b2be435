"""A model whose fit fails its chi-square test carries a model-form error in its intervals.

At the best values the fit's chi-square (:func:`itr_identify.inference.calibrate.residuals`:
measured minus model over every formulation, each over its likelihood variance) is set
against a chi-square distribution of ``n - P`` degrees of freedom (n formulations, P
parameters). Where its upper-tail probability is below :data:`MISFIT_P`, the model misses
the data by more than every stated error allows: the residuals hold an error of the model's
form that no parameter value removes. Its size is estimated as one relative error ``tau``
common to every formulation, the one that brings the chi-square down to its degrees of
freedom,

    sum_i r_i^2 / (v_i + (tau k_i)^2) = n - P,

(solved at the best values, then again at the best values of the calibration that carries
it, until ``tau`` moves by less than 1 %), and the calibration is repeated with ``tau`` in
every likelihood variance (:func:`itr_identify.inference.calibrate.variance`). The intervals
then hold the misfit as an uncertainty; the values keep the flag ``model misfit``
(:mod:`itr_identify.reporting.headline`), never ``determined``: a wider interval does not
make a failing model right. ``tau`` is a point estimate (it has n - P degrees of freedom
behind it), and the record keeps the interval without it beside the one with it.
"""

from __future__ import annotations

from collections.abc import Mapping

from scipy import special

from ..forward.model import ForwardModel
from .calibrate import Posterior, calibrate, residuals
from .measurements import Measurements

__all__ = ["MISFIT_P", "chi_square_p", "model_form_sd", "fit_record", "with_model_form",
           "misfit_note", "is_misfit"]

#: A fit whose chi-square has an upper-tail probability below this fails its test.
MISFIT_P = 0.01
#: The largest relative model-form error searched for.
MAX_SD = 0.5


def chi_square_p(chi2: float, dof: int) -> float:
    """Upper-tail probability of ``chi2`` under a chi-square of ``dof`` degrees of freedom."""
    if dof < 1:
        raise ValueError(f"dof: expected at least 1 degree of freedom, got {dof!r}")
    return float(special.gammaincc(0.5 * dof, 0.5 * max(chi2, 0.0)))


def model_form_sd(terms: Mapping[str, tuple[float, float, float]], dof: int) -> float:
    """The relative error ``tau`` that brings the chi-square of ``terms`` (per formulation:
    measured mean, model k_iso, variance) down to ``dof``; 0 where it is already at most
    ``dof``. Bisection on ``tau`` in [0, :data:`MAX_SD`] (the chi-square falls with it)."""
    def chi2(tau: float) -> float:
        return sum((m - k) ** 2 / (v + (tau * k) ** 2) for m, k, v in terms.values())

    if chi2(0.0) <= dof:
        return 0.0
    lo, hi = 0.0, MAX_SD
    if chi2(hi) > dof:
        return MAX_SD
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2(mid) > dof else (lo, mid)
    return hi


def fit_record(models: Mapping[str, ForwardModel], measurements: Measurements,
               post: Posterior) -> dict:
    """The chi-square test of ``post``'s best values without a model-form term:
    ``chi2``, ``dof``, ``p`` and ``misfit`` (p below :data:`MISFIT_P`)."""
    terms = residuals(models, measurements, post.best)
    dof = max(len(terms) - len(post.names), 1)
    chi2 = float(sum((m - k) ** 2 / v for m, k, v in terms.values()))
    p = chi_square_p(chi2, dof)
    return {"chi2": chi2, "dof": dof, "p": p, "misfit": p < MISFIT_P, "threshold_p": MISFIT_P,
            "log_likelihood_best": post.log_likelihood_best()}


def with_model_form(models: Mapping[str, ForwardModel], measurements: Measurements,
                    post: Posterior, **calibrate_kw) -> tuple[Posterior, dict]:
    """``post`` (a calibration without a model-form term) and its :func:`fit_record`; where
    the fit fails its test, the calibration carrying the model-form error instead, and the
    record gains ``model_form_sd``, ``intervals_without`` (the 90 % intervals of ``post``,
    m^2 K/W) and ``chi2_with`` (the chi-square with the term at the new best values)."""
    record = fit_record(models, measurements, post)
    record["model_form_sd"] = 0.0
    if not record["misfit"]:
        return post, record
    dof = record["dof"]
    tau, new = 0.0, post
    for _ in range(5):
        t = model_form_sd(residuals(models, measurements, new.best), dof)
        if tau > 0 and abs(t / tau - 1) < 0.01:
            break
        tau = t
        new = calibrate(models, measurements, model_form_sd=tau, **calibrate_kw)
    with_tau = residuals(models, measurements, new.best, tau)
    record.update(model_form_sd=tau,
                  chi2_with=float(sum((m - k) ** 2 / v for m, k, v in with_tau.values())),
                  intervals_without={n: list(post.interval(n)) for n in post.names})
    return new, record


def misfit_note(record: Mapping) -> str:
    """One line on the test: passed, or failed and the model-form error the intervals carry."""
    test = (f"chi-square {record['chi2']:.1f} on {record['dof']} dof, p = "
            f"{record['p']:.2g}")
    mf = record.get("model_form")
    if isinstance(mf, Mapping):   # the joint posterior's structured model form
        free, st = record["free_inputs"], record["stated"]
        test = (f"chi-square {record['chi2']:.1f} on {record['dof']} dof with the inputs free "
                f"within their priors and no model form (data {free['chi2_data']:.1f}, "
                f"inputs {free['chi2_inputs']:.1f}), p = {record['p']:.2g}")
        stated = (f"; at the points quoted with the stated inputs chi-square "
                  f"{st['chi2']:.1f} on {st['dof']} dof"
                  + (f", {st['chi2_with']:.1f} with the model form's prior variance"
                     if mf.get("on") else ""))
        carried = (f"; the intervals carry the structured model-form term (per filler "
                   f"system an offset, sd {100 * mf['offset_sd']:g} %, and a slope, sd "
                   f"{100 * mf['slope_sd_per_5_vol_pct']:g} % per 5 vol%)"
                   if mf.get("on") else "")
        if not record.get("misfit"):
            return f"the fit passes its chi-square test ({test}){stated}{carried}"
        return (f"the fit fails its chi-square test ({test} < {record['threshold_p']:g}): "
                f"the model misses the data by more than every stated error{stated}"
                f"{carried}; flag 'model misfit'")
    if not record.get("misfit"):
        return f"the fit passes its chi-square test ({test})"
    return (f"the fit fails its chi-square test ({test} < {record['threshold_p']:g}): the "
            f"intervals carry a model-form error of {100 * record['model_form_sd']:.1f} % "
            "of k at every formulation; flag 'model misfit'")


def is_misfit(record: Mapping | None) -> bool:
    """Whether a fit record says the model failed its test."""
    return bool(record and record.get("misfit"))

