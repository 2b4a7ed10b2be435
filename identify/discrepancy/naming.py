"""Naming the missing effect on the identification's own joint model (issue 60).

The base model and every candidate are the same joint model (:mod:`itr_identify.inference.
joint`: the same reduced bases and shipped corrections, likelihood, resistance prior and
uncertain inputs), without the model-form term (an effect is to explain what the model form
would absorb), a candidate with its effect's terms added (:mod:`itr_identify.inference.
effect_terms`). Each is sampled by the same sampler; its evidence is the sampler's
importance-sampling estimate, its fit the chi-square at its highest-posterior point with
the inputs' prior prices counted (:func:`~itr_identify.inference.free_inputs_fit.
fit_with_inputs_free`).

The rule (:func:`decide`, its words in :mod:`itr_identify.reporting.naming_words`):

1. candidates over the threshold: a log Bayes factor over the base of at least
   :attr:`NamingSettings.threshold` (3: a Bayes factor of 20, "strong" on Kass and
   Raftery's scale), fixed before any table was read;
2. those within :attr:`NamingSettings.tie_margin` of the best are tied with it: a tie of
   two or more is reported as a tie, with the measurement that separates them and the
   resistances each would leave, where at least one of them fits (p of its chi-square at
   least :attr:`NamingSettings.fit_p`); where none fits, the tie reduces the gap without
   closing it and the verdict is *unexplained* (the tie kept in :attr:`NamingVerdict.tied`);
3. one alone over the threshold is *named* where its own fit passes (p of its chi-square at
   least :attr:`NamingSettings.fit_p`), else the discrepancy is *unexplained* (the best
   candidate reduces, does not remove, it);
4. none over the threshold: *none* where the base model's fit passes, *unexplained* where
   it fails.

The verdict is frozen (:class:`NamingVerdict`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..inference.effect_terms import JointEffect
from ..inference.free_inputs_fit import fit_with_inputs_free
from ..inference.joint import JointLikelihood, sample, weighted_quantile

__all__ = [
    "VERDICTS",
    "ModelFit",
    "NamingSettings",
    "NamingVerdict",
    "decide",
    "fit_and_posterior",
    "fit_model",
    "name_effect",
]

#: A posterior's best draws the fit climbs from (besides the prior's).
STARTS = 50
#: The verdicts the rule returns.
VERDICTS = ("none", "named", "tie", "unexplained")


@dataclass(frozen=True)
class NamingSettings:
    """The rule's settings and the sampler's effort per model.

    Attributes
    ----------
    threshold : float
        Log Bayes factor over the base model a candidate needs (3: a factor of 20).
    tie_margin : float
        Log Bayes factor within which a candidate ties with the best.
    fit_p : float
        The p-value of a model's chi-square under which its fit fails.
    steps, burn : int
        Sampler steps kept and burnt per model (a fixed chain: every model the same).
    evidence_draws : int
        Importance draws of each evidence.
    seed : int
    """

    threshold: float = 3.0
    tie_margin: float = 1.0
    fit_p: float = 0.01
    steps: int = 1500
    burn: int = 500
    evidence_draws: int = 200_000
    seed: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.threshold) and self.threshold > 0):
            raise ValueError(f"threshold: expected a log Bayes factor > 0, got "
                             f"{self.threshold!r}")
        if not (math.isfinite(self.tie_margin) and 0 <= self.tie_margin < self.threshold):
            raise ValueError(f"tie_margin: expected 0 <= margin < threshold, got "
                             f"{self.tie_margin!r}")
        if not 0 < self.fit_p < 1:
            raise ValueError(f"fit_p: expected a p-value in (0, 1), got {self.fit_p!r}")
        for name in ("steps", "burn", "evidence_draws"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= (1000 if name == "evidence_draws" else 100)):
                raise ValueError(f"{name}: expected a whole number >= "
                                 f"{1000 if name == 'evidence_draws' else 100}, got {v!r}")


@dataclass(frozen=True)
class ModelFit:
    """One model (the base, or the base with one effect) fitted to a table.

    Attributes
    ----------
    key, name : str
        ``"base"`` for the base model.
    log_evidence, log_evidence_se : float
    chi_square, dof, p : float, int, float
        Its fit at its highest-posterior point (the inputs' prior prices counted).
    per_formulation : dict
        Each formulation's chi-square term there.
    resistances : dict
        Per resistance (flat name) its posterior median and 90 % interval, m^2 K/W.
    parameter : str or None
        The effect's parameter (None for the base).
    value : (float, float, float) or None
        Its median and 90 % interval.
    nominal : float or None
        Its value where the effect is absent.
    """

    key: str
    name: str
    log_evidence: float
    log_evidence_se: float
    chi_square: float
    dof: int
    p: float
    per_formulation: dict[str, float]
    resistances: dict[str, tuple[float, float, float]]
    parameter: str | None = None
    value: tuple[float, float, float] | None = None
    nominal: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "name": self.name, "log_evidence": self.log_evidence,
                "log_evidence_se": self.log_evidence_se, "chi_square": self.chi_square,
                "dof": self.dof, "p": self.p, "per_formulation": dict(self.per_formulation),
                "resistances": {k: list(v) for k, v in self.resistances.items()},
                "parameter": self.parameter,
                "value": list(self.value) if self.value else None, "nominal": self.nominal}


@dataclass(frozen=True)
class NamingVerdict:
    """What the rule says of one table (frozen).

    Attributes
    ----------
    verdict : str
        One of :data:`VERDICTS`.
    base : ModelFit
    candidates : tuple of ModelFit
        In the order they were fitted.
    named : str or None
        The named effect's key.
    tied : tuple of str
        The keys tied at the top (two or more; empty without a tie), under a verdict
        ``"tie"`` or, where none of them fits, ``"unexplained"``.
    over_threshold : tuple of str
        Every candidate over the threshold, best first.
    settings : NamingSettings
    separate_by : dict
        Per candidate over the threshold the measurement that tells it apart.
    """

    verdict: str
    base: ModelFit
    candidates: tuple[ModelFit, ...]
    named: str | None
    tied: tuple[str, ...]
    over_threshold: tuple[str, ...]
    settings: NamingSettings
    separate_by: dict[str, str] = field(default_factory=dict)

    def log_bayes_factor(self, key: str) -> float:
        """ln Z of candidate ``key`` over the base's."""
        return self.candidate(key).log_evidence - self.base.log_evidence

    def candidate(self, key: str) -> ModelFit:
        for c in self.candidates:
            if c.key == key:
                return c
        raise ValueError(f"key: no candidate {key!r} (have "
                         f"{', '.join(c.key for c in self.candidates)})")

    @property
    def winner(self) -> ModelFit | None:
        """The named candidate, else the best over the threshold, else None."""
        key = self.named or (self.over_threshold[0] if self.over_threshold else None)
        return self.candidate(key) if key else None

    def to_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "named": self.named, "tied": list(self.tied),
                "over_threshold": list(self.over_threshold),
                "threshold": self.settings.threshold, "tie_margin": self.settings.tie_margin,
                "fit_p": self.settings.fit_p, "base": self.base.to_dict(),
                "candidates": [c.to_dict() for c in self.candidates],
                "log_bayes_factors": {c.key: self.log_bayes_factor(c.key)
                                      for c in self.candidates},
                "separate_by": dict(self.separate_by)}


