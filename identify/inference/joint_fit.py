"""The identification's joint posterior from its forward models (issue 59): run it, hand it
on as the package's :class:`~.calibrate.Posterior`, and read from its samples what each
input contributes and what measuring one would leave.

- :func:`run_joint`: tabulate the models (:class:`~.joint.Tabulated`), build the space of
  the resistances, the uncertain inputs, the shared correction terms and the model form
  (:class:`~.joint.JointSpace`), sample it (:func:`~.joint.sample`).
- :func:`as_posterior`: the resistances' draws as a :class:`~.calibrate.Posterior` whose
  best values are the points quoted (the posterior medians of ln R), whose intervals are
  the weighted draws' equal-tailed ones, and whose ``samples`` are draws by weight.
- :func:`inputs_record`: per resistance its interval at the nominal inputs (the grid
  calibration's), the joint one, each input's share of the variance of its log10 value (a
  linear regression of the samples: the inputs', the model form's and corrections', and the
  rest, the measurements'), and per input the value of its information: the 90 % interval
  expected if it were measured with :data:`MEASUREMENT_SD`, averaged over what that
  measurement could give (its predictive distribution, by reweighting the samples).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..forward.model import ForwardModel
from .calibrate import Posterior, pooled_scatter
from .joint import (
    CHAIN_TAUS,
    MAX_STEPS,
    PROPOSAL_TAUS,
    TARGET_DRAWS,
    JointLikelihood,
    JointPosterior,
    JointSpace,
    Tabulated,
    sample,
)
from .effect_terms import JointEffect
from .marginal import DRAWS as MARGINAL_DRAWS
from .measurements import Measurements
from .nuisance import FilmPrior, InputPrior
from .priors import DEFAULT_MODEL_FORM, DEFAULT_RESISTANCE, ModelFormPrior, ResistancePrior

__all__ = ["likelihood_of", "run_joint", "as_posterior", "inputs_record", "value_of_information",
           "MEASUREMENT_SD", "POSTERIOR_DRAWS"]

#: What a measurement of an input would give, its standard deviation: a conductivity to 2 %
#: (a steady-state or laser-flash measurement of the neat matrix or a sintered filler), a
#: film to 0.5 nm (ellipsometry or TEM of a coated surface).
MEASUREMENT_SD = {"k": 0.02, "film_nm": 0.5}
#: Draws of the posterior handed on as a Posterior (evenly thinned).
POSTERIOR_DRAWS = 4000
#: Hypothetical measurements averaged over by the value of information.
VOI_DRAWS = 200


def likelihood_of(models: Mapping[str, ForwardModel], measurements: Measurements,
                  inputs: Mapping[str, InputPrior | FilmPrior],
                  elasticity: Mapping[str, Mapping[str, float]], *,
                  resistance: ResistancePrior = DEFAULT_RESISTANCE,
                  model_form: ModelFormPrior = DEFAULT_MODEL_FORM,
                  hold: Mapping[str, float] | None = None,
                  effect: JointEffect | None = None) -> JointLikelihood:
    """The joint likelihood of ``models`` given ``measurements`` over the space of the
    priors (module notes); ``elasticity``: :func:`~.nuisance.elasticities` of the models;
    ``hold``: parameters held at a value; ``effect``: a candidate effect's terms
    (:mod:`.effect_terms`). A density column is read where the material system states the
    phase densities."""
    system = next(iter(models.values())).settings.system
    k0 = system.conductivities()
    for pr in inputs.values():
        if isinstance(pr, InputPrior) and not math.isclose(pr.nominal, float(k0[pr.phase]),
                                                           rel_tol=1e-12):
            raise ValueError(f"{pr.name}: the forward models were built at "
                             f"{float(k0[pr.phase]):g} W/(m K); a prior centred elsewhere "
                             f"({pr.nominal:g}) needs models built there")
    tables = {f: Tabulated.of(f, m, elasticity.get(f, {})) for f, m in models.items()}
    space = JointSpace.build(tables, matrix=system.matrix, resistance=resistance,
                             inputs=inputs, model_form=model_form, hold=hold, effect=effect)
    groups: dict[str, list[ForwardModel]] = {}
    for f, t in tables.items():
        groups.setdefault(t.group, []).append(models[f])
    return JointLikelihood(tables, measurements, space,
                           scatter={g: pooled_scatter(ms) for g, ms in groups.items()},
                           densities=_densities(system),
                           matrix_conductivity=float(k0[system.matrix]))


def _densities(system) -> dict[str, float] | None:
    """The system's phase densities, g/cm^3, where it states every one (else None)."""
    try:
        return dict(system.densities())
    except ValueError:
        return None


