"""Interface resistances of a solve gathered from where a user states them: the command
line (``Al2O3-matrix=1e-8``), an identification's ``identified.json`` (its quoted values)
and a material-system file's ``[resistances]``; merged by one stated precedence.

A resistance belongs to a pair of phases, m^2 K/W: a filler and the matrix (``R_<A>_<B>``),
or two fillers whose particles touch (a per-area contact resistance, ``Rff_<A>_<B>``; a
filler with itself for two of its own particles). Contact-spot conductances (``Gc_``, W/K)
belong to the gap model's sphere geometry, which a label image does not have: they are
listed as not used.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from .parameters import parse_parameter

__all__ = ["parse_resistance", "resistances_from_identified", "resistances_from_system",
           "merge_resistances", "pair_of", "PRECEDENCE", "read_identified"]

#: Sources from the strongest to the weakest: a pair given by several takes the first's.
PRECEDENCE = ("command line", "identified", "system file")


def pair_of(name: str, matrix: str, *, argument: str = "resistance") -> tuple[str, str]:
    """The sorted phase pair of a flat ``R_`` or ``Rff_`` name; ValueError naming
    ``argument`` for another kind, an ``R_`` without the matrix or an ``Rff_`` with it."""
    try:
        kind, phases = parse_parameter(name)
    except ValueError as exc:
        raise ValueError(f"{argument}: {exc}") from None
    if kind not in ("R", "Rff"):
        raise ValueError(f"{argument}: {name} is a {kind} parameter, not a resistance")
    if (kind == "R") != (matrix in phases):
        raise ValueError(f"{argument}: {name}: R_ names a filler and the matrix ({matrix}), "
                         "Rff_ two fillers")
    return tuple(sorted(phases))  # type: ignore[return-value]


def _value(text: object, where: str, argument: str) -> float:
    try:
        v = float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(text, bool) or math.isnan(v) or v < 0:
        raise ValueError(f"{argument}: {where}: expected a resistance >= 0 (m^2 K/W) or inf, "
                         f"got {text!r}")
    return v


def parse_resistance(text: str, phases: Sequence[str], matrix: str, *,
                     argument: str = "resistance") -> tuple[tuple[str, str], float]:
    """``(sorted pair, value)`` of ``"A-B=VALUE"`` (``matrix`` may stand for the matrix;
    names holding ``-`` are matched against ``phases``) or ``"R_A_B=VALUE"``.

    Raises
    ------
    ValueError
        Naming ``argument``: no ``=``, an unknown phase, an ambiguous split, a value that
        is not >= 0.
    """
    key, sep, value = str(text).partition("=")
    key = key.strip()
    if not sep:
        raise ValueError(f"{argument}: expected PAIR=VALUE (Al2O3-matrix=1e-8), got {text!r}")
    if "_" in key:
        pair = pair_of(key, matrix, argument=argument)
    else:
        known = {*phases, "matrix"}
        splits = [(key[:i], key[i + 1:]) for i, c in enumerate(key) if c == "-"
                  and key[:i] in known and key[i + 1:] in known]
        if len(splits) != 1:
            raise ValueError(f"{argument}: {key!r} is not PHASE-PHASE of the phases "
                             f"{', '.join(phases)} (or matrix)" if not splits else
                             f"{argument}: {key!r} splits into phases in more than one way")
        a, b = (matrix if p == "matrix" else p for p in splits[0])
        if a == matrix and b == matrix:
            raise ValueError(f"{argument}: {key!r}: the matrix has no interface with itself")
        pair = tuple(sorted((a, b)))
    for p in pair:
        if p not in phases:
            raise ValueError(f"{argument}: {key!r}: {p!r} is not a phase of the image "
                             f"({', '.join(phases)})")
    return pair, _value(value.strip(), key, argument)  # type: ignore[return-value]


def read_identified(path: str | os.PathLike, *, argument: str) -> dict:
    """An ``identified.json`` of ``itr identify``/``reproduce`` as a dict, its headline of
    identified parameters checked; ValueError naming ``argument`` for a missing or
    unreadable file, one that is not JSON or one without that headline."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{argument}: no such file {str(p)!r}") from None
    except (json.JSONDecodeError, UnicodeDecodeError, IsADirectoryError) as exc:
        raise ValueError(f"{argument}: {str(p)!r} is not JSON ({exc})") from None
    except OSError as exc:
        raise ValueError(f"{argument}: cannot read {str(p)!r} ({exc})") from None
    head = data.get("headline") if isinstance(data, dict) else None
    if not isinstance(head, dict) or not isinstance(head.get("parameters"), dict):
        raise ValueError(f"{argument}: {str(p)!r} has no headline of identified parameters "
                         "(an itr identify or itr reproduce identified.json)")
    return data


def resistances_from_identified(path: str | os.PathLike, *, parametrisation: str | None = None,
                                argument: str = "resistances"
                                ) -> tuple[dict[str, float], str, list[str]]:
    """The quoted resistances of an ``identified.json`` (``itr identify``/``reproduce``):
    the headline's best value of every ``R_`` and ``Rff_`` parameter of the parametrisation
    the headline quotes (or ``parametrisation``).

    Returns
    -------
    values : dict of str to float
        Flat name -> m^2 K/W.
    parametrisation : str
        The one read (``"gap"`` or ``"area"``).
    skipped : list of str
        Parameters read and not used (``Gc_``: W/K, the gap model's sphere geometry).

    Raises
    ------
    ValueError
        Naming ``argument``: a missing file, not JSON, no headline, no such
        parametrisation.
    """
    p = Path(path)
    head = read_identified(p, argument=argument)["headline"]
    chosen = parametrisation or head.get("quote")
    table = head["parameters"].get(chosen)
    if not isinstance(table, dict):
        raise ValueError(f"{argument}: {str(p)!r} holds no parametrisation {chosen!r} (it "
                         f"holds {', '.join(head['parameters'])})")
    values, skipped = {}, []
    for name, entry in table.items():
        kind = parse_parameter(name)[0]
        if kind in ("R", "Rff"):
            values[name] = _value(entry.get("best"), name, argument)
        else:
            skipped.append(name)
    return values, str(chosen), skipped


def resistances_from_system(system) -> dict[str, float]:
    """The resistances a :class:`~itr_fv.materials.material_system.MaterialSystem` states
    as known (its file's ``[resistances]``), flat name -> m^2 K/W."""
    return dict(system.resistances)


def merge_resistances(sources: Sequence[tuple[str, Mapping[tuple[str, str], float]]]
                      ) -> dict[tuple[str, str], dict]:
    """One value per pair from ``sources`` ((name, {pair: value}) from the strongest to the
    weakest, :data:`PRECEDENCE`): per sorted pair ``value``, ``source`` and ``overridden``
    (the weaker sources' values, ``[{"source", "value"}]``)."""
    out: dict[tuple[str, str], dict] = {}
    for source, table in sources:
        for pair, value in table.items():
            key = tuple(sorted(pair))
            if key in out:
                out[key]["overridden"].append({"source": source, "value": float(value)})
            else:
                out[key] = {"value": float(value), "source": source, "overridden": []}
    return out
