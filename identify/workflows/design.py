"""``itr design``: the cheapest formulation that reaches a target conductivity, from an
identification's posterior.

The anchor formulations of the design space (:class:`~itr_identify.inference.design_space.
DesignSpace`) are built and tabulated as ``itr predict`` builds a formulation
(:func:`~itr_identify.workflows.predict.tables_for`); every posterior draw's ln k at the
anchors is interpolated over the space (the surrogate), the measured mean's noise added, and
the cheapest point whose measured mean reaches the target with the probability asked is
chosen. Candidates near it (the chosen point and its neighbours one total step either side)
are checked: each built as its own formulation, predicted directly from its own model, and
solved in full on its RVE replicas at the posterior's point (the quoted resistances and the
phase conductivities' posterior medians; at the identification's level); the check holds
where those full solves lie inside the surrogate's 90 % interval.
Writes ``design.json``, ``design.md``, ``design.png`` and ``manifest.json``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from itr_fv.io import write_text
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.run_folder import begin_run, write_manifest
from itr_surrogate.engine import SolveEngine

from ..inference.design_space import Choice, DesignSpace, choose
from ..inference.predictive import (
    DEFAULT_REPLICATES,
    PredictiveRecord,
    measured_draws,
    model_draws,
    predict,
    with_draws,
)
from .predict import (
    check_names,
    effect_for,
    forward_settings_of,
    system_of,
    tables_for,
)

__all__ = ["run_design", "DESIGN_DRAWS"]

#: Posterior draws the design's surrogate carries (evenly thinned from the record's).
DESIGN_DRAWS = 5000


def _thinned(record: PredictiveRecord) -> PredictiveRecord:
    step = max(1, record.draws.shape[0] // DESIGN_DRAWS)
    return with_draws(record, record.draws[::step][:DESIGN_DRAWS])


def surrogate(space: DesignSpace, record: PredictiveRecord, tables: Mapping, *,
              replicates: int, seed: int, terms: dict
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured-mean draws over the grid, (S, T, N), with the grid's shares and totals;
    ``terms``: the effect and matrix conductivity of :func:`~itr_identify.inference.
    predictive.model_draws`."""
    anchors = [space.name(s, t) for s, t in space.anchors()]
    order, k, v = model_draws(record, {n: tables[n] for n in anchors}, seed=seed, **terms)
    idx = [order.index(n) for n in anchors]
    k, v = k[idx], v[idx]
    rel = v / k ** 2
    shares, totals = space.shares(), space.totals()
    kg = np.exp(space.interpolate(np.log(k), shares, totals))
    relg = np.clip(space.interpolate(rel, shares, totals), rel.min(), None)
    y = measured_draws(record, kg, relg * kg ** 2, replicates=replicates,
                       rng=np.random.default_rng(seed + 1))
    return y, shares, totals


def _near(space: DesignSpace, choice: Choice, totals: np.ndarray, count: int
          ) -> list[tuple[float, float]]:
    """The chosen point and its neighbours one total step below and above (in the grid),
    at most ``count``."""
    j = int(np.argmin(np.abs(totals - choice.total)))
    picks = [(choice.share, float(totals[j]))]
    for dj in (-1, 1):
        if 0 <= j + dj < totals.size:
            picks.append((choice.share, float(totals[j + dj])))
    return picks[:count]