def run_joint(models: Mapping[str, ForwardModel], measurements: Measurements,
              inputs: Mapping[str, InputPrior | FilmPrior],
              elasticity: Mapping[str, Mapping[str, float]], *,
              resistance: ResistancePrior = DEFAULT_RESISTANCE,
              model_form: ModelFormPrior = DEFAULT_MODEL_FORM,
              hold: Mapping[str, float] | None = None, seed: int = 0,
              steps: int | None = None, progress: bool = False, marginals: bool = True,
              marginal_draws: int = MARGINAL_DRAWS) -> tuple[JointPosterior, JointLikelihood]:
    """Sample the joint posterior of ``models`` given ``measurements`` (:func:`likelihood_of`);
    ``steps``: a fixed chain length (default: until converged); ``marginals``: attach the
    resistances' Rao-Blackwell marginals over ``marginal_draws`` draws
    (:func:`~.joint.sample`)."""
    lik = likelihood_of(models, measurements, inputs, elasticity, resistance=resistance,
                        model_form=model_form, hold=hold)
    return sample(lik, seed=seed, steps=steps, burn=steps, progress=progress,
                  marginals=marginals, marginal_draws=marginal_draws), lik


def as_posterior(joint: JointPosterior, *, resistance: ResistancePrior,
                 stages=(), draws: int = POSTERIOR_DRAWS) -> Posterior:
    """The resistances of ``joint`` as a :class:`~.calibrate.Posterior`: its weighted
    log10 draws (the intervals), ``draws`` of them by weight (``samples``), best values the
    points quoted (medians of ln R), the resistance prior's range, the evidence;
    ``stages``: the grid calibration's (its densities for the figures)."""
    names = joint.resistances
    full = np.column_stack([joint.column(f"log10 {n}") for n in names])
    rows = joint.resample(draws, seed=joint.seed)
    return Posterior(list(names), full[rows], {n: joint.point(n) for n in names},
                     (resistance.low, resistance.high), stages=list(stages),
                     log_evidence=joint.log_evidence, weighted=(full, joint.weights),
                     marginals={n: joint.marginals[f"log10 {n}"] for n in names
                                if f"log10 {n}" in joint.marginals} or None)


#: Equal-weight draws (by weight) that the records below read.
RECORD_DRAWS = 20000


def _rows(joint: JointPosterior) -> np.ndarray:
    return joint.counted_rows(RECORD_DRAWS, seed=joint.seed + 1)


def _input_columns(joint: JointPosterior, rows: np.ndarray) -> dict[str, np.ndarray]:
    """The sampled inputs' columns (ln k over nominal, the film in nm) at ``rows``."""
    return {n.split(" ", 1)[1] if n.startswith("ln ") else n: joint.column(n)[rows]
            for n in joint.names if n.startswith("ln ") or n == "film_nm"}


