"""Find, name, add, shrink on the identification's own model (issue 60).

:func:`name_on` takes a finished gap identification (:class:`~itr_identify.inference.
pipeline.Identification`: its forward models at the headline's fidelity level, its
measurements, uncertain inputs, elasticities and resistance prior), solves the ratio tables
of the candidate effects on the models' first replicas (:mod:`.joint_effects`), fits the
base model and every candidate on the one joint model without the model form and applies
the rule (:mod:`.naming`). :func:`with_effect` fits one effect jointly with the resistances
(``itr identify --effect NAME``, and the named one): the base beside it, each with its
resistances, its chi-square without the model-form term, each formulation predicted from
the others (leave-one-out) and the residuals before and after.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from itr_surrogate.engine import SolveEngine

from ..inference.effect_terms import JointEffect
from ..inference.joint_fit import leave_one_out_joint
from ..inference.priors import ModelFormPrior
from .joint_effects import joint_effects, n_ratio_solves, ratio_tables
from .naming import ModelFit, NamingSettings, NamingVerdict, fit_and_posterior, name_effect

__all__ = ["EffectFit", "effects_of", "name_on", "with_effect"]


@dataclass(frozen=True)
class EffectFit:
    """The identification with one effect beside the base model (frozen).

    Attributes
    ----------
    base, effect : ModelFit
        The two fits (resistances, chi-square without the model form, evidence).
    loo_base, loo_effect : list of dict
        Each formulation predicted from the others (:func:`~itr_identify.inference.
        joint_fit.leave_one_out_joint`) under each.
    residuals : dict
        Per formulation (measured mean, model k and the sd of a measured mean about it at
        the base's best point, the same at the effect's), W/(m K).
    posterior, likelihood : JointPosterior, JointLikelihood
        The identification with the effect: its draws and its likelihood (what ``itr
        predict`` evaluates, :mod:`itr_identify.inference.predictive`; not in
        :meth:`to_dict`).
    """

    base: ModelFit
    effect: ModelFit
    loo_base: list[dict]
    loo_effect: list[dict]
    residuals: dict[str, tuple[float, float, float, float, float]]
    posterior: Any = field(default=None, repr=False, compare=False)
    likelihood: Any = field(default=None, repr=False, compare=False)

    def loo_inside(self, which: str) -> tuple[int, int]:
        """(inside the 90 % predictive interval, formulations) of ``which`` ('base' or
        'effect')."""
        rows = self.loo_base if which == "base" else self.loo_effect
        return sum(bool(r["inside"]) for r in rows), len(rows)

    def to_dict(self) -> dict[str, Any]:
        return {"base": self.base.to_dict(), "effect": self.effect.to_dict(),
                "loo_inside": {w: list(self.loo_inside(w)) for w in ("base", "effect")},
                "leave_one_out": {"base": self.loo_base, "effect": self.loo_effect},
                "residuals": {f: list(v) for f, v in self.residuals.items()}}


def effects_of(ident, keys: Sequence[str], *, engine: SolveEngine | None = None,
               tick: Callable[[], None] | None = None) -> list[JointEffect]:
    """The joint effects ``keys`` on ``ident``'s models (their ratio tables solved on the
    models' first replicas through ``engine``)."""
    if ident.parametrisation != "gap" or ident.joint is None:
        raise ValueError("ident: an effect is added to the gap identification's joint "
                         "posterior (parametrisation 'gap', joint=True)")
    system = ident.settings.system
    ratios = ratio_tables(ident.models, keys, engine=engine, seed=ident.settings.seed,
                          tick=tick)
    return joint_effects(keys, matrix=system.matrix, ratios=ratios, system=system)


def n_solves(ident, keys: Sequence[str]) -> int:
    """Full solves :func:`effects_of` makes."""
    return n_ratio_solves(len(ident.models), keys)


def name_on(ident, effects: Sequence[JointEffect], *, settings: NamingSettings | None = None,
            step: Callable[[str], None] | None = None) -> NamingVerdict:
    """The rule on ``ident``'s table: base and every candidate of ``effects`` (built by
    :func:`effects_of` on ``ident``) on the one joint model without the model form (module
    notes)."""
    off = ModelFormPrior(on=False)
    return name_effect(lambda e: ident.likelihood(model_form=off, effect=e), effects,
                       settings or NamingSettings(), tick=step)


def with_effect(ident, effect: JointEffect, *,
                settings: NamingSettings | None = None) -> EffectFit:
    """``effect`` fitted jointly with the resistances beside the base model (module notes):
    each model sampled once, its fit, leave-one-out and best point read from that sample."""
    settings = settings or NamingSettings()
    off = ModelFormPrior(on=False)
    fits, loos, best, posts = {}, {}, {}, {}
    for which, e in (("base", None), ("effect", effect)):
        lik = ident.likelihood(model_form=off, effect=e)
        fits[which], post = fit_and_posterior(lik, settings, effect=e)
        posts[which] = (post, lik)
        loos[which] = leave_one_out_joint(post, lik, seed=settings.seed)
        best[which] = _best_point(lik, post)
    res = {}
    for i, f in enumerate(best["base"][0]):
        mean = float(ident.measurements.mean(f))
        res[f] = (mean, best["base"][1][i], best["base"][2][i], best["effect"][1][i],
                  best["effect"][2][i])
    return EffectFit(fits["base"], fits["effect"], loos["base"], loos["effect"], res,
                     *posts["effect"])


def _best_point(lik, post) -> tuple[list[str], list[float], list[float]]:
    """(formulations, model k, sd of a measured mean about it) at the posterior's highest
    draw, W/(m K)."""
    lp = post.log_likelihood + lik.space.log_prior(post.samples)
    k, v = lik.predictive(post.samples[int(np.argmax(lp))][None, :])
    return list(lik.order), [float(x) for x in k[:, 0]], [float(x) for x in np.sqrt(v[:, 0])]
