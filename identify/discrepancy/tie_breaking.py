"""What the data cannot tell apart, and the measurement that would.

:func:`tied_set` lists the models (the base model and the candidates) that explain the
measurements equally well when each is fitted with its resistances in
:attr:`~.settings.DiscrepancySettings.physical_r_m2K_per_W` and its value in its physical
range (the best plausible explanation of each): less than
:attr:`~.settings.DiscrepancySettings.bic_margin` behind the best in ``-2 ln L`` (the margin
that would name one: a model is ruled out by as much as another is named by), and, for a
candidate, with the values it allows within that margin (its profile within half the
margin of its maximum) reaching at least one grid step from nominal (an effect the data
allow, not only its absence). Where an effect is absorbed by the
resistances (filler conductivity, porosity, a fraction error on k alone), its candidate
and the base model sit in this set.

:func:`rank_measurements` simulates each auxiliary measurement the table lacks (density,
filler mass fraction, a thickness series, a second powder) from each tied model's best fit
with the stated noise (:attr:`~.settings.DiscrepancySettings.auxiliary_noise`), adds it
to the measurements noise-free (the expected data set), refits every tied model and takes
the BIC difference: the expected separation of the truth from each alternative. A
measurement decides the set when every ordered pair is separated by the BIC margin.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np

from .fit import Group, ModelFit, evaluate, fit_held_at, fit_physical, fit_present
from .observables import AuxGroup
from .outcome import DecidingMeasurement, Discrepancy
from .settings import DiscrepancySettings
from .tables import resistance_name

__all__ = ["DecidingMeasurement", "tied_set", "rank_measurements", "deciding_set",
           "unseparated", "MEASUREMENTS"]

#: The auxiliary measurements the workflow can propose: key -> what a lab does.
MEASUREMENTS = {
    "density": "the Archimedes density of every formulation",
    "mass_fraction": "the filler mass fraction (TGA ash content) of every formulation",
    "thickness": "every formulation at several thicknesses (the tester's Eq. 8)",
    "powder": "every formulation made again with a second powder of another size",
}

#: At most this many tied models are simulated (the most likely first).
MAX_TIED = 12


def _effect(d: Discrepancy, name: str):
    return None if name == "base" else next(e for e in d.effects if e.name == name)


def _plausible(m: ModelFit, d: Discrepancy, st: DiscrepancySettings) -> bool:
    if m.at_grid_edge:
        return False
    lo, hi = st.physical_r_m2K_per_W
    for g in d.groups:
        r = m.parameters[resistance_name(g.filler, st.system.matrix)]
        if not lo <= r <= hi:
            return False
    e = _effect(d, m.name)
    if e is not None and e.physical_range is not None:
        a, b = e.physical_range
        if not a - 1e-12 <= m.parameters[e.parameter] <= b * (1 + 1e-9):
            return False
    return True


def _reaches(m: ModelFit, d: Discrepancy) -> bool:
    """Whether the candidate's 90 % interval reaches one grid step away from nominal."""
    e = _effect(d, m.name)
    v = np.asarray(e.values, dtype=float)
    lo, hi = m.interval
    below, above = v[v < e.nominal], v[v > e.nominal]
    return bool((below.size and lo <= below.max() * (1 + 1e-9))
                or (above.size and hi >= above.min() * (1 - 1e-9)))


def tied_set(d: Discrepancy, st: DiscrepancySettings) -> list[ModelFit]:
    """The models the data cannot tell apart (see the module's text), best first, each
    fitted within its physical ranges; the winner alone where one is named."""
    if d.verdict == "named" and d.winner is not None:
        return [d.winner]
    if d.verdict == "tie" and d.winner is not None:
        return [d.winner] + [m for m in d.candidates if m is not d.winner
                             and m.bic - d.winner.bic < st.tie_margin
                             and _plausible(m, d, st)]
    models = [fit_physical(d.tables, d.groups, _effect(d, m.name), d.aux,
                           interval_drop=st.bic_margin / 2)
              for m in [d.base] + list(d.candidates)]
    pool = [m for m in models if m.log_likelihood > -1e299]
    best = min(-2 * m.log_likelihood for m in pool)
    out = [m for m in pool if -2 * m.log_likelihood - best < st.bic_margin
           and (m.name == "base" or (_reaches(m, d) and not _effect(d, m.name)
                                     .scales_resistance))]
    out.sort(key=lambda m: -m.log_likelihood)
    return out