def _checks(space: DesignSpace, choice: Choice, y: np.ndarray, grid: tuple, *,
            record: PredictiveRecord, settings, built: tuple[dict, dict],
            engine: SolveEngine | None, count: int, target: float, replicates: int,
            seed: int, echo: Callable[[str], None]) -> list[dict]:
    """Candidates near the choice: each its own model (direct prediction) and full solves
    at the quoted resistances, against the surrogate's interval there; ``built``: the
    anchors' tables and models (a candidate that is one is not built again)."""
    shares, totals = grid
    picks = _near(space, choice, totals, count)
    names = [space.name(s, t) for s, t in picks]
    echo(f"design: checking {', '.join(names)} by their own models and full solves")
    tables, models = _candidates(names, record, settings, built, engine=engine, echo=echo)
    direct = predict(record, tables, replicates=replicates, seed=seed,
                     **_terms(record, models, settings.system, engine))
    rows = []
    for (s, t), name in zip(picks, names):
        i = int(np.argmin(np.abs(shares - s)))
        j = int(np.argmin(np.abs(totals - t)))
        lo, med, hi = np.quantile(y[i, j], [0.05, 0.5, 0.95])
        m = models[name]
        full = _full_at_point(m, tables[name], record, settings.system)
        d = direct[name]
        rows.append({"formulation": name, "surrogate_median": float(med),
                     "surrogate_interval_90": [float(lo), float(hi)],
                     "surrogate_probability": float((y[i, j] >= target).mean()),
                     "direct_median": d.median, "direct_interval_90": list(d.interval),
                     "direct_probability": d.probability_above(target),
                     "full_solve_k": full, "full_solve_inside": bool(lo <= full <= hi)})
    return rows


def _full_at_point(model, table, record: PredictiveRecord, system: MaterialSystem) -> float:
    """The full solves' k_iso (mean over replicas and directions) at the posterior's point,
    W/(m K): the quoted resistances, the phase conductivities and the film at their
    posterior medians, times the level's factor there and the model form's and shared
    correction's factor at that point (the one formula of the joint model: the table's k
    at the point over its k with those terms at 0; 1 for a filler system not measured)."""
    names = record.space["names"]
    point = np.median(record.draws, axis=0)
    nominal = system.conductivities()
    inputs = {f"k_{n[5:]}": float(nominal[n[5:]] * np.exp(point[i]))
              for i, n in enumerate(names) if n.startswith("ln k_")}
    film = float(point[names.index("film_nm")]) * 1e-9 if "film_nm" in names else None
    values = {p: record.quoted[p] for p in model.parameters}
    k = float((model.solve_replicas(values, purpose="design check", inputs=inputs,
                                    film_m=film) * model.level_at(values)["factor"]).mean())
    if record.effect is not None or table.group not in record.group_means:
        return k
    bare = point.copy()
    for i, n in enumerate(names):
        if n.startswith(("offset_", "slope_")):
            bare[i] = 0.0
    at = {name: model_draws(with_draws(record, row[None, :]), {"x": table})[1][0, 0]
          for name, row in (("point", point), ("bare", bare))}
    return k * at["point"] / at["bare"]


def _candidates(names: list[str], record: PredictiveRecord, settings,
                built: tuple[dict, dict], *, engine: SolveEngine | None,
                echo: Callable[[str], None]) -> tuple[dict, dict]:
    """The tables and models of ``names``, those of ``built`` reused."""
    todo = [n for n in names if n not in built[0]]
    new_tables, new_models = tables_for(todo, record, settings, engine=engine, echo=echo)
    tables, models = {**built[0], **new_tables}, {**built[1], **new_models}
    return {n: tables[n] for n in names}, {n: models[n] for n in names}


def _terms(record: PredictiveRecord, models: dict, system: MaterialSystem,
           engine: SolveEngine | None) -> dict:
    """The effect's terms on ``models`` and the matrix's conductivity (model_draws')."""
    return {"effect": effect_for(record, models, system, engine=engine),
            "matrix_conductivity": float(system.conductivities()[system.matrix])}


