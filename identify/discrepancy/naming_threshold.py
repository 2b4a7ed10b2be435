"""The naming rule's threshold, calibrated on the table at hand (issue 49).

An effect is named by its log Bayes factor over the base model
(``ModelFit.log_evidence`` of the candidate less the base model's: the likelihood
integrated over the resistances and the effect's prior, :meth:`Effect.prior_weights`). How
large a Bayes factor noise alone produces depends on the table (its formulations, its
auxiliary columns, its thicknesses) and on how many candidates are tried, so the threshold is
measured, not set: noise-only tables are drawn from the calibrated base model with the
likelihood's own noise (each group's replicate error, and one draw per formulation of the
error its groups share), every candidate is fitted to each, and the threshold is the
``1 - false_naming_rate`` quantile of the largest log Bayes factor among the candidates
(at least :data:`FLOOR`). Naming an effect when its log Bayes factor exceeds it names one on
at most that share of noise-only tables drawn from the model.

Whether the likelihood's noise model is right is checked separately, on noise-only truths
the workflow does not share (``validation/discrepancy_calibration_study.py``: the base
model's chi-square against its degrees of freedom and the false-naming rate there).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .candidate import Effect
from .fit import Group, ModelFit, fit_model
from .observables import AuxGroup
from .tables import ForwardTables

__all__ = ["NamingThreshold", "calibrate_threshold", "FLOOR"]

#: The smallest threshold on the log Bayes factor (a Bayes factor of e^2 = 7.4: "positive"
#: evidence at least, however quiet the noise-only tables are).
FLOOR = 2.0


@dataclass(frozen=True)
class NamingThreshold:
    """The calibrated threshold of the naming rule.

    Attributes
    ----------
    log_bayes_factor : float
        An effect is named when its log Bayes factor over the base model exceeds this.
    false_naming_rate : float
        The share of noise-only tables in which it names one, by construction.
    null_maxima : tuple of float
        The largest log Bayes factor among the candidates on each noise-only table drawn.
    seed : int
        Seed of the draws.
    """

    log_bayes_factor: float
    false_naming_rate: float
    null_maxima: tuple[float, ...]
    seed: int

    @property
    def replicates(self) -> int:
        return len(self.null_maxima)

    def to_dict(self) -> dict:
        return {"log_bayes_factor": self.log_bayes_factor,
                "false_naming_rate": self.false_naming_rate,
                "replicates": self.replicates, "seed": self.seed,
                "null_maxima": list(self.null_maxima)}


def log_bayes_factor(fit: ModelFit, base: ModelFit) -> float:
    """``ln`` of the Bayes factor of ``fit`` over ``base``."""
    return float(fit.log_evidence - base.log_evidence)


def _noise_only(groups: Sequence[Group], aux: Sequence[AuxGroup], base: ModelFit,
                rng: np.random.Generator) -> tuple[list[Group], list[AuxGroup]]:
    """One table drawn from the base model at its best values with the likelihood's noise:
    a group's own error and one error per formulation for what its groups share (the
    marginal variance less the group's own)."""
    shared = {f: rng.standard_normal() for f in sorted({g.formulation for g in groups})}
    out = []
    for g, mu, var in zip(groups, base.predicted, base.variance):
        own = g.standard_error ** 2
        common = max(float(var) - own, 0.0)
        y = mu + g.standard_error * rng.standard_normal() + np.sqrt(common) * shared[
            g.formulation]
        out.append(replace(g, mean=float(y)))
    out_aux = []
    for a, mu, var in zip(aux, base.aux_predicted, base.aux_variance):
        y = mu + np.sqrt(float(var)) * rng.standard_normal()
        out_aux.append(replace(a, mean=float(y)))
    return out, out_aux


def calibrate_threshold(tables: ForwardTables, groups: Sequence[Group],
                        aux: Sequence[AuxGroup], base: ModelFit, effects: Sequence[Effect],
                        *, false_naming_rate: float, replicates: int, seed: int
                        ) -> NamingThreshold:
    """Measure the threshold on ``replicates`` noise-only tables drawn from ``base``.

    Parameters
    ----------
    tables : ForwardTables
    groups, aux : sequences of Group and AuxGroup
        The table's observations (their standard errors are kept; their means are drawn).
    base : ModelFit
        The base model calibrated on the table.
    effects : sequence of Effect
        The candidates tried.
    false_naming_rate : float
        The share of noise-only tables allowed to name an effect, in (0, 0.5].
    replicates : int
        Noise-only tables drawn (at least 10).
    seed : int
    """
    if not 0 < false_naming_rate <= 0.5:
        raise ValueError(f"false_naming_rate: expected a share in (0, 0.5], got "
                         f"{false_naming_rate!r}")
    if replicates < 10:
        raise ValueError(f"replicates: expected at least 10 noise-only tables, got "
                         f"{replicates!r}")
    rng = np.random.default_rng(seed)
    meshes: dict = {}
    maxima = []
    for _ in range(replicates):
        g, a = _noise_only(groups, aux, base, rng)
        b = fit_model(tables, g, None, a, meshes=meshes)
        best = max((log_bayes_factor(fit_model(tables, g, e, a, meshes=meshes), b)
                    for e in effects),
                   default=-np.inf)
        maxima.append(float(best))
    q = float(np.quantile(maxima, 1.0 - false_naming_rate, method="higher"))
    return NamingThreshold(max(q, FLOOR), false_naming_rate, tuple(maxima), seed)