def _shares(joint: JointPosterior, resistance: str) -> dict[str, float]:
    """Each input's share of the variance of log10 ``resistance`` (a least-squares
    regression on the sampled columns, each input's part ``beta^2 var``), the model form's
    and shared corrections' together, and the rest (``measurements``), summing to 1."""
    rows = _rows(joint)
    y = joint.column(f"log10 {resistance}")[rows]
    total = float(np.var(y))
    inputs = _input_columns(joint, rows)
    other = [n for n in joint.names if n.startswith(("offset_", "slope_", "tau_"))]
    cols = list(inputs.values()) + [joint.column(n)[rows] for n in other]
    if total <= 0 or not cols:
        return {"measurements": 1.0}
    X = np.column_stack([np.ones_like(y)] + cols)
    beta, *_ = np.linalg.lstsq(X, y - y.mean(), rcond=None)
    fitted = X[:, 1:] * beta[1:]
    out = {name: float(np.var(fitted[:, i])) / total for i, name in enumerate(inputs)}
    out["model form and corrections"] = float(np.var(fitted[:, len(inputs):].sum(axis=1))) \
        / total if other else 0.0
    explained = sum(out.values())
    resid = 1.0 - float(np.var(y - y.mean() - fitted.sum(axis=1))) / total
    if explained > 0:   # the regression's explained part, shared in proportion
        out = {k: v * max(resid, 0.0) / explained for k, v in out.items()}
    out["measurements"] = 1.0 - sum(out.values())
    return out


def _weighted_interval(x: np.ndarray, w: np.ndarray, level: float = 0.9
                       ) -> tuple[float, float]:
    order = np.argsort(x)
    c = np.cumsum(w[order])
    c /= c[-1]
    a = (1 - level) / 2
    return float(np.interp(a, c, x[order])), float(np.interp(1 - a, c, x[order]))


def value_of_information(joint: JointPosterior, input_name: str, resistance: str, *,
                         seed: int = 0, draws: int = VOI_DRAWS) -> dict[str, float]:
    """The 90 % interval of ``resistance`` expected if ``input_name`` (``k_<phase>`` or
    ``film_nm``) were measured with :data:`MEASUREMENT_SD`: over ``draws`` values that
    measurement could give (a posterior draw of the input plus the measurement's error),
    the samples reweighted by each value's likelihood; the geometric means of the ends and
    the expected half-width factor ``F`` (m^2 K/W)."""
    rows = _rows(joint)
    x = _input_columns(joint, rows)[input_name]
    sd = MEASUREMENT_SD["film_nm" if input_name == "film_nm" else "k"]
    y = joint.column(f"log10 {resistance}")[rows]
    rng = np.random.default_rng(seed)
    measured = x[rng.integers(0, x.size, draws)] + sd * rng.standard_normal(draws)
    los, his = [], []
    for m in measured:
        w = np.exp(-0.5 * ((x - m) / sd) ** 2)
        lo, hi = _weighted_interval(y, w)
        los.append(lo)
        his.append(hi)
    lo, hi = float(np.mean(los)), float(np.mean(his))
    return {"interval": [10 ** lo, 10 ** hi],
            "factor": float(np.mean([10 ** ((b - a) / 2) for a, b in zip(los, his)])),
            "measurement_sd": sd}


def inputs_record(joint: JointPosterior, nominal: Posterior,
                  inputs: Mapping[str, InputPrior | FilmPrior], *, seed: int = 0) -> dict:
    """What the inputs do to each resistance (module notes), as the report reads it."""
    sampled = _input_columns(joint, _rows(joint)[:1])
    record = {"inputs": {pr.name: ({"low_nm": pr.low_nm, "high_nm": pr.high_nm}
                                   if isinstance(pr, FilmPrior) else
                                   {"nominal": pr.nominal, "rel_sd": pr.rel_sd})
                         for pr in inputs.values() if pr.name in sampled},
              "measurement_sd": dict(MEASUREMENT_SD), "parameters": {}}
    for r in joint.resistances:
        if_known = {n: value_of_information(joint, n, r, seed=seed) for n in sampled}
        record["parameters"][r] = {
            "interval_nominal": list(nominal.interval(r)) if r in nominal.names else None,
            "interval_marginal": list(joint.interval(r)), "shares": _shares(joint, r),
            "if_known": {n: v["interval"] for n, v in if_known.items()},
            "if_measured": if_known}
    return record


