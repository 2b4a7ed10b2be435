"""The numerical error budget of an identification, per formulation and per resistance.

Every source of error of the forward model is given as a relative effect on k_iso at the
best point (per formulation), next to the measurement noise of that formulation's mean, and
as its effect on each identified resistance: a relative change ``delta`` of the model's
k_iso moves a resistance by the factor ``exp(-delta / s)``, ``s = d ln k / d ln R`` of the
formulations that identify it (their mean). The sources:

- in the likelihood (the 90 % intervals carry them): the measurement noise, the RVE-to-RVE
  scatter, the reduced basis's error bound and, at a fidelity level with faithful RVEs, the
  faithful correction's uncertainty (:mod:`itr_identify.forward.fidelity`);
- applied, not a source: the faithful correction itself (the box's cut of the coarse tail
  and the voxel's bias, removed by the faithful solves);
- outside the likelihood (the intervals do not carry them), from the package's own studies
  (``identify/data/numerical_studies.csv``, written by
  ``validation/numerical_studies_table.py``): the box effect beyond the box the level
  solves on (the largest box of the RVE-size study against it), the voxel bias where no
  correction removes it (the Al2O3-60 bias law), and the stated inputs: a 2 or 5 nm
  silicone film at contacts instead of none, Table 1 read as volume-weighted.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from functools import lru_cache
from importlib import resources

import numpy as np

from itr_fv.io import counted

from ..forward.fidelity import fidelity_name
from ..inference.calibrate import pooled_scatter, stages_of
from ..inference.pipeline import Identification

__all__ = ["error_budget", "error_budget_lines", "numerical_studies"]

#: Relative step of the resistance for d ln k / d ln R.
_STEP = 1.1


@lru_cache(maxsize=1)
def numerical_studies() -> tuple[dict, ...]:
    """Rows of ``identify/data/numerical_studies.csv``: system, quantity, box_um, voxel_um,
    value, unit, source."""
    text = resources.files("itr_identify").joinpath("data/numerical_studies.csv").read_text()
    rows = []
    for r in csv.DictReader(text.splitlines()):
        rows.append({**r, "box_um": float(r["box_um"]), "voxel_um": float(r["voxel_um"]),
                     "value": float(r["value"])})
    return tuple(rows)


def _system(fillers) -> str:
    return "hybrid" if len(fillers) > 1 else next(iter(fillers))


def _box_effect(system: str, box_um: float) -> tuple[float | None, str]:
    """Relative k_iso of the largest studied box over ``box_um``'s, and how it is known:
    from the large-box study (``k_iso_box_large``, 56-80 um) where it reaches ``box_um``,
    else from the RVE-size study (``k_iso_box``); the two are not mixed (other voxels)."""
    def rows(quantity: str) -> dict[float, float]:
        return {r["box_um"]: r["value"] for r in numerical_studies()
                if r["system"] == system and r["quantity"] == quantity}

    boxes = rows("k_iso_box_large")
    if not boxes or box_um < min(boxes):
        boxes = rows("k_iso_box")
    if not boxes:
        return None, "not studied"
    largest = max(boxes)
    if box_um >= largest:
        if len(boxes) < 2:
            return None, f"not measured: the study's largest box is {largest:g} um"
        prev = max(b for b in boxes if b < largest)
        return (boxes[largest] / boxes[prev] - 1,
                f"the last step studied, {prev:g} -> {largest:g} um, as the next one's "
                "estimate")
    if box_um in boxes:
        return boxes[largest] / boxes[box_um] - 1, f"{box_um:g} -> {largest:g} um"
    smaller = [b for b in boxes if b > box_um]
    b = min(smaller)
    return (boxes[largest] / boxes[b] - 1,
            f"at least: {b:g} -> {largest:g} um ({box_um:g} um not studied)")


def _input_effect(system: str, quantity: str) -> tuple[float | None, str]:
    vals = {r["system"]: r["value"] for r in numerical_studies() if r["quantity"] == quantity}
    if system in vals:
        return vals[system], f"{system}-60"
    if system == "hybrid" and vals:
        return float(np.mean(list(vals.values()))), "mean of the single-filler studies"
    return None, "not studied"


def _voxel_bias(voxel_um: float) -> tuple[float | None, str]:
    vals = {r["voxel_um"]: r["value"] for r in numerical_studies()
            if r["quantity"] == "voxel_bias"}
    for h, v in vals.items():
        if math.isclose(h, voxel_um, rel_tol=1e-9):
            return v, "Al2O3-60 bias law"
    return None, "no bias law at this voxel"


def _shipped_items(items: dict, m, best: Mapping[str, float]) -> float:
    """The shipped correction's entries of a formulation's budget; returns the converged box
    it corrects to, um."""
    fit = m.shipped.fit
    cols = {p: np.array([best[p]]) for p in m.parameters}
    parts = m.shipped.parts(cols, 1)
    sh = fit["shared"]
    box = sh["box"]
    items["faithful correction (applied)"] = {
        "value": float(parts["c"][0]) - 1, "in_likelihood": False,
        "basis": f"shipped ({m.shipped.system}): {fit['box_um']:g} um table box at "
                 f"{fit['voxel_um']:g} um, to the converged {box['converged_um']:g} um box and "
                 "no voxel bias, corrections.json"}
    items["of it: box step (applied)"] = {
        "value": box["factor"] - 1, "in_likelihood": False,
        "basis": f"box study, {box['table_box_um']:g} -> {box['converged_um']:g} um and larger"}
    items["of it: voxel bias removed (applied)"] = {
        "value": -fit["voxel_bias"], "in_likelihood": False,
        "basis": "the order study's bias at the table voxel, mean over the design"}
    items["correction uncertainty"] = {
        "value": float(math.hypot(parts["packing"][0], parts["interpolation"][0])),
        "in_likelihood": True,
        "basis": f"packings +-{100 * parts['packing'][0]:.1f} % ({parts['packing_dof']} dof, "
                 f"pooled), interpolation +-{100 * parts['interpolation'][0]:.1f} %"}
    items["correction uncertainty, shared"] = {
        "value": float(parts["shared"][0]), "in_likelihood": True,
        "basis": f"box step +-{100 * box['sd']:.1f} %, tail cut +-"
                 f"{100 * sh['tail']['sd']:.1f} %, voxel bias (its order's interval): one term "
                 "for every formulation of the system"}
    return float(box["converged_um"])


def _slope(model, best: Mapping[str, float], p: str) -> float:
    """d ln k / d ln R_p of the model at ``best`` (central difference, factor 1.1)."""
    up = {q: np.array([best[q] * (_STEP if q == p else 1.0)]) for q in model.parameters}
    dn = {q: np.array([best[q] / (_STEP if q == p else 1.0)]) for q in model.parameters}
    return float(math.log(model.predict(up)[0][0] / model.predict(dn)[0][0])
                 / (2 * math.log(_STEP)))


def error_budget(ident: Identification) -> dict:
    """The budget as JSON-ready data: ``formulations`` (per formulation: the relative
    effects on k_iso, each with ``value``, ``in_likelihood`` and ``basis``), ``parameters``
    (per identified resistance: d ln k / d ln R and each effect as a factor on R, the 90 %
    interval's half-width as a factor), ``dominant`` and ``numerical_below_noise``."""
    post, s = ident.posterior, ident.settings
    best = ident.at_nominal.best          # the models' own inputs: where they predict
    faithful = s.faithful if ident.parametrisation == "gap" else None
    forms: dict[str, dict] = {}
    for stage in stages_of(ident.models):
        scatter = pooled_scatter([ident.models[f] for f in stage.formulations])
        for f in stage.formulations:
            forms[f] = _formulation_budget(ident, f, scatter=scatter, best=best)
    params: dict[str, dict] = {}
    prior_width = math.log(post.prior[1] / post.prior[0])
    for p in post.names:
        using = [f for f, d in forms.items() if p in d["slopes"]]
        if using:
            params[p] = _parameter_budget(p, forms, using, post, prior_width=prior_width)
    below = {f: d["numerical_rss"] < d["items"]["measurement noise"]["value"]
             for f, d in forms.items()}
    level = fidelity_name(s.faithful)
    if s.faithful is not None and faithful is None:
        level += " (not applied to the area parametrisation)"
    return {"fidelity": level,
            "formulations": forms, "parameters": params, "dominant": _dominant(params),
            "numerical_below_noise": below}


#: The budget's entries that are numerical errors of the model (summed in quadrature as a
#: formulation's ``numerical_rss``).
_NUMERICAL = ("RVE scatter", "surrogate error", "correction uncertainty",
              "correction uncertainty, shared", "voxel bias (not corrected)",
              "box effect beyond the box solved")
#: The entries that are standard deviations (a factor of +1 sd on a resistance).
_SDS = ("measurement noise", "RVE scatter", "surrogate error", "correction uncertainty",
        "correction uncertainty, shared")


def _formulation_budget(ident: Identification, f: str, *, scatter: float,
                        best: Mapping[str, float]) -> dict:
    """One formulation's entry of the budget at the parameters ``best`` (m^2 K/W): its
    system, k_iso, the relative effects on k_iso (``items``), their numerical part summed
    in quadrature and d ln k / d ln R per parameter; ``scatter`` is the RVE scatter pooled
    over its stage."""
    s, m, meas = ident.settings, ident.models[f], ident.measurements
    k, err = m.predict({p: np.array([best[p]]) for p in m.parameters})
    system = _system(m.fractions)
    items: dict[str, dict] = {
        "measurement noise": {"value": meas.standard_error(f) / meas.mean(f),
                              "in_likelihood": True, "basis": "standard error of the "
                              "mean of the replicates"},
        "RVE scatter": {"value": scatter, "in_likelihood": True,
                        "basis": f"{s.replicas} packings of {s.box_um:g} um"},
        "surrogate error": {"value": float(err[0] / k[0]), "in_likelihood": True,
                            "basis": "reduced basis's certified bound"},
    }
    box = _level_items(items, m, best, settings=s)
    if m.correction is None and m.shipped is not None:
        eff, basis = 0.0, (f"corrected to the converged {box:g} um box; what the box "
                           "study resolves of the step is in the shared term")
    else:
        eff, basis = _box_effect(system, box)
    items["box effect beyond the box solved"] = {"value": eff, "in_likelihood": False,
                                                 "basis": basis}
    for name, q in (("film 2 nm", "film_2nm"), ("film 5 nm", "film_5nm"),
                    ("Table 1 volume-weighted", "psd_volume")):
        v, basis = _input_effect(system, q)
        items[name] = {"value": v, "in_likelihood": False, "basis": basis}
    numerical = [items[n]["value"] for n in _NUMERICAL
                 if n in items and items[n]["value"] is not None]
    return {"system": system, "k_iso": float(k[0]), "items": items,
            "numerical_rss": float(math.hypot(*numerical)) if numerical else 0.0,
            "slopes": {p: _slope(m, best, p) for p in m.parameters}}


def _level_items(items: dict, m, best: Mapping[str, float], *, settings) -> float:
    """The entries of a formulation's budget that its fidelity level makes (a runtime
    faithful correction, a shipped one, or the voxel bias no correction removes), added to
    ``items``; returns the box the level's k belongs to, um."""
    corr = m.correction
    if corr is not None:
        items["faithful correction (applied)"] = {
            "value": corr.factor - 1, "in_likelihood": False,
            "basis": f"{corr.box_um:g} um box at {corr.voxel_um:g}/"
                     f"{corr.coarse_voxel_um:g} um, {len(corr.seeds)} packings"}
        items["of it: voxel bias removed (applied)"] = {
            "value": -corr.voxel_bias, "in_likelihood": False,
            "basis": f"Richardson, p = {corr.order:.2f}"}
        items["correction uncertainty"] = {
            "value": corr.relative_sd, "in_likelihood": True,
            "basis": "faithful packings' scatter and the bias order's uncertainty"}
        return corr.box_um
    if m.shipped is not None:
        return _shipped_items(items, m, best)
    bias, basis = _voxel_bias(settings.voxel_um)
    items["voxel bias (not corrected)"] = {
        "value": None if bias is None else -bias, "in_likelihood": False, "basis": basis}
    return settings.box_um


def _parameter_budget(p: str, forms: Mapping[str, dict], using: list[str], post, *,
                      prior_width: float) -> dict:
    """One resistance's entry of the budget: d ln k / d ln R over the formulations
    ``using`` that identify it (their mean), each effect as a factor on R (None where an
    effect is unknown, k does not move with R, or it would move R beyond the prior's whole
    width ``prior_width``, natural log; those listed in ``beyond_prior``) and the 90 %
    interval's half-width as a factor."""
    slope = float(np.mean([forms[f]["slopes"][p] for f in using]))
    lo, hi = post.interval(p)
    factors: dict[str, float | None] = {}
    beyond: list[str] = []
    for name in forms[using[0]]["items"]:
        vals = [forms[f]["items"][name]["value"] for f in using]
        if any(v is None for v in vals) or abs(slope) < 1e-6:
            factors[name] = None
            continue
        delta = float(np.mean(vals))
        if name in _SDS:
            delta = -abs(delta)  # a standard deviation: shown as the factor of +1 sd
        # an effect that would move R beyond the prior's whole width says only that:
        # the model cannot turn it into a factor (k barely moves with R there)
        factors[name] = (math.exp(-delta / slope) if abs(delta / slope) <= prior_width
                         else None)
        if factors[name] is None:
            beyond.append(name)
    return {"formulations": using, "dlnk_dlnR": slope,
            "interval_half_width_factor": math.sqrt(hi / lo), "factors": factors,
            "beyond_prior": beyond}


def _dominant(params: Mapping[str, dict]) -> list[str]:
    """The three effects (not the applied corrections) that move a resistance most, by
    their largest factor over the resistances."""
    ranked: dict[str, float] = {}
    for d in params.values():
        for name, fct in d["factors"].items():
            if fct is not None and "applied" not in name:  # applied: not an error
                ranked[name] = max(ranked.get(name, 0.0), abs(math.log(fct)))
    return sorted(ranked, key=ranked.get, reverse=True)[:3]


def _pct(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:+.1f} %"


def error_budget_lines(ident: Identification, budget: dict | None = None) -> list[str]:
    """The budget as Markdown: per formulation the effects on k_iso, then per resistance
    the factors, and the verdict."""
    b = budget or error_budget(ident)
    forms = b["formulations"]
    names = list(next(iter(forms.values()))["items"])
    lines = [f"Error budget, {ident.parametrisation} parametrisation (fidelity "
             f"`{b['fidelity']}`): relative effect on k_iso at the best point; `*` marks "
             "what the likelihood (and so the 90 % interval) carries; +-values are standard "
             "deviations, signed values are shifts the model would see if the effect were "
             "taken in.", "",
             "| formulation | " + " | ".join(n + (" *" if forms[next(iter(forms))]["items"][n]
                                                    ["in_likelihood"] else "")
                                             for n in names) + " | numerical (rss) |",
             "|" + "---|" * (len(names) + 2)]
    for f, d in forms.items():
        cells = []
        for n in names:
            it = d["items"][n]
            v = it["value"]
            cells.append("n/a" if v is None else (f"+-{100 * abs(v):.1f} %"
                                                   if it["in_likelihood"] else _pct(v)))
        lines.append(f"| {f} | " + " | ".join(cells) + f" | {100 * d['numerical_rss']:.1f} % |")
    lines += ["", "| resistance | d ln k / d ln R | 90 % interval (x/÷) | " +
              " | ".join(n for n in names) + " |", "|" + "---|" * (len(names) + 3)]
    for p, d in b["parameters"].items():
        cells = ["n/a" if d["factors"][n] is None else f"x{d['factors'][n]:.2f}"
                 for n in names]
        lines.append(f"| {p} | {d['dlnk_dlnR']:.3f} | {d['interval_half_width_factor']:.2f} | "
                     + " | ".join(cells) + " |")
    n_below = sum(b["numerical_below_noise"].values())
    lines += ["", f"Largest effects on the resistances: {', '.join(b['dominant'])}. The "
              f"numerical error (RVE scatter, surrogate, correction, uncorrected voxel bias, "
              f"box beyond the box solved, in quadrature) is below the measurement noise in "
              f"{n_below} of {counted(len(forms), 'formulation')}."]
    first_of = {}
    for f, d in forms.items():
        first_of.setdefault(d["system"], f)
    for system, f in first_of.items():
        lines.append(f"- bases for {system}: " + "; ".join(
            f"{n}: {forms[f]['items'][n]['basis']}" for n in names) + ".")
    return lines
