"""Assemble the shipped corrections from a corrections plan's finished campaigns.

The plan (:mod:`itr_identify.forward.correction_plan`) solves per filler system a *table*
(its formulations at one box and voxel, several packings, every resistance of the design)
and three *studies*. The factor that takes the cheap RVE to a converged box without voxel
bias is, per formulation ``i`` and design point ``R``,

    k_0(i, R) = mean_j k_table(i, R, j) * f_box / (1 + b(R))        (W/(m K))
    c(i, R)   = k_0(i, R) / mean_r k_cheap(i, R, r)                 (dimensionless)

- ``f_box`` (:func:`box_step`): the converged level over the table box's, from the box
  study (one formulation, many packings per box): the converged box is the smallest whose
  mean lies within :data:`BOX_CRITERION` of every larger box's; the converged level pools
  the packings of it and every larger box;
- ``b(R)`` (:func:`voxel_order`): the table voxel's relative bias against no voxel, from the
  order study (the same particles at three voxels or more): per design point the law
  ``k_jh = a_j (1 + beta h^p)`` (a level per packing, one relative slope and one order),
  fitted by least squares over the relative residuals with the order in
  :data:`ORDER_RANGE`, its 90 % interval by the profile of the order (the F test of
  nonlinear regression: ``RSS(p) <= RSS_min (1 + F_0.9(1, dof) / dof)``); between design
  points linear in log10 R (a hybrid: the mean log10 of its two);
- the tail cut (:func:`tail_cut`): the finest quantile's level against the table's cut at
  the same box, not applied (it is not resolved by a few packings) but its change and its
  standard error in quadrature as an uncertainty.

The three uncertainties are one *shared* term per system (``shared_sd``: every formulation
of the system moves with it; the likelihood marginalises it once per system). Per
formulation the packings' scatter is the *independent* term: the relative variance of one
packing pooled over the system's formulations (per design point; ``packing_dof`` = the
pooled degrees of freedom, for a Student t), over ``sqrt(J)``.

Per system the factors are fitted by least squares as a smooth function of the total
filler fraction ``phi`` and ``x = log10(R / R0)``:

    single filler:  c = a + b dphi + d x + e x^2 + g dphi x
    two fillers:    c = a + b dphi + d1 x1 + d2 x2 + e1 x1^2 + e2 x2^2 + e12 x1 x2
                        + g dphi (x1 + x2)

(``dphi = phi - phi0``); its residual RMS is the interpolation's uncertainty for a fraction
the table does not hold. A formulation the table holds takes its own points (a quadratic in
``x``, or in ``x1, x2``, through them by least squares; their residual RMS added).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import optimize, stats

from itr_fv.rve.contact_film import CONTACT_GEOMETRY

from .correction_plan import CorrectionPlan
from .fidelity import CHEAP_REPLICAS, CHEAP_TOL

__all__ = ["assemble", "campaign_rows", "plan_rows", "box_step", "voxel_order", "tail_cut",
           "table_points", "fit_system", "design_columns", "BOX_CRITERION", "TABLE_FORMAT"]

#: A box is converged when its mean k_iso lies within this of every larger box's.
BOX_CRITERION = 0.005
#: The corrections table's format: 2 holds shared terms per system (this module).
TABLE_FORMAT = 2
#: Relative sd of the box term of a system without a box study, whose table box is the
#: powders' rule (the size cut removes at most 1.5 % of a filler's volume): measured for
#: AlN-60 at that rule's 80 um, the next step (80 -> 96 um) was -0.07 %, 90 % interval
#: -0.77 to +0.64 % (validation/results/box_study.md), about 0.4 % sd.
BOX_RULE_SD = 0.004
#: The orders the voxel law is fitted over: at least first order (the staircase of a
#: sphere's surface misplaces its area by O(h), the gap model's least order), at most 8 (a
#: bias that vanishes within the finest voxel). Below 1 a power law cannot tell its term
#: from a level (h^p about constant over the voxels), and a non-monotone increment of one
#: packing (AlN-60 at 5e-9) then reads as an unbounded extrapolation.
ORDER_RANGE = (1.0, 8.0)
#: Confidence of the intervals the studies report.
LEVEL = 0.90
_Z = stats.norm.ppf(0.5 + LEVEL / 2)


def campaign_rows(folder: Path) -> list[dict]:
    """A campaign store's rows, or where there is none the rows of ``<folder>.rows.json``
    (rows kept without their store, e.g. read back from a device run's log)."""
    from itr_surrogate.store import CampaignStore

    if (folder / "campaign.json").is_file():
        store = CampaignStore(folder)
        return store.results().to_pylist() if store.done_tasks() else []
    loose = folder.with_name(folder.name + ".rows.json")
    return json.loads(loose.read_text()) if loose.is_file() else []


def plan_rows(roots: Sequence[str | Path], name: str) -> list[dict]:
    """The rows of campaign ``name`` from every run folder in ``roots`` (its store
    ``ROOT/<name>``); a (task, parameter set) solved in two folders counts once (the
    first)."""
    out, seen = [], set()
    for root in roots:
        for r in campaign_rows(Path(root) / name):
            key = (r["task_id"], int(r["set_index"]))
            if key not in seen:
                seen.add(key)
                out.append(r)
    return out


def _by_replica(rows: Sequence[Mapping], set_index: int = 0) -> dict[int, float]:
    return {int(r["replica"]): float(r["k_iso"]) for r in rows
            if int(r["set_index"]) == set_index}


def _welch(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """``mean(b) / mean(a) - 1`` with its standard error (first order) and Welch dof."""
    ma, mb = a.mean(), b.mean()
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    se = math.sqrt(va + vb) / ma
    dof = (va + vb) ** 2 / (va ** 2 / (a.size - 1) + vb ** 2 / (b.size - 1))
    t = stats.t.ppf(0.5 + LEVEL / 2, dof)
    rel = mb / ma - 1
    return {"rel": float(rel), "se": float(se), "dof": float(dof),
            "interval": [float(rel - t * se), float(rel + t * se)]}


def box_step(plan: CorrectionPlan, system: str, roots: Sequence[str | Path]) -> dict[str, Any]:
    """The box study of ``system``: per box its packings' k_iso, mean and standard error;
    the steps between boxes; the converged box; ``factor`` (converged level over the table
    box's) and its relative standard uncertainty ``sd``."""
    s = plan.system(system)
    st = s.studies["boxes"]
    ks = {}
    for box, camp in zip(st.boxes_um, plan.study_campaigns(system, "boxes")):
        k = np.array([v for _, v in sorted(_by_replica(plan_rows(roots, camp.name)).items())])
        if k.size < 2:
            raise ValueError(f"boxes: {camp.name} has {k.size} packings solved (need 2)")
        ks[box] = k
    boxes = sorted(ks)
    means = {b: float(ks[b].mean()) for b in boxes}
    converged = next(b for b in boxes if all(abs(means[c] / means[b] - 1) <= BOX_CRITERION
                                             for c in boxes if c > b))
    pooled = np.concatenate([ks[b] for b in boxes if b >= converged])
    if s.box_um not in ks:
        raise ValueError(f"boxes: the study has no run at the table box {s.box_um:g} um")
    step = _welch(ks[s.box_um], pooled)
    return {"formulation": st.formulation, "seed": st.seed, "design": st.design or s.design,
            "boxes": [{"box_um": b, "k_iso": ks[b].tolist(), "mean": means[b],
                       "se": float(ks[b].std(ddof=1) / math.sqrt(ks[b].size))}
                      for b in boxes],
            "steps": [{"from_um": a, "to_um": b, **_welch(ks[a], ks[b])}
                      for a, b in zip(boxes, boxes[1:])],
            "converged_um": converged, "table_box_um": s.box_um,
            "factor": 1 + step["rel"], "sd": step["se"], "dof": step["dof"]}


def _order_fit(h: np.ndarray, k: np.ndarray, p: float) -> tuple[float, float, np.ndarray]:
    """Least squares of ``k_jv = a_j (1 + beta h_v^p)`` (relative residuals) at a fixed
    order ``p``: (RSS, beta, a)."""
    g_h = h ** p

    def rss(beta: float) -> tuple[float, np.ndarray]:
        g = 1 + beta * g_h
        w = 1 / k ** 2       # relative residuals
        a = (k * g * w).sum(axis=1) / (g ** 2 * w).sum(axis=1)
        return float((((k - a[:, None] * g) / k) ** 2).sum()), a

    res = optimize.minimize_scalar(lambda b: rss(b)[0], bounds=(-50.0, 50.0),
                                   method="bounded", options={"xatol": 1e-12})
    value, a = rss(float(res.x))
    return value, float(res.x), a


def _one_order(h: np.ndarray, k: np.ndarray, h0: float) -> dict[str, Any]:
    """The order, the bias at ``h0`` and their 90 % intervals from packings x voxels ``k``."""
    ps = np.exp(np.linspace(math.log(ORDER_RANGE[0]), math.log(ORDER_RANGE[1]), 241))
    fits = [_order_fit(h, k, p) for p in ps]
    rss = np.array([f[0] for f in fits])
    bias = np.array([f[1] * h0 ** p for f, p in zip(fits, ps)])
    dof = k.size - (k.shape[0] + 2)
    i = int(np.argmin(rss))
    if dof < 1:
        raise ValueError(f"order: {k.shape[0]} packings at {k.shape[1]} voxels leave no "
                         "degree of freedom for the order")
    inside = rss <= rss[i] * (1 + stats.f.ppf(LEVEL, 1, dof) / dof)
    return {"order": float(ps[i]), "order_interval": [float(ps[inside].min()),
                                                      float(ps[inside].max())],
            "order_bounded": bool(not inside[0] and not inside[-1]),
            "bias": float(bias[i]), "bias_interval": [float(bias[inside].min()),
                                                      float(bias[inside].max())],
            "rms": float(math.sqrt(rss[i] / max(dof, 1))), "dof": int(dof)}


def voxel_order(plan: CorrectionPlan, system: str,
                roots: Sequence[str | Path]) -> dict[str, Any]:
    """The order study of ``system``: per design point the packings' k_iso at every voxel,
    the fitted order and the table voxel's bias ``b`` with their 90 % intervals, and ``sd``
    (the bias interval's half-width over 1.645)."""
    s = plan.system(system)
    st = s.studies["order"]
    camps = plan.study_campaigns(system, "order")
    design = st.design or s.design
    sets = camps[0].parameter_sets(camps[0].formulations[0])
    points = []
    for i, pset in enumerate(sets):
        per = [_by_replica(plan_rows(roots, c.name), i) for c in camps]
        packs = sorted(set.intersection(*(set(p) for p in per)))
        if len(packs) < 2:
            raise ValueError(f"order: {len(packs)} packings solved at every voxel of "
                             f"{st.stem} at {pset} (need 2)")
        k = np.array([[p[j] for p in per] for j in packs])
        fit = _one_order(np.array(st.voxels_um), k, s.voxel_um)
        lo, hi = fit["bias_interval"]
        points.append({"values": pset, "k_iso": k.tolist(), "packings": packs, **fit,
                       "sd": (hi - lo) / 2 / _Z})
    return {"formulation": st.formulation, "box_um": st.boxes_um[0], "seed": st.seed,
            "voxels_um": list(st.voxels_um), "design": design, "points": points}


def bias_at(order: Mapping[str, Any], values: Mapping[str, float]) -> tuple[float, float]:
    """The table voxel's relative bias and its sd at ``values`` (m^2 K/W): linear in the
    mean log10 of the resistances between the order study's points, held beyond them."""
    xs = np.array([np.mean([math.log10(v) for v in p["values"].values()])
                   for p in order["points"]])
    idx = np.argsort(xs)
    x = np.mean([math.log10(v) for v in values.values()])
    b = np.interp(x, xs[idx], [order["points"][j]["bias"] for j in idx])
    sd = np.interp(x, xs[idx], [order["points"][j]["sd"] for j in idx])
    return float(b), float(sd)


def tail_cut(plan: CorrectionPlan, system: str, roots: Sequence[str | Path],
             box: Mapping[str, Any]) -> dict[str, Any]:
    """The tail study of ``system``: per quantile its packings and change against the box
    study's packings at the same box (the table's cut); ``sd``: the finest quantile's change
    and its standard error in quadrature (not applied: an uncertainty)."""
    s = plan.system(system)
    st = s.studies["tail"]
    ref = next((b for b in box["boxes"] if b["box_um"] == st.boxes_um[0]), None)
    if ref is None:
        raise ValueError(f"tail: the box study has no run at {st.boxes_um[0]:g} um, the tail "
                         "study's box")
    out = []
    for q, camp in zip(st.quantiles, plan.study_campaigns(system, "tail")):
        k = np.array([v for _, v in sorted(_by_replica(plan_rows(roots, camp.name)).items())])
        if k.size < 2:
            raise ValueError(f"tail: {camp.name} has {k.size} packings solved (need 2)")
        out.append({"quantile": q, "k_iso": k.tolist(), "mean": float(k.mean()),
                    **_welch(np.array(ref["k_iso"]), k)})
    finest = min(out, key=lambda r: r["quantile"])
    return {"formulation": st.formulation, "box_um": st.boxes_um[0], "seed": st.seed,
            "reference_quantile": plan.cheap_rve.tail_quantile, "quantiles": out,
            "sd": float(math.hypot(finest["rel"], finest["se"]))}


def _key(values: Mapping[str, float]) -> tuple:
    return tuple(sorted((k, round(float(v) * 1e12)) for k, v in values.items()))


def _pooled_packing(tab: Mapping[tuple, Mapping[str, np.ndarray]]) -> tuple[float, int]:
    """The relative sd of one packing, pooled over formulations per design point and then
    over the design points (RMS), and its degrees of freedom (one design point's:
    the packings of one formulation are the same at every point)."""
    per_point: dict[tuple, list[tuple[float, int]]] = {}
    for (form, key), k in tab.items():
        if k.size >= 2:
            per_point.setdefault(key, []).append((float((k / k.mean()).var(ddof=1)),
                                                  k.size - 1))
    pooled = [sum(v * d for v, d in x) / sum(d for _, d in x) for x in per_point.values()]
    dof = min(sum(d for _, d in x) for x in per_point.values())
    return float(math.sqrt(np.mean(pooled))), int(dof)


def table_points(plan: CorrectionPlan, system: str, roots: Sequence[str | Path],
                 shared: Mapping[str, Any]) -> tuple[list[dict], dict[str, Any]]:
    """The design points of ``system``'s table whose every packing and cheap replica is
    solved (formulation, fractions, resistances, k per packing, cheap level, the box and
    voxel factors, ``c`` and its independent and shared relative uncertainties), and the
    pooled packing scatter (``packing_sd`` of one packing, ``packing_dof``)."""
    from itr_fv.materials.formulation_names import fractions_of

    table = plan.table_campaign(system)
    cheap = plan.cheap_campaign(system)
    tab: dict[tuple, np.ndarray] = {}
    values: dict[tuple, dict[str, float]] = {}
    for camp, want, store in ((table, plan.packings, tab), (cheap, CHEAP_REPLICAS, None)):
        got: dict[tuple, dict[int, float]] = {}
        sets = {f.name: camp.parameter_sets(f) for f in camp.formulations}
        for r in plan_rows(roots, camp.name):
            pset = sets[r["formulation"]][int(r["set_index"])]
            key = (r["formulation"], _key(pset))
            values[key] = pset
            got.setdefault(key, {})[int(r["replica"])] = float(r["k_iso"])
        full = {key: np.array([v for _, v in sorted(d.items())]) for key, d in got.items()
                if len(d) == want}
        if store is None:
            k_cheap = full
        else:
            store.update(full)
    s_pack, dof = _pooled_packing(tab)
    points = []
    for key in sorted(set(tab) & set(k_cheap)):
        k, kc = tab[key], k_cheap[key]
        b, sd_b = bias_at(shared["voxel"], values[key])
        f_box = shared["box"]["factor"]
        k0 = float(k.mean() * f_box / (1 + b))
        points.append({
            "formulation": key[0], "system": system,
            "fractions": fractions_of(key[0], plan.material), "values": values[key],
            "k_table_iso": k.tolist(), "k_table": float(k.mean()),
            "k_cheap_iso": kc.tolist(), "k_cheap": float(kc.mean()),
            "box_factor": f_box, "voxel_bias": b, "k_faithful": k0,
            "c": k0 / float(kc.mean()),
            "packing_sd": s_pack / math.sqrt(k.size), "packing_dof": dof,
            "shared_sd": float(math.sqrt(shared["box"]["sd"] ** 2 + sd_b ** 2
                                         + shared["tail"]["sd"] ** 2)),
            "shared_parts": {"box": shared["box"]["sd"], "voxel": sd_b,
                             "tail": shared["tail"]["sd"]}})
    return points, {"packing_sd": s_pack, "packing_dof": dof}


def design_columns(fit: Mapping[str, Any], fraction: np.ndarray | float,
                   columns: Mapping[str, np.ndarray], n: int, *,
                   own: bool = False) -> np.ndarray:
    """The design matrix (n, terms) of a system's fit (:func:`fit_system`; ``own``: the
    per-formulation quadratic, without the fraction terms) at the total filler fraction
    ``fraction`` and the resistance ``columns`` (m^2 K/W, clipped by the caller)."""
    names = fit["parameters"]
    xs = [np.log10(np.broadcast_to(np.asarray(columns[p], float), (n,)) / fit["R0"][p])
          for p in names]
    dphi = np.broadcast_to(np.asarray(fraction, float) - fit["phi0"], (n,))
    cols = [np.ones(n)] + ([] if own else [dphi]) + xs + [x ** 2 for x in xs]
    if len(xs) == 2:
        cols.append(xs[0] * xs[1])
    if not own:
        cols.append(dphi * sum(xs))
    return np.column_stack(cols)


def fit_system(points: list[dict], names: list[str]) -> dict[str, Any]:
    """Least-squares fit of ``c(phi, R)`` to a system's points (the module docstring's
    terms) and its range; needs two fractions at least."""
    fractions = sorted({round(sum(p["fractions"].values()), 6) for p in points})
    if len(fractions) < 2:
        raise ValueError(f"points: a fit over the fraction needs two fractions, got "
                         f"{fractions}")
    phi = np.array([sum(p["fractions"].values()) for p in points])
    fit: dict[str, Any] = {
        "parameters": names, "phi0": float(np.round(phi.mean(), 4)),
        "R0": {n: math.sqrt(min(p["values"][n] for p in points)
                            * max(p["values"][n] for p in points)) for n in names}}
    X = design_columns(fit, phi, {n: np.array([p["values"][n] for p in points])
                                  for n in names}, len(points))
    y = np.array([p["c"] for p in points])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ coef
    dof = max(len(y) - X.shape[1], 1)
    return {**fit, "coefficients": coef.tolist(),
            "fit_rms": float(math.sqrt(resid @ resid / dof)),
            "max_residual": float(np.abs(resid).max()),
            "fraction_range": [fractions[0], fractions[-1]],
            "R_range": {n: [min(p["values"][n] for p in points),
                            max(p["values"][n] for p in points)] for n in names},
            "packing_sd": float(np.sqrt(np.mean([p["packing_sd"] ** 2 for p in points]))),
            "packing_dof": int(min(p["packing_dof"] for p in points)),
            "voxel_bias": float(np.mean([p["voxel_bias"] for p in points]))}


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).resolve().parent, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def assemble(plan: CorrectionPlan, roots: Sequence[str | Path] | str | Path, *,
             provenance: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The shipped file's content from the finished campaigns of ``plan`` in the run
    folders ``roots``: per system its studies, points and fit (systems whose studies and
    table are complete enough), and the provenance (commit, date, contact law and film,
    boxes, voxels, seeds, studies, cheap RVE; ``provenance`` adds or replaces entries)."""
    roots = [roots] if isinstance(roots, (str, Path)) else list(roots)
    systems, points, missing = {}, [], {}
    for s in plan.systems:
        try:
            box = (box_step(plan, s.name, roots) if "boxes" in s.studies else
                   {"boxes": [], "steps": [], "converged_um": s.box_um,
                    "table_box_um": s.box_um, "factor": 1.0, "sd": BOX_RULE_SD,
                    "note": "no box study: the table box is the powders' rule"})
            tail = (tail_cut(plan, s.name, roots, box) if "tail" in s.studies else
                    {"quantiles": [], "sd": 0.0, "note": "no tail study"})
            shared = {"box": box, "voxel": voxel_order(plan, s.name, roots), "tail": tail}
            pts, pack = table_points(plan, s.name, roots, shared)
            fit = fit_system(pts, s.parameters)
        except (ValueError, KeyError, StopIteration) as exc:
            missing[s.name] = str(exc)
            continue
        points += pts
        systems[s.name] = {"fillers": sorted(pts[0]["fractions"]), "box_um": s.box_um,
                           "voxel_um": s.voxel_um, **fit, **pack, "shared": shared}
    film = plan.cheap_rve.film_um
    prov = {"plan": plan.name, "format": TABLE_FORMAT, "commit": _commit(),
            "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d"),
            "contacts": CONTACT_GEOMETRY,
            "film_um": plan.cheap_rve.min_gap_um if film is None else film,
            "boxes_um": {s.name: s.box_um for s in plan.systems},
            "voxels_um": {s.name: s.voxel_um for s in plan.systems},
            "packings": plan.packings,
            "seeds": [plan.seed + j for j in range(plan.packings)], "solver": plan.solver.key,
            "tol": plan.tol, "orders": {n: [{"values": p["values"], "order": p["order"],
                                             "order_interval": p["order_interval"]}
                                            for p in s["shared"]["voxel"]["points"]]
                                        for n, s in systems.items()},
            "cheap_rve": {**plan.cheap_rve.to_dict(), "replicas": CHEAP_REPLICAS,
                          "seeds": [plan.cheap_rve.seed + r for r in range(CHEAP_REPLICAS)],
                          "tol": CHEAP_TOL},
            "material_system": plan.material.to_dict(), "not_assembled": missing,
            **dict(provenance or {})}
    return {"provenance": prov, "systems": systems, "points": points}