def joint_fit_record(models: Mapping[str, ForwardModel], measurements: Measurements,
                     post: Posterior, joint: JointPosterior,
                     model_form: ModelFormPrior, free: Mapping[str, Any]) -> dict:
    """The fit's test and its record. The test (``chi2``, ``dof``, ``p``, ``misfit`` below
    :data:`~.misfit.MISFIT_P`) is ``free``'s: the model without the model form at its
    highest-posterior point, the inputs free within their priors
    (:func:`~.free_inputs_fit.fit_with_inputs_free`). Beside it, ``stated``: the chi-square
    at the points quoted with the stated inputs, without the model form and with its prior
    variance (``chi2_with``: each formulation's variance plus ``(tau_offset^2 + (tau_slope
    z)^2) k^2``); and the model form's posterior offsets and slopes per filler system
    (medians, relative)."""
    from .calibrate import residuals
    from .misfit import MISFIT_P, chi_square_p

    terms = residuals(models, measurements, post.best)
    dof = max(len(terms) - len(post.names), 1)
    chi2 = float(sum((m - k) ** 2 / v for m, k, v in terms.values()))
    with_mf = 0.0
    for f, (m, k, v) in terms.items():
        z = (sum(models[f].fractions.values()) - float(np.mean(
            [sum(models[g].fractions.values()) for g in models
             if sorted(models[g].fractions) == sorted(models[f].fractions)]))) / 0.05
        extra = (model_form.offset_scale ** 2 + (model_form.slope_scale * z) ** 2
                 if model_form.on else 0.0)
        with_mf += (m - k) ** 2 / (v + extra * k ** 2)
    structure = {n: float(joint.quantile(n, 0.5)) for n in joint.names
                 if n.startswith(("offset_", "slope_"))}
    stated = {"chi2": chi2, "dof": dof, "p": chi_square_p(chi2, dof),
              "chi2_with": float(with_mf), "p_with": chi_square_p(with_mf, dof),
              "at": "the points quoted, the stated inputs"}
    return {"chi2": free["chi2"], "dof": free["dof"], "p": free["p"],
            "misfit": free["p"] < MISFIT_P, "threshold_p": MISFIT_P,
            "free_inputs": dict(free), "stated": stated, "model_form": {
                "on": model_form.on, "offset_sd": model_form.offset_scale,
                "slope_sd_per_5_vol_pct": model_form.slope_scale,
                "posterior_medians": structure},
            "model_form_sd": 0.0, "at": free["what"]}


def joint_note(joint: JointPosterior) -> str:
    """One line on the sampler: draws, autocorrelation, convergence."""
    tau = max(joint.autocorr.values())
    return (f"emcee: {joint.walkers} walkers x {joint.steps} steps after {joint.burn} of "
            f"burn-in, longest autocorrelation {tau:.0f} steps, acceptance "
            f"{joint.acceptance:.2f}; the posterior's draws "
            + ("importance-weighted from two t fitted to the chain, worth "
               if joint.source == "importance" else "the chain's, worth ")
            + f"{joint.effective_draws:.0f} independent draws"
            + ("" if joint.converged else
               f"; NOT converged at {MAX_STEPS} steps (the rule: importance draws worth "
               f"{TARGET_DRAWS} from a chain spanning {PROPOSAL_TAUS} autocorrelation "
               f"times, else every chain spans {CHAIN_TAUS} autocorrelation times and is "
               f"worth {TARGET_DRAWS} draws)"))


#: Posterior draws over which a validation row's predictive interval is taken.
PREDICTIVE_DRAWS = 20000


