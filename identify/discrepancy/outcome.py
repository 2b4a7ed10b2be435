"""What the discrepancy workflow finds (:class:`Discrepancy`) and the auxiliary measurements
it proposes to decide a tie (:class:`DecidingMeasurement`): the result types, apart from
the steps that make them (:mod:`.decision`, :mod:`.tie_breaking`, :mod:`.best_point`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from scipy import stats

from .candidate import Effect
from .fit import Group, ModelFit
from .gp_discrepancy import LeaveOneOut, ModelFormFit
from .naming_threshold import NamingThreshold
from .observables import AuxGroup
from .tables import ForwardTables

__all__ = ["Discrepancy", "DecidingMeasurement"]


def _short(name: str) -> str:
    return "no effect" if name == "base" else name


@dataclass(frozen=True)
class DecidingMeasurement:
    """One auxiliary measurement, simulated under each tied model (frozen).

    Attributes
    ----------
    key : str
        One of :data:`MEASUREMENTS`.
    description : str
        What to measure, with the noise assumed.
    separation : dict of (str, str) to float
        Per pair of tied models, the expected BIC separation once the measurement is added
        (noise-free expected data; :func:`_pair_separation`).
    outcomes : dict of str to list of (str, float)
        Per tied model, the expected values of the measurement (label, value).
    margin : float
        The BIC difference that names a model.
    """

    key: str
    description: str
    separation: dict[tuple[str, str], float]
    outcomes: dict[str, list[tuple[str, float]]] = field(default_factory=dict)
    margin: float = 6.0

    @property
    def separated(self) -> int:
        """How many pairs it separates by the margin."""
        return sum(v >= self.margin for v in self.separation.values())

    @property
    def score(self) -> float:
        """The separations summed, each capped at twice the margin."""
        return float(sum(min(v, 2 * self.margin) for v in self.separation.values()))

    def separates(self, name: str) -> bool:
        """Whether it separates model ``name`` from every other tied model."""
        mine = [v for (a, b), v in self.separation.items() if name in (a, b)]
        return bool(mine) and min(mine) >= self.margin

    @property
    def worst(self) -> tuple[tuple[str, str], float]:
        """The least separated ordered pair and its expected BIC difference."""
        pair = min(self.separation, key=self.separation.get)
        return pair, self.separation[pair]

    @property
    def decides(self) -> bool:
        """Whether every ordered pair is separated by the margin."""
        return self.worst[1] >= self.margin

    def sentence(self, *, alone: bool = True) -> str:
        """What it would show under each tied model; ``alone``: named as the one
        measurement (else as one of a set)."""
        (a, b), s = self.worst
        verb = "would decide them" if self.decides else "would separate them best"
        n = len(self.separation)
        outs = "; ".join(f"under {_short(m)}: " + ", ".join(f"{lab} {v:.4g}" for lab, v in o)
                         for m, o in self.outcomes.items())
        head = (f"The measurement that {verb}: {self.description} (expected to separate "
                if alone else f"{self.description[0].upper()}{self.description[1:]}: "
                "expected to separate ")
        return (head + f"{self.separated} of {n} pairs by a BIC of {self.margin:g} or more; "
                f"least {s:.1f}, between {_short(a)} and {_short(b)}"
                + (")" if alone else "") + f". Expected outcome {outs}.")

    def to_dict(self) -> dict:
        return {"key": self.key, "description": self.description,
                "separation": [{"models": [a, b], "delta_bic": s}
                               for (a, b), s in self.separation.items()],
                "pairs_separated": self.separated,
                "worst_delta_bic": self.worst[1], "decides": self.decides,
                "outcomes": {m: [[lab, v] for lab, v in o] for m, o in self.outcomes.items()}}


@dataclass(frozen=True)
class Discrepancy:
    """Outcome of the workflow (frozen: every stage of
    :func:`~.decision.find_discrepancy` makes a new one).

    Attributes
    ----------
    verdict : {"none", "named", "tie", "unexplained"}
    statement : str
        One paragraph: what the data say.
    groups : list of Group
    base : ModelFit
    candidates : list of ModelFit
        Ranked by log Bayes factor over the base model, best first.
    skipped : dict of str to str
        Candidates not tried, with the reason.
    p_value_base : float
        Chi-square test of the base model's residuals.
    structure : list of str
        The residuals' trends (filler fraction, filler type, thickness).
    left_out : list of str
        Formulations not used (two-filler).
    model_form : ModelFormFit or None
        The base model with the model-form term (:mod:`itr_identify.discrepancy.gp_discrepancy`),
        calibrated when no candidate is named.
    leave_one_out : dict of str to LeaveOneOut
        With the model-form term: each formulation predicted from the others by the base
        model alone (``"base"``) and with the term (``"model-form"``).
    aux : list of AuxGroup
        The auxiliary observations (density, filler mass fraction) in the likelihood.
    densities : dict
        The phase densities the auxiliary predictions used, g/cm^3.
    tied : list of ModelFit
        The models the data cannot tell apart (:func:`.tie_breaking.tied_set`): within the tie
        margin in likelihood, physically plausible, and (a candidate) reaching an effect of
        one grid step or more.
    deciding : list of DecidingMeasurement
        The auxiliary measurements ranked by the BIC separation they are expected to give
        among :attr:`tied` (best first).
    corrected_at_best : dict
        Per candidate corrected at its best point: formulation -> its correction factor.
    deciding_keys : list of str
        The measurement named to decide the tied set: the best one, or the two that
        together separate every pair where no single one does.
    threshold : NamingThreshold or None
        The naming rule's threshold on the log Bayes factor, calibrated on this table
        (:mod:`.naming_threshold`).
    """

    verdict: str
    statement: str
    groups: list[Group]
    base: ModelFit
    candidates: list[ModelFit]
    skipped: dict[str, str]
    p_value_base: float
    structure: list[str]
    left_out: list[str]
    effects: list[Effect]
    winner: ModelFit | None = None
    tables: ForwardTables | None = None
    model_form: ModelFormFit | None = None
    leave_one_out: dict[str, LeaveOneOut] | None = None
    aux: list[AuxGroup] = field(default_factory=list)
    densities: dict[str, float] = field(default_factory=dict)
    tied: list[ModelFit] = field(default_factory=list)
    deciding: list[DecidingMeasurement] = field(default_factory=list)
    corrected_at_best: dict[str, dict[str, float]] = field(default_factory=dict)
    deciding_keys: list[str] = field(default_factory=list)
    threshold: NamingThreshold | None = None

    def log_bayes_factor(self, fit: ModelFit) -> float:
        """``ln`` of the Bayes factor of ``fit`` over the base model."""
        return float(fit.log_evidence - self.base.log_evidence)

    def p_value(self, fit: ModelFit) -> float:
        return float(stats.chi2.sf(fit.chi_square, fit.dof()))

    def chi_square_per_dof(self, fit: ModelFit) -> float:
        return fit.chi_square / fit.dof()

    def to_dict(self) -> dict:
        def fit_dict(m: ModelFit) -> dict:
            return {"name": m.name, "parameters": m.parameters,
                    "interval_90": list(m.interval) if m.interval else None,
                    "chi_square": m.chi_square, "dof": m.dof(),
                    "p_value": self.p_value(m), "bic": m.bic,
                    "delta_bic": self.base.bic - m.bic,
                    "log_evidence": m.log_evidence,
                    "log_bayes_factor": self.log_bayes_factor(m),
                    "predicted": m.predicted.tolist(), "at_grid_edge": m.at_grid_edge,
                    "auxiliary_predicted": m.aux_predicted.tolist(),
                    "n_observations": m.n_observations}
        return {"verdict": self.verdict, "statement": self.statement,
                "winner_name": self.winner.name if self.winner is not None else None,
                "groups": [{"label": g.label, "formulation": g.formulation,
                            "thickness_m": g.thickness_m, "measured": g.mean,
                            "standard_error": g.standard_error, "n": g.n}
                           for g in self.groups],
                "auxiliary": [{"label": a.label, "observable": a.observable,
                               "measured": a.mean, "standard_error": a.standard_error,
                               "n": a.n} for a in self.aux],
                "densities_g_per_cm3": self.densities,
                "tied": [m.name for m in self.tied],
                "deciding": [x.to_dict() for x in self.deciding],
                "deciding_keys": self.deciding_keys,
                "corrected_at_best": self.corrected_at_best,
                "threshold": self.threshold.to_dict() if self.threshold else None,
                "base": fit_dict(self.base), "candidates": [fit_dict(c) for c in self.candidates],
                "skipped": self.skipped, "structure": self.structure,
                "left_out": self.left_out,
                "effects": [e.describe() for e in self.effects],
                "model_form": self.model_form.to_dict() if self.model_form else None,
                "leave_one_out": ({k: v.to_dict() for k, v in self.leave_one_out.items()}
                                  if self.leave_one_out else None),
                "corrections": ({f: c.to_dict() for f, c in self.tables.corrections.items()}
                                if self.tables is not None else {})}