def fit_model(likelihood: JointLikelihood, settings: NamingSettings, *,
              effect: JointEffect | None = None) -> ModelFit:
    """Sample ``likelihood`` (built without the model form; with ``effect``'s terms where
    one is given) and read its evidence, fit, resistances and the effect's value."""
    return fit_and_posterior(likelihood, settings, effect=effect)[0]


def fit_and_posterior(likelihood: JointLikelihood, settings: NamingSettings, *,
                      effect: JointEffect | None = None) -> tuple[ModelFit, Any]:
    """:func:`fit_model` and the posterior it was read from (one sampling serves both)."""
    space = likelihood.space
    if any(n.startswith(("tau_", "slope_")) for n in space.names):
        raise ValueError("likelihood: build it without the model form (ModelFormPrior(on="
                         "False)); an effect is named against the model alone")
    post = sample(likelihood, seed=settings.seed, steps=settings.steps, burn=settings.burn,
                  marginals=False, evidence_draws=settings.evidence_draws)
    lp = post.log_likelihood + space.log_prior(post.samples)
    fit = fit_with_inputs_free(likelihood, seed=settings.seed,
                               starts=post.samples[np.argsort(lp)[::-1][:STARTS]])
    res = {}
    for i, n in enumerate(post.names):
        if n.startswith("log10 R_"):
            q = weighted_quantile(post.samples[:, i], [0.5, 0.05, 0.95], post.weights)
            res[n[len("log10 "):]] = tuple(float(10 ** v) for v in q)
    value = parameter = nominal = None
    if effect is not None:
        p = effect.parameter
        parameter, nominal = p.name, p.nominal
        i = post.names.index(p.name)
        value = tuple(float(v) for v in weighted_quantile(post.samples[:, i],
                                                          [0.5, 0.05, 0.95], post.weights))
    model = ModelFit(effect.key if effect else "base", effect.name if effect else "no effect",
                     float(post.log_evidence), float(post.log_evidence_se),
                     float(fit["chi2"]), int(fit["dof"]), float(fit["p"]),
                     dict(fit["per_formulation"]), res, parameter, value, nominal)
    return model, post


