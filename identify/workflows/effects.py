"""The discrepancy verdict and the identification with an effect, inside ``itr reproduce`` and
``itr identify`` (issue 60): on the gap identification's own joint model
(:mod:`itr_identify.discrepancy.on_identification`), written into the run's report
(``## Discrepancy``), ``identified.json`` (``discrepancy``) and ``effect_residuals.png``."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from itr_surrogate.engine import SolveEngine

from ..discrepancy.joint_effects import JOINT_EFFECTS
from ..discrepancy.naming import NamingSettings
from ..discrepancy.on_identification import effects_of, n_solves, name_on, with_effect
from ..inference.predictive import record_of, write_record
from ..reporting.figures import effect_residual_figure
from ..reporting.naming_words import (
    candidate_lines,
    effect_fit_lines,
    headline_entry,
    rule_sentence,
    verdict_sentence,
)

__all__ = ["run_effects"]


def run_effects(ident, out: Path, *, engine: SolveEngine, verdict: bool,
                effect: str | None, progress: bool, echo: Callable[[str], None] = print,
                settings: NamingSettings | None = None
                ) -> tuple[dict, list[str], list[Path]]:
    """The verdict over the library (``verdict``) and the identification with ``effect``
    (or with the named one) beside the base model; returns (the record, the report's
    lines, the files written)."""
    from tqdm.auto import tqdm

    settings = settings or NamingSettings()
    record: dict = {}
    lines = ["## Discrepancy: the identification's model against the library's effects", ""]
    files: list[Path] = []
    v = None
    built: dict = {}
    if verdict:
        echo(f"discrepancy: the {len(JOINT_EFFECTS)} library effects on the gap "
             "identification's joint model (ratio tables on its first replicas; base and "
             "candidates without the model form)")
        with tqdm(total=n_solves(ident, JOINT_EFFECTS), desc="effect ratio solves",
                  unit="solve", disable=not progress) as bar:
            built = {e.key: e for e in effects_of(ident, JOINT_EFFECTS, engine=engine,
                                                  tick=bar.update)}
        v = name_on(ident, list(built.values()), settings=settings)
        record["verdict"] = v.to_dict()
        lines += [rule_sentence(v), "", verdict_sentence(v), ""] + candidate_lines(v) + [""]
        echo(f"discrepancy: {v.verdict}" + (f" ({v.named})" if v.named else ""))
    if v is not None:
        record["headline"] = headline_entry(v)
    key = effect or (v.named if v is not None else None)
    if key is not None:
        e = built.get(key) or effects_of(ident, [key], engine=engine)[0]
        echo(f"discrepancy: the identification with {e.name} beside the base model")
        fit = with_effect(ident, e, settings=settings)
        record["effect_fit"] = fit.to_dict()
        record["predictive"], draws = write_record(
            record_of(ident, joint=fit.posterior, likelihood=fit.likelihood), out)
        files.append(draws)
        fig = effect_residual_figure(fit, out / "effect_residuals.png")
        files.append(fig)
        record["headline"] = headline_entry(v, fit)
        lines += [f"### With {e.name}" + ("" if v is None or v.named == key
                                          else " (asked for; not named by the rule)"), "",
                  *effect_fit_lines(fit), "",
                  f"Figure: `{fig.name}` (each formulation's residual over its sd, before "
                  "and after)."]
    return record, lines, files
