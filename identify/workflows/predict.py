"""``itr predict``: formulations not measured, predicted from an identification's posterior.

:func:`forward_settings_of` rebuilds the forward settings an identification ran with from
its record (:class:`~itr_identify.inference.predictive.PredictiveRecord`), refusing where
they cannot be rebuilt exactly. :func:`tables_for` builds each formulation's forward model as
the identification built the measured ones (its RVE replicas, reduced basis, replicas solved at
the quoted point, its level: the shipped correction where it holds, else one faithful
correction at the quoted point, at the identification's fidelity level; the inputs'
elasticities) and tabulates it. :func:`run_predict` writes ``predicted.json``,
``predicted.md`` and ``manifest.json``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from itr_fv.io import write_text
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.run_folder import begin_run, write_manifest
from itr_surrogate.engine import SolveEngine

from ..forward.model import PARAMETRISATIONS, ForwardModel, ForwardSettings
from ..inference.formulations import fractions_of
from ..inference.joint import Tabulated
from ..inference.nuisance import elasticities
from ..inference.predictive import (
    DEFAULT_LEVEL,
    DEFAULT_REPLICATES,
    Prediction,
    PredictiveRecord,
    predict,
)

__all__ = ["forward_settings_of", "system_of", "tables_for", "run_predict",
           "prediction_lines", "effect_for", "check_names"]


def system_of(record: PredictiveRecord, system: MaterialSystem | None = None
              ) -> MaterialSystem:
    """The material system of ``record``: ``system`` where given, else re-read from the file
    the identification named (the package's default where it named none); ValueError naming
    ``system`` where it differs from the one the identification ran with."""
    from itr_fv.materials import default_system
    from itr_fv.materials.system_file import read_system

    stated = record.settings["system"]
    want = {k: v for k, v in stated.items() if k != "source"}
    if system is None:
        source = stated.get("source") or ""
        if _same(default_system(), want):
            system = default_system()
        elif source and Path(source).is_file():
            system = read_system(source)
        else:
            raise ValueError(f"system: the identification's material system file "
                             f"{source or '(none named)'} is not there; give it with "
                             "--system FILE")
    have = {k: v for k, v in system.to_dict().items() if k != "source"}
    if have != want:
        diff = sorted(k for k in set(have) | set(want) if have.get(k) != want.get(k))
        raise ValueError(f"system: {system.name} differs from the identification's "
                         f"{stated.get('name')} in {', '.join(diff)}")
    return system


def _same(system: MaterialSystem, want: dict) -> bool:
    return {k: v for k, v in system.to_dict().items() if k != "source"} == want


def forward_settings_of(record: PredictiveRecord, system: MaterialSystem) -> ForwardSettings:
    """The forward settings of ``record`` (its fidelity level's, the RVE, replicas,
    tolerances and solver as recorded); ValueError naming ``identified`` where the rebuilt
    settings differ from the recorded ones."""
    from itr_fv.rve.spec import RVESpec

    from ..forward.fidelity import faithful_for

    s = dict(record.settings)
    level = s.pop("fidelity", "") or "quick"
    s.pop("effect_reference_fraction", None)
    faithful = faithful_for(level, system)
    corrections = (s.get("faithful") or {}).get("corrections")
    if faithful is not None and corrections:
        from dataclasses import replace

        faithful = replace(faithful, corrections=corrections)
    rve = RVESpec.from_dict({k: s[k] for k in RVESpec.field_names() if k in s})
    fw = ForwardSettings(rve, replicas=s["replicas"],
                         prior_m2K_per_W=tuple(s["prior_m2K_per_W"]), rb_tol=s["rb_tol"],
                         rb_max_solves=s["rb_max_solves"], solver_tol=s["solver_tol"],
                         solver=s["solver"], psd_basis=s["psd_basis"], faithful=faithful,
                         system=system)
    got = fw.to_dict()
    diff = sorted(k for k in set(got) | set(s) if k != "system" and got.get(k) != s.get(k))
    if diff:
        raise ValueError(f"identified: the forward settings cannot be rebuilt as recorded "
                         f"({', '.join(diff)} differ)")
    return fw


def _model_for(name: str, record: PredictiveRecord, settings: ForwardSettings, *,
               engine: SolveEngine | None, progress: bool) -> ForwardModel:
    """One formulation's forward model built and set to its level at the quoted point."""
    par = PARAMETRISATIONS[record.parametrisation]
    fractions = fractions_of(name, settings.system)
    fixed = {}
    if par.contact == "area" and len(fractions) > 1:
        # as the identification holds its hybrids under the per-area model: the fillers'
        # own parameters at the point quoted, the pair's contact varied
        own = {p for f in fractions for p in par.parameters([f], matrix=settings.system.matrix)}
        fixed = {p: record.quoted[p] for p in sorted(own) if p in record.quoted}
    m = ForwardModel(name, fractions, par, settings, fixed=fixed, engine=engine).build(
        progress=progress)
    values = {p: record.quoted[p] for p in m.parameters}
    m.anchor_at(values)
    if m.shipped is None and settings.faithful is not None and par.name == "gap":
        m.correct_at(values, settings.faithful)
    return m


def tables_for(names: Sequence[str], record: PredictiveRecord, settings: ForwardSettings, *,
               engine: SolveEngine | None = None, progress: bool = False,
               echo: Callable[[str], None] = print
               ) -> tuple[dict[str, Tabulated], dict[str, ForwardModel]]:
    """The tabulated forward models of ``names`` (module notes) and the models."""
    sampled = record.space["names"]
    inputs = any(n.startswith("ln k_") or n == "film_nm" for n in sampled)
    film = "film_nm" in sampled
    tables, models = {}, {}
    for name in names:
        t = time.perf_counter()
        m = _model_for(name, record, settings, engine=engine, progress=progress)
        values = {p: record.quoted[p] for p in m.parameters}
        el = elasticities({name: m}, values, film=film)[name] if inputs else {}
        tables[name], models[name] = Tabulated.of(name, m, el), m
        level = m.level_at(values)
        echo(f"  {name}: {m.microstructures[0].n_particles} particles, "
             f"{len(m.solves)} full solves, level {level['source']} "
             f"x{level['factor']:.3f}, {time.perf_counter() - t:.0f} s")
    return tables, models


def effect_for(record: PredictiveRecord, models: dict[str, ForwardModel],
               system: MaterialSystem, *, engine: SolveEngine | None = None):
    """The terms of the record's effect on ``models`` (None without one): a ratio effect's
    tables solved on their first replicas, as the identification solved its own."""
    if record.effect is None:
        return None
    from ..discrepancy.joint_effects import joint_effects, ratio_tables

    seed = int(record.settings.get("seed", 0))
    ratios = ratio_tables(models, [record.effect], engine=engine, seed=seed)
    return joint_effects([record.effect], matrix=system.matrix, ratios=ratios, system=system,
                         reference_fraction=record.settings["effect_reference_fraction"])[0]


def check_names(names: Sequence[str], system: MaterialSystem, record: PredictiveRecord
                ) -> list[str]:
    """The formulation names, each of the system and needing only resistances the record
    identified; ValueError naming ``formulations`` (before any packing or solve)."""
    if not names:
        raise ValueError("formulations: name one formulation at least (e.g. Al2O3-60)")
    par = PARAMETRISATIONS[record.parametrisation]
    out = []
    for n in names:
        try:
            fractions = fractions_of(n, system)
        except ValueError as exc:
            raise ValueError(f"formulations: {exc}") from None
        if n in out:
            raise ValueError(f"formulations: {n} named twice")
        missing = [p for p in par.parameters(sorted(fractions), matrix=system.matrix)
                   if p not in record.resistances]
        if missing:
            raise ValueError(f"formulations: {n} needs {', '.join(missing)}, which the "
                             f"identification (of {', '.join(record.measured)}) did not "
                             "identify; measure a formulation of that filler")
        out.append(n)
    return out


def prediction_lines(preds: dict[str, Prediction]) -> list[str]:
    """A Markdown table of predictions."""
    level = next(iter(preds.values())).level
    lines = [f"| formulation | k median, W/(m K) | {100 * level:g} % predictive interval | "
             "model k (no noise) | its filler system measured |", "|---|---|---|---|---|"]
    for p in preds.values():
        lines.append(f"| {p.formulation} | {p.median:.3f} | {p.interval[0]:.3f} - "
                     f"{p.interval[1]:.3f} | {p.model_median:.3f} | "
                     f"{'yes' if p.system_identified else 'no (prior terms)'} |")
    return lines


def run_predict(record: PredictiveRecord, names: Sequence[str], out: Path, *,
                identified: str, system: MaterialSystem | None = None,
                replicates: int = DEFAULT_REPLICATES, level: float = DEFAULT_LEVEL,
                seed: int = 0, progress: bool = True, echo: Callable[[str], None] = print,
                engine: SolveEngine | None = None) -> list[Path]:
    """Predict ``names`` from ``record`` into ``out`` (module notes); returns the files."""
    t0 = time.perf_counter()
    out = Path(out)
    sysm = system_of(record, system)
    settings = forward_settings_of(record, sysm)
    names = check_names(names, sysm, record)
    begin_run(out, "predict", folders=("solves",))
    own = engine is None
    engine = engine or SolveEngine(out / "solves", echo=echo)
    try:
        echo(f"predict: {len(names)} formulation(s) from the {record.parametrisation} "
             f"identification of {', '.join(record.measured)}"
             + (f" with the effect {record.effect!r}" if record.effect else ""))
        tables, models = tables_for(names, record, settings, engine=engine,
                                    progress=progress, echo=echo)
        preds = predict(record, tables, replicates=replicates, level=level, seed=seed,
                        effect=effect_for(record, models, sysm, engine=engine),
                        matrix_conductivity=float(sysm.conductivities()[sysm.matrix]))
    finally:
        if own:
            engine.close()
    data = {"identified": identified, "parametrisation": record.parametrisation,
            "effect": record.effect, "replicates": replicates, "level": level, "seed": seed,
            "fidelity": record.settings.get("fidelity"),
            "predictions": [p.to_dict() | {"level_source": models[p.formulation].level_at(
                {q: record.quoted[q] for q in models[p.formulation].parameters})["source"]}
                for p in preds.values()]}
    files = [write_text(out / "predicted.json", json.dumps(data, indent=2) + "\n")]
    md = [f"# Predicted conductivities from {identified}", "",
          f"The measured mean of {replicates} samples per formulation, {record.parametrisation} "
          f"identification at fidelity {record.settings.get('fidelity')}"
          + (f", with the effect {record.effect!r}" if record.effect else "") + ".", ""]
    files.append(write_text(out / "predicted.md", "\n".join(md + prediction_lines(preds))
                            + "\n"))
    files.append(write_manifest(out, files, {"identified": identified, "formulations": names,
                                             "replicates": replicates, "level": level,
                                             "seed": seed,
                                             "wall_s": round(time.perf_counter() - t0, 1)},
                                job="predict"))
    for line in prediction_lines(preds):
        echo(line)
    return files
