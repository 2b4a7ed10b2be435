"""Validation of identified resistances: full-solver predictions and leave-one-out.

- :func:`validate`: every formulation solved with the full solver (the settings' choice) on each RVE
  replica in three directions at the identified values; the mean of the replicas x
  directions is the prediction, their spread its RVE scatter; next to the measured mean and
  the paper's Table 6.
- :func:`leave_one_out`: for each formulation, the calibration repeated without it and its
  conductivity predicted from that posterior (reduced basis, posterior median and 90 %
  predictive interval): a held-out error the paper does not give (its Table 6 predicts the
  samples it identified on).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

from itr_fv.materials import paper_data

from ..forward.model import ForwardModel
from .calibrate import Posterior, calibrate
from .measurements import Measurements
from .misfit import with_model_form

__all__ = ["validate", "leave_one_out", "posterior_prediction"]


def validate(models: Mapping[str, ForwardModel], values: Mapping[str, float],
             measurements: Measurements, *,
             tick: Callable[[], None] | None = None) -> list[dict]:
    """Full-solver predictions of every formulation at ``values`` (flat names, m^2 K/W).

    Returns one row per formulation: measured mean and standard error, predicted mean and
    standard deviation over replicas x directions at the model's fidelity level
    (``predicted``: the cheap replicas' full solves times the level's factor at ``values``,
    :meth:`~itr_identify.forward.model.ForwardModel.level_at`) and raw (``predicted_raw``:
    the cheap RVEs' own), W/(m K), the level and its factor, relative error (%), and the
    paper's Table 6 prediction and error where the formulation is one of the paper's.
    """
    table6 = paper_data.paper_validation()
    rows = []
    for name, model in models.items():
        own = {p: values[p] for p in model.parameters}
        raw = model.solve_replicas(own, tick=tick)      # the cheap replicas' full solves
        level = model.level_at(own)
        k = raw * level["factor"]                      # at the model's fidelity level
        pred = float(k.mean())
        meas = measurements.mean(name)
        row = {"formulation": name, "measured": meas,
               "measured_se": measurements.standard_error(name),
               "predicted": pred, "predicted_sd": float(k.std(ddof=1)),
               "replica_k_iso": k.mean(axis=1).tolist(),
               "predicted_raw": float(raw.mean()), "predicted_raw_sd": float(raw.std(ddof=1)),
               "replica_k_iso_raw": raw.mean(axis=1).tolist(),
               "level": level["source"], "level_factor": level["factor"],
               "error_pct": 100 * (pred / meas - 1)}
        if name in table6:
            row["paper_predicted"] = table6[name][1]
            row["paper_error_pct"] = 100 * (table6[name][1] / meas - 1)
        rows.append(row)
    return rows


def posterior_prediction(model: ForwardModel, posterior: Posterior, *,
                         standard_error: float = 0.0, level: float = 0.9,
                         seed: int = 0) -> tuple[float, float, float]:
    """(median, lo, hi) of the predicted measured mean over the posterior samples,
    W/(m K): the parameter spread, the model's RVE scatter and earlier-stage spread
    (relative), the shipped correction's own and shared uncertainty, its surrogate error
    bound and the measurement's ``standard_error``."""
    S = posterior.samples.shape[0]
    if model.parameters:
        cols = {p: 10 ** posterior.samples[:, posterior.names.index(p)]
                for p in model.parameters}
        k, err = model.predict(cols)
    else:
        k, err = np.full(S, model.predict({})[0][0]), np.zeros(S)
    rng = np.random.default_rng(seed)
    shared = (model.shared_sd(cols) if model.parameters
              and getattr(model, "shared_system", None) is not None else 0.0)
    rel = np.hypot(math.hypot(model.rve_scatter, model.model_sd, posterior.model_form_sd),
                   shared)
    k = (k * (1 + rel * rng.standard_normal(S)) + err * rng.uniform(-1, 1, S)
         + standard_error * rng.standard_normal(S))
    a = (1 - level) / 2
    lo, med, hi = np.quantile(k, [a, 0.5, 1 - a])
    return float(med), float(lo), float(hi)


def leave_one_out(models: Mapping[str, ForwardModel], measurements: Measurements, *,
                  tick: Callable[[], None] | None = None, **calibrate_kw) -> list[dict]:
    """Identify without each formulation in turn and predict it (the calibration of the
    others carries a model-form error where their fit fails its chi-square test:
    :func:`itr_identify.inference.misfit.with_model_form`).

    Returns per formulation: measured mean, held-out prediction of the measured mean
    (median, 90 % interval: :func:`posterior_prediction`),
    relative error (%), whether the measured mean lies inside the interval, and the
    fraction of posterior samples outside the held-out model's reduced-basis box.
    """
    rows = []
    for name, model in models.items():
        rest = {f: m for f, m in models.items() if f != name}
        held_out = measurements.without(name)
        post, _ = with_model_form(rest, held_out, calibrate(rest, held_out, **calibrate_kw),
                                  **calibrate_kw)
        missing = [p for p in model.parameters if p not in post.names]
        if missing:
            rows.append({"formulation": name, "skipped": f"without it nothing identifies "
                                                          f"{', '.join(missing)}"})
            if tick is not None:
                tick()
            continue
        meas = measurements.mean(name)
        med, lo, hi = posterior_prediction(
            model, post, standard_error=measurements.standard_error(name))
        cols = {p: 10 ** post.samples[:, post.names.index(p)] for p in model.parameters}
        rows.append({"formulation": name, "measured": meas, "predicted": med,
                     "interval_90": [lo, hi], "error_pct": 100 * (med / meas - 1),
                     "inside": bool(lo <= meas <= hi),
                     "outside_box_fraction": model.outside_fraction(cols)})
        if tick is not None:
            tick()
    return rows
