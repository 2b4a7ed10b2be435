"""Designs of a campaign: which parameter sets to solve.

A design is an ordered list of parameter sets, each a mapping of the package's flat names
(:mod:`itr_fv.materials.parameters`) to values; names it leaves out keep the campaign's base values.

- :func:`grid`: the Cartesian product of value lists (the paper's Table 4 is one).
- :func:`points`: parameter sets listed one by one (a design that is no product, e.g.
  the diagonal and a few off-diagonal pairs of two resistances).
- :func:`table4`: the paper's Table 4 grid for the fillers of a formulation, from the
  shipped ``parameter_grid.csv``, under a contact model: with ``contact="area"`` the
  filler conductivity x particle-matrix x per-area contact resistance (5 x 8 x 8 = 320
  solves per single filler, as the paper); with the gap model the contact resistance is no
  parameter (5 x 8 = 40).
- :func:`space_filling`: a scaled Latin hypercube, log-uniform for resistances and
  contact conductances, uniform for conductivities, seeded.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np

from itr_fv.materials import paper_data
from itr_fv.materials.parameters import is_log_scaled, parameter_name, parse_parameter

__all__ = ["grid", "points", "table4", "space_filling", "TABLE4_HYBRID_K"]

#: Filler conductivities the paper fixes for the hybrids (W/(m K)).
TABLE4_HYBRID_K = {f: paper_data.paper_parameters()[parameter_name("k", f)]
                   for f in ("Al2O3", "AlN")}


def _check_names(names: Sequence[str], argument: str) -> None:
    for name in names:
        try:
            parse_parameter(name)
        except ValueError as exc:
            raise ValueError(f"{argument}: {exc}") from None


def grid(values: Mapping[str, Sequence[float]]) -> list[dict[str, float]]:
    """All combinations of the value lists, the first name varying slowest.

    Raises
    ------
    ValueError
        For a malformed name or an empty or non-numeric value list (naming it).
    """
    names = list(values)
    _check_names(names, "grid")
    lists = []
    for name in names:
        vals = values[name]
        if isinstance(vals, (str, bytes)) or not isinstance(vals, Sequence) or not vals:
            raise ValueError(f"grid: {name} needs a non-empty list of values")
        try:
            lists.append([float(v) for v in vals])
        except (TypeError, ValueError):
            raise ValueError(f"grid: {name} has a value that is not a number: {vals!r}") from None
    return [dict(zip(names, combo)) for combo in itertools.product(*lists)]


def points(sets: Sequence[Mapping[str, float]]) -> list[dict[str, float]]:
    """The listed parameter sets, in order; every set names the same parameters.

    Raises
    ------
    ValueError
        For an empty list, a set that is not a table of numbers, a malformed name, or sets
        that name different parameters (naming ``points`` and the set's index).
    """
    if isinstance(sets, (str, bytes, Mapping)) or not isinstance(sets, Sequence) or not sets:
        raise ValueError("points: expected a non-empty list of parameter sets")
    out: list[dict[str, float]] = []
    for i, entry in enumerate(sets):
        if not isinstance(entry, Mapping) or not entry:
            raise ValueError(f"points: set {i} is not a table of parameter = value")
        _check_names(list(entry), "points")
        try:
            one = {str(k): float(v) for k, v in entry.items()}
        except (TypeError, ValueError):
            raise ValueError(f"points: set {i} has a value that is not a number: "
                             f"{dict(entry)!r}") from None
        if out and sorted(one) != sorted(out[0]):
            raise ValueError(f"points: set {i} names {sorted(one)}, set 0 names "
                             f"{sorted(out[0])}")
        out.append(one)
    return out


def _table4_values() -> dict[str, list[float]]:
    out = {}
    for row in paper_data.read_table("parameter_grid"):
        out[row["parameter"]] = [float(v) for v in row["values"].split(";")]
    return out


def table4(fillers: Sequence[str], *, contact: str = "gap",
           matrix: str = "silicone") -> list[dict[str, float]]:
    """The paper's Table 4 grid for a formulation's fillers.

    Single filler: ``k_<filler>`` x ``R_<filler>_<matrix>`` (x ``Rff_<filler>_<filler>``
    with ``contact="area"``). Two fillers: conductivities fixed at :data:`TABLE4_HYBRID_K`
    (as the paper), both particle-matrix resistances (x the three per-area contact
    resistances with ``contact="area"``: 8^5 = 32768 sets, which the paper reduced to 2048
    by a sub-range it does not list; pass a sub-grid with :func:`grid` for that).
    """
    table = _table4_values()
    fillers = list(fillers)
    if not fillers or len(fillers) > 2:
        raise ValueError(f"fillers: Table 4 covers one or two fillers, got {fillers!r}")
    values: dict[str, list[float]] = {}
    if len(fillers) == 1:
        values[parameter_name("k", fillers[0])] = table[f"k_{fillers[0]}"]
    for f in fillers:
        values[parameter_name("R", f, matrix)] = table[f"R_{f}-silicone"]
    if contact == "area":
        for a, b in itertools.combinations_with_replacement(sorted(fillers), 2):
            values[parameter_name("Rff", a, b)] = table[f"R_{a}-{b}"]
    sets = grid(values)
    if len(fillers) == 2:
        for s in sets:
            s.update({parameter_name("k", f): TABLE4_HYBRID_K[f] for f in fillers})
    return sets


def space_filling(bounds: Mapping[str, Sequence[float]], n: int, seed: int
                  ) -> list[dict[str, float]]:
    """``n`` parameter sets of a scaled Latin hypercube over ``bounds`` ({name: (lo, hi)}).

    Resistances and contact conductances are sampled log-uniformly (they span decades),
    conductivities uniformly. The same seed gives the same sets.
    """
    from scipy.stats import qmc

    names = list(bounds)
    _check_names(names, "bounds")
    if not names:
        raise ValueError("bounds: give at least one parameter with its (lo, hi)")
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"n: expected a positive whole number of parameter sets, got {n!r}")
    lo, hi = [], []
    for name in names:
        pair = bounds[name]
        if isinstance(pair, (str, bytes)) or len(pair) != 2:
            raise ValueError(f"bounds: {name} needs (lo, hi), got {pair!r}")
        a, b = float(pair[0]), float(pair[1])
        log = is_log_scaled(name)
        if not (math.isfinite(a) and math.isfinite(b) and a < b and (a > 0 or not log)):
            raise ValueError(f"bounds: {name} needs finite lo < hi{' > 0' if log else ''}, "
                             f"got ({a:g}, {b:g})")
        lo.append(math.log10(a) if log else a)
        hi.append(math.log10(b) if log else b)
    unit = qmc.LatinHypercube(d=len(names), seed=np.random.default_rng(int(seed))).random(int(n))
    x = qmc.scale(unit, lo, hi)
    return [{name: float(10.0 ** v if is_log_scaled(name) else v)
             for name, v in zip(names, row)} for row in x]