def run_design(record: PredictiveRecord, space: DesignSpace, out: Path, *, identified: str,
               target: float, probability: float = 0.95,
               cost: Mapping[str, float] | None = None,
               replicates: int = DEFAULT_REPLICATES, seed: int = 0, check: int = 3,
               system: MaterialSystem | None = None, progress: bool = True,
               echo: Callable[[str], None] = print,
               engine: SolveEngine | None = None) -> list[Path]:
    """Screen ``space`` for ``target`` (W/(m K)) into ``out`` (module notes)."""
    t0 = time.perf_counter()
    out = Path(out)
    sysm = system_of(record, system)
    settings = forward_settings_of(record, sysm)
    anchors = check_names([space.name(s, t) for s, t in space.anchors()], sysm, record)
    begin_run(out, "design", folders=("solves",))
    record = _thinned(record)
    echo(f"design: {len(anchors)} anchor formulations ({', '.join(anchors)})")
    tables, models = tables_for(anchors, record, settings, engine=engine, progress=progress,
                                echo=echo)
    y, shares, totals = surrogate(space, record, tables, replicates=replicates, seed=seed,
                                  terms=_terms(record, models, sysm, engine))
    choice, p, c = choose(space, y, shares, totals, target=target, probability=probability,
                          cost=cost)
    checks = [] if choice is None or check == 0 else _checks(
        space, choice, y, (shares, totals), record=record, settings=settings,
        built=(tables, models), engine=engine, count=check, target=target,
        replicates=replicates, seed=seed, echo=echo)
    from ..reporting.design_figure import design_figure

    files = [design_figure(space, y, shares, totals, p, choice, out / "design.png",
                           target=target, probability=probability)]
    data = {"identified": identified, "parametrisation": record.parametrisation,
            "effect": record.effect,
            "fidelity": record.settings.get("fidelity"), "space": space.to_dict(),
            "target": target, "probability": probability, "cost": dict(cost or {}),
            "replicates": replicates, "seed": seed, "draws": int(record.draws.shape[0]),
            "choice": choice.to_dict() if choice is not None else None, "checks": checks,
            "max_probability": float(p.max()), "anchors": _levels(models, record)}
    files.insert(0, write_text(out / "design.json", json.dumps(data, indent=2) + "\n"))
    lines = design_lines(data)
    files.insert(1, write_text(out / "design.md", "\n".join(
        [f"# Design from {identified}", ""] + lines) + "\n"))
    files.append(write_manifest(out, files, {"identified": identified, **data["space"],
                                             "target": target, "probability": probability,
                                             "wall_s": round(time.perf_counter() - t0, 1)},
                                job="design"))
    for line in lines:
        echo(line)
    return files


def _levels(models: Mapping, record: PredictiveRecord) -> dict[str, dict]:
    """Per anchor how its level was set at the quoted point (shipped or runtime, factor)."""
    out = {}
    for name, m in models.items():
        lv = m.level_at({p: record.quoted[p] for p in m.parameters})
        out[name] = {"level": lv["source"], "factor": float(lv["factor"])}
    return out


def design_lines(data: dict) -> list[str]:
    """What the design found, as Markdown lines."""
    ch, tgt, prob = data["choice"], data["target"], data["probability"]
    levels = ("Anchors and their level at the quoted resistances: " + ", ".join(
        f"{n} ({a['level']} x{a['factor']:.3f})" for n, a in data.get("anchors", {}).items())
        + ".")
    if ch is None:
        return [f"No formulation of the space reaches {tgt:g} W/(m K) with probability "
                f"{prob:g} (the most probable reaches it with {data['max_probability']:.2f}).",
                "", levels]
    lines = [f"Cheapest formulation reaching {tgt:g} W/(m K) with probability >= {prob:g}: "
             f"**{ch['formulation']}** (probability {ch['probability']:.3f}, cost "
             f"{ch['cost']:.4g}); k {ch['median']:.3f} W/(m K), 90 % interval "
             f"{ch['interval_90'][0]:.3f} - {ch['interval_90'][1]:.3f}.", ""]
    if data["checks"]:
        lines += ["| candidate | surrogate k (90 %) | P(k >= target) | own model k (90 %) | "
                  "its P | full solves k | inside |", "|---|---|---|---|---|---|---|"]
        for r in data["checks"]:
            lo, hi = r["surrogate_interval_90"]
            dlo, dhi = r["direct_interval_90"]
            lines.append(f"| {r['formulation']} | {r['surrogate_median']:.3f} ({lo:.3f} - "
                         f"{hi:.3f}) | {r['surrogate_probability']:.3f} | "
                         f"{r['direct_median']:.3f} ({dlo:.3f} - {dhi:.3f}) | "
                         f"{r['direct_probability']:.3f} | {r['full_solve_k']:.3f} | "
                         f"{'yes' if r['full_solve_inside'] else 'NO'} |")
    return lines + ["", levels]
