"""Formulation names and their composition: a Table 2 name, or ``<filler>-<vol%>`` and
``<filler>-<vol%>-<filler>-<vol%>`` (e.g. ``Al2O3-62``, ``Al2O3-30-AlN-30``).

The numbers are percent: a part below :data:`MIN_PERCENT` (``Al2O3-0.55``) reads as a
volume fraction written where a percentage belongs, and is refused.
"""

from __future__ import annotations

import re

from itr_fv import paper_data

__all__ = ["fractions_of", "MIN_PERCENT"]

#: Smallest filler part a name may give, vol%: below it a 12 um RVE holds about one
#: particle, and a value such as 0.55 is a fraction meant as 55 %.
MIN_PERCENT = 1.0

_PART = re.compile(r"^(Al2O3|AlN)-(\d+(?:\.\d+)?)$")


def fractions_of(name: str) -> dict[str, float]:
    """Filler volume fractions (0-1) of a formulation name (Table 2 or ``<filler>-<vol%>``
    pairs); ValueError naming the formulation otherwise."""
    table2 = paper_data.formulations()
    if name in table2:
        return dict(table2[name])
    parts = name.split("-")
    out: dict[str, float] = {}
    for i in range(0, len(parts) - 1, 2):
        m = _PART.match(f"{parts[i]}-{parts[i + 1]}")
        if m is None or m.group(1) in out:
            break
        percent = float(m.group(2))
        if 0 < percent < MIN_PERCENT:
            raise ValueError(f"formulation {name!r}: {m.group(1)} at {percent:g} vol% looks "
                             f"like a volume fraction; the names give percent "
                             f"({m.group(1)}-{100 * percent:g} for {100 * percent:g} vol%)")
        out[m.group(1)] = percent / 100
    else:
        if out and len(parts) % 2 == 0 and 0 < sum(out.values()) < 0.7:
            return out
    raise ValueError(f"formulation {name!r}: expected a Table 2 name or <filler>-<vol%> "
                     "pairs of Al2O3 and AlN (e.g. Al2O3-62, Al2O3-30-AlN-30), below 70 vol% "
                     "in all")