def mark_predictive(rows: list[dict], ident) -> None:
    """Add to each validation row (:func:`~.validate.validate`: full solves at the points
    quoted, the stated inputs) the posterior predictive 90 % interval of the measured mean
    (``predictive_90``) and whether the mean lies in it (``inside``).

    The full solves anchor it: per posterior draw, the full solves' k times the tables'
    k at the draw over the tables' k at the point with the stated inputs (no model-form
    shift), so the draw's inputs, model form and resistances move the anchored value as
    the likelihood moves them; then the measurement's standard error, one RVE's scatter over
    the replicas solved, the level's own sd and the pooled packing sd, drawn. Where the
    tables disagree with the full solves at the point, the anchor carries the difference."""
    jp, lik = ident.joint, ident.likelihood()
    rng = np.random.default_rng(jp.seed + 2)
    # counted by weight (a count a rounding change of the weights leaves as it is; a
    # systematic resampling of importance draws moves a draw across its cut: a device run
    # then differed from the CPU run's by 2e-5 in one interval end)
    theta = jp.samples[jp.counted_rows(PREDICTIVE_DRAWS, seed=jp.seed + 2)]
    k_all, _ = lik.conductivities_all(lik.space.columns(theta))
    at = np.zeros((1, lik.space.dim))
    for r in jp.resistances:
        at[0, lik.space.names.index(f"log10 {r}")] = math.log10(ident.posterior.best[r])
    k_at, _ = lik.conductivities_all(lik.space.columns(at))
    for row in rows:
        f = row["formulation"]
        i, tab = lik.order.index(f), lik.tables[f]
        pack = tab.packing[0] if tab.packing else 0.0
        rel = math.sqrt(tab.rve_scatter ** 2 / max(len(row["replica_k_iso"]), 1)
                        + tab.model_sd ** 2 + pack ** 2)
        k = row["predicted"] * k_all[i] / k_at[i, 0]
        y = k * (1 + rel * rng.standard_normal(k.size)) \
            + row["measured_se"] * rng.standard_normal(k.size)
        lo, hi = np.quantile(y, [0.05, 0.95])
        row["predictive_90"] = [float(lo), float(hi)]
        row["inside"] = bool(lo <= row["measured"] <= hi)


def leave_one_out_joint(joint: JointPosterior, likelihood: JointLikelihood, *,
                        seed: int = 0) -> list[dict]:
    """Each formulation predicted from the others' posterior: the joint posterior's draws
    reweighted by the inverse of the formulation's own likelihood term (truncated importance
    sampling, weights capped at ``sqrt(S)`` times their mean, Ionides 2008), its k over
    those draws with the measurement's standard error, one RVE's scatter and its level's
    own sd: the 90 % predictive interval, whether the measured mean lies in it, and the
    effective sample size of the weights (a few per cent of the draws or less: the
    formulation dominates its own posterior, the prediction is rough). Run on a posterior
    without the model-form term, it is the test of the model alone."""
    rng = np.random.default_rng(seed)
    theta = joint.samples[_rows(joint)]
    terms = likelihood.per_formulation(theta)
    cols = likelihood.space.columns(theta)
    rows = []
    for f, ll in terms.items():
        logw = -ll - np.max(-ll)
        w = np.exp(logw)
        w = np.minimum(w, w.mean() * math.sqrt(w.size))
        w /= w.sum()
        k, err = likelihood.conductivities(cols, f)
        mean, se, _ = likelihood.data[f]
        tab = likelihood.tables[f]
        sd = np.sqrt(se ** 2 + (tab.rve_scatter ** 2 + tab.model_sd ** 2) * k ** 2)
        draws = k + sd * rng.standard_normal(k.size)
        lo, hi = _weighted_interval(draws, w)
        med = _weighted_interval(draws, w, level=0.0)[0]
        rows.append({"formulation": f, "measured": mean, "predicted": med,
                     "interval_90": [lo, hi], "error_pct": 100 * (med / mean - 1),
                     "inside": bool(lo <= mean <= hi),
                     "effective_draws": float(1 / np.sum(w ** 2))})
    return rows