def _available(d: Discrepancy) -> list[str]:
    have = {a.observable for a in d.aux}
    out = []
    if "density_g_per_cm3" not in have:
        out.append("density")
    if "filler_mass_fraction" not in have:
        out.append("mass_fraction")
    if len({g.thickness_m for g in d.groups if g.thickness_m is not None}) < 2:
        out.append("thickness")
    if all(g.scale == 1.0 for g in d.groups):
        out.append("powder")
    return out


def _describe(key: str, st: DiscrepancySettings) -> str:
    z = st.auxiliary_noise
    n = int(z["samples"])
    if key == "density":
        return f"{MEASUREMENTS[key]}, {n} samples at {100 * z['density_g_per_cm3']:g} % each"
    if key == "mass_fraction":
        return f"{MEASUREMENTS[key]}, {n} samples at +-{z['filler_mass_fraction']:g} each"
    if key == "thickness":
        return (f"{MEASUREMENTS[key]}: " + ", ".join(f"{t:g}" for t in z["thicknesses_mm"])
                + " mm, as many samples per thickness as the table has")
    return (f"{MEASUREMENTS[key]}: median {z['powder_scale']:g} times the first's, as many "
            "samples as the table has")


def _expected_data(key: str, d: Discrepancy, st: DiscrepancySettings, truth: ModelFit
                   ) -> tuple[list[Group], list[AuxGroup], list[tuple[str, float]]]:
    """The measurements with ``key`` added as ``truth`` predicts them (noise-free), and
    the predicted values (label, value)."""
    z = st.auxiliary_noise
    e = _effect(d, truth.name)
    groups, aux = list(d.groups), list(d.aux)
    forms = {}
    for g in d.groups:
        forms.setdefault(g.formulation, g)
    if key in ("density", "mass_fraction"):
        obs = "density_g_per_cm3" if key == "density" else "filler_mass_fraction"
        new = [AuxGroup(g.formulation, g.filler, g.fraction, obs, 1.0, 1.0, int(z["samples"]))
               for g in forms.values()]
        _, pred = evaluate(d.tables, e, truth.parameters, [], new)
        sd = z[obs]
        new = [replace(a, mean=float(p), standard_error=float(
            (sd * p if obs == "density_g_per_cm3" else sd) / math.sqrt(a.n)))
            for a, p in zip(new, pred)]
        return groups, aux + new, [(a.formulation, a.mean) for a in new]
    if key == "thickness":
        new = [replace(g, thickness_m=t * 1e-3) for g in d.groups if g.thickness_m is None
               for t in z["thicknesses_mm"]]
        k, _ = evaluate(d.tables, e, truth.parameters, new)
        new = [replace(g, mean=float(v), standard_error=g.standard_error / g.mean * float(v))
               for g, v in zip(new, k)]
        kept = [g for g in d.groups if g.thickness_m is not None]
        return kept + new, aux, [(g.label, g.mean) for g in new]
    s = float(z["powder_scale"])
    new = [replace(g, scale=s) for g in forms.values()]
    k, _ = evaluate(d.tables, e, truth.parameters, new)
    new = [replace(g, mean=float(v), standard_error=g.standard_error / g.mean * float(v))
           for g, v in zip(new, k)]
    return groups + new, aux, [(g.label, g.mean) for g in new]


def representative(m: ModelFit, d: Discrepancy) -> ModelFit:
    """The fit a tied candidate is simulated from: its best fit, or, where its best value
    lies within one grid step of nominal, its fit with the value held at the end of its
    90 % interval farthest from nominal (the largest effect the data allow)."""
    e = _effect(d, m.name)
    if e is None:
        return m
    v = np.asarray(e.values, dtype=float)
    best = m.parameters[e.parameter]
    step = np.min(np.abs(v[v != e.nominal] - e.nominal))
    if abs(best - e.nominal) >= step * (1 - 1e-9):
        return m
    lo, hi = m.interval
    end = lo if abs(lo - e.nominal) > abs(hi - e.nominal) else hi
    return fit_held_at(d.tables, d.groups, e, d.aux, at=end)