def decide(base: ModelFit, candidates: Sequence[ModelFit], settings: NamingSettings, *,
           separate_by: Mapping[str, str] | None = None) -> NamingVerdict:
    """The rule (module notes) on fitted models."""
    lbf = {c.key: c.log_evidence - base.log_evidence for c in candidates}
    over = tuple(sorted((k for k, v in lbf.items() if v >= settings.threshold),
                        key=lambda k: -lbf[k]))
    tied: tuple[str, ...] = ()
    named = None
    if not over:
        verdict = "none" if base.p >= settings.fit_p else "unexplained"
    else:
        top = lbf[over[0]]
        tied = tuple(k for k in over if top - lbf[k] <= settings.tie_margin)
        best = _fit_of(candidates, over[0])
        passing = [k for k in tied if _fit_of(candidates, k).p >= settings.fit_p]
        if len(tied) > 1:
            verdict = "tie" if passing else "unexplained"
        elif best.p >= settings.fit_p:
            verdict, named = "named", best.key
        else:
            verdict = "unexplained"
    sep = {k: (separate_by or {}).get(k, "") for k in over}
    return NamingVerdict(verdict, base, tuple(candidates), named, tied if len(tied) > 1 else (),
                         over, settings, sep)


def _fit_of(candidates: Sequence[ModelFit], key: str) -> ModelFit:
    return next(c for c in candidates if c.key == key)


def name_effect(make_likelihood: Callable[[JointEffect | None], JointLikelihood],
                effects: Sequence[JointEffect], settings: NamingSettings | None = None, *,
                tick: Callable[[str], None] | None = None) -> NamingVerdict:
    """The base model and each of ``effects`` fitted (``make_likelihood(effect)``: the joint
    likelihood without the model form, with the effect's terms; None for the base), then
    :func:`decide`. ``tick(name)`` is called as each model starts."""
    settings = settings or NamingSettings()
    if tick:
        tick("base")
    base = fit_model(make_likelihood(None), settings)
    fits = []
    for e in effects:
        if tick:
            tick(e.key)
        fits.append(fit_model(make_likelihood(e), settings, effect=e))
    return decide(base, fits, settings, separate_by={e.key: e.separate_by for e in effects})