def alone_agreement(alone: list[dict]) -> dict[str, dict]:
    """Per resistance: do the formulations fitted alone (at the nominal inputs) agree? Each
    alone fit's log10 value (its best) and sd (its 90 % interval's half-width in log10 over
    1.645); the weighted mean and the chi-square of the values about it on ``n - 1``
    degrees of freedom, its p-value (``agree``: p >= 0.01). Values at an end of the prior
    count with their one-sided interval's width."""
    from .misfit import MISFIT_P, chi_square_p

    by: dict[str, list[dict]] = {}
    for row in alone:
        by.setdefault(row["parameter"], []).append(row)
    out = {}
    for p, rows in by.items():
        if len(rows) < 2:
            continue
        x = np.array([math.log10(r["best"]) for r in rows])
        s = np.array([max(math.log10(r["interval_90"][1] / r["interval_90"][0]) / 2 / 1.645,
                          1e-6) for r in rows])
        w = 1 / s ** 2
        mean = float(np.sum(w * x) / np.sum(w))
        chi2 = float(np.sum(w * (x - mean) ** 2))
        pval = chi_square_p(chi2, len(rows) - 1)
        out[p] = {"formulations": [r["formulation"] for r in rows], "weighted_mean":
                  10 ** mean, "chi2": chi2, "dof": len(rows) - 1, "p": pval,
                  "agree": pval >= MISFIT_P}
    return out


#: Steps (after as many of burn-in) of the run with the resistance prior's floor a decade
#: lower: the floor's sensitivity is a comparison, not the headline.
FLOOR_STEPS = 3000
#: Draws of that run's Rao-Blackwell marginals: its chain is worth about 2,000 independent
#: draws on Table 3 (224 walkers x 3,000 steps over an autocorrelation of 340), which bound
#: its quantiles' error more than a quarter of the headline's marginal draws do.
FLOOR_MARGINAL_DRAWS = 5000


def floor_sensitivity(joint: JointPosterior, models: Mapping[str, ForwardModel],
                      measurements: Measurements,
                      inputs: Mapping[str, InputPrior | FilmPrior],
                      elasticity: Mapping[str, Mapping[str, float]], *,
                      resistance: ResistancePrior, model_form: ModelFormPrior,
                      seed: int = 0) -> dict[str, dict]:
    """How each resistance's point and 90 % interval move when the resistance prior's floor
    moves a decade: up (the draws with every resistance above the raised floor: the same
    posterior under the truncated prior) and down (a run of :data:`FLOOR_STEPS` steps; below
    the reduced bases' box the tables hold k at its edge, where the likelihood is flat)."""
    out: dict[str, dict] = {}
    names = joint.resistances
    up = resistance.low * 10
    keep = np.all([joint.column(f"log10 {n}") >= math.log10(up) for n in names], axis=0)
    if joint.weights[keep].sum() * joint.effective_draws >= 100:
        out[f"floor {up:g}"] = {n: _summary(joint.column(f"log10 {n}")[keep],
                                            joint.weights[keep]) for n in names}
    low = resistance.with_floor(resistance.low / 10)
    jp, _ = run_joint(models, measurements, inputs, elasticity, resistance=low,
                      model_form=model_form, seed=seed, steps=FLOOR_STEPS,
                      marginal_draws=FLOOR_MARGINAL_DRAWS)
    out[f"floor {low.low:g}"] = {n: _quoted(jp, n) for n in names}
    out[f"floor {resistance.low:g} (the prior)"] = {n: _quoted(joint, n) for n in names}
    return out


def _quoted(joint: JointPosterior, name: str) -> dict[str, Any]:
    """A resistance's point and 90 % interval as the posterior quotes them."""
    return {"point": joint.point(name), "interval_90": list(joint.interval(name))}


def _summary(x: np.ndarray, w: np.ndarray) -> dict[str, Any]:
    from .joint import weighted_quantile

    lo, med, hi = weighted_quantile(x, [0.05, 0.5, 0.95], w)
    return {"point": float(10 ** med), "interval_90": [float(10 ** lo), float(10 ** hi)]}