def _side(m: ModelFit, d: Discrepancy) -> int:
    """-1 or +1: the side of nominal the tied candidate's effect lies on (0: the base)."""
    e = _effect(d, m.name)
    if e is None:
        return 0
    return -1 if m.parameters[e.parameter] < e.nominal else 1


def _refit(d: Discrepancy, groups: list[Group], aux: list[AuxGroup], m: ModelFit, *,
           side: int) -> ModelFit:
    """The tied model ``m`` fitted to the expected data within its physical ranges, its
    effect held present on ``side`` of nominal (-1 or +1; 0: free)."""
    e = _effect(d, m.name)
    if side:
        return fit_present(d.tables, groups, e, aux, side=side)
    return fit_physical(d.tables, groups, e, aux)


def _pair_separation(sep: dict[tuple[str, str], float], a: str, b: str) -> float:
    """The expected BIC separation of one pair: where one is the base model, how far the
    base falls behind when the effect is true (a true base model can only pin the
    effect's value, never gain the margin over a model that nests it); else the smaller
    of the two directions, each alternative refitted with its effect present (a grid step
    or more from nominal), so that a measurement that would show an effect absent
    separates it."""
    if a == "base":
        return sep[(b, a)]
    if b == "base":
        return sep[(a, b)]
    return min(sep[(a, b)], sep[(b, a)])


def rank_measurements(d: Discrepancy, st: DiscrepancySettings
                      ) -> list[DecidingMeasurement]:
    """The auxiliary measurements the table lacks, ranked by the pairs of tied models
    (:attr:`Discrepancy.tied`) they are expected to separate by the BIC margin, then by
    their separations, best first."""
    tied = d.tied[:MAX_TIED]
    truths = {m.name: representative(m, d) for m in tied}
    sides = {n: _side(t, d) for n, t in truths.items()}
    out = []
    for key in _available(d):
        sep, outcomes = {}, {}
        for name, truth in truths.items():
            groups, aux, shown = _expected_data(key, d, st, truth)
            outcomes[name] = _few(shown)
            fits = {m.name: _refit(d, groups, aux, m,
                                   side=0 if m.name == name else sides[m.name])
                    for m in tied}
            for m in tied:
                if m.name != name:
                    sep[(name, m.name)] = float(fits[m.name].bic - fits[name].bic)
        pairs = {(a.name, b.name): _pair_separation(sep, a.name, b.name)
                 for i, a in enumerate(tied) for b in tied[i + 1:]}
        out.append(DecidingMeasurement(key, _describe(key, st), pairs, outcomes,
                                       st.bic_margin))
    out.sort(key=lambda x: (-x.separated, -x.score))
    return out


def _few(shown: list[tuple[str, float]]) -> list[tuple[str, float]]:
    """The first and last values (the lowest and highest filler fraction per filler)."""
    if len(shown) <= 4:
        return shown
    return [shown[0], shown[len(shown) // 2 - 1], shown[len(shown) // 2], shown[-1]]




def deciding_set(ranked: list[DecidingMeasurement]) -> list[DecidingMeasurement]:
    """The fewest measurements whose separated pairs together cover every pair of tied
    models that any of them separates (each separates its pairs on its own; taken together
    they can only separate more), the most separating set of that size, best first;
    empty where none separates any pair (:func:`unseparated` lists the pairs left)."""
    if not ranked:
        return []
    pairs = {p for p in ranked[0].separation
             if any(x.separation.get(p, -np.inf) >= x.margin for x in ranked)}
    if not pairs:
        return []
    for size in range(1, len(ranked) + 1):
        best = None
        for combo in itertools.combinations(ranked, size):
            union = {p for p in pairs if any(x.separation.get(p, -np.inf) >= x.margin
                                             for x in combo)}
            if union == pairs:
                score = sum(x.score for x in combo)
                if best is None or score > best[0]:
                    best = (score, list(combo))
        if best is not None:
            return best[1]
    return [ranked[0]]


def unseparated(ranked: list[DecidingMeasurement]) -> list[tuple[str, str]]:
    """The pairs of tied models no measurement separates."""
    if not ranked:
        return []
    return [p for p in ranked[0].separation
            if not any(x.separation.get(p, -np.inf) >= x.margin for x in ranked)]
