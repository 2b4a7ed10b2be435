"""The handbook of common phases: typical conductivity, its published range and the density
of the fillers and matrices of thermal interface materials, each with its source
(``itr_fv/data/handbook.csv``; ``itr materials`` lists it).

A material-system file may name a phase without a value (:mod:`itr_fv.materials.system_file`):
the handbook's value becomes its nominal conductivity and the published range its prior,
a lognormal whose 90 % interval is the range (:func:`range_sd`).
"""

from __future__ import annotations

import csv
import difflib
import math
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources

__all__ = ["HandbookPhase", "handbook", "handbook_phase", "range_sd", "RANGE_QUANTILE_Z"]

#: A stated range is read as the 5-95 % interval of a lognormal: its half width in ln is
#: this many standard deviations.
RANGE_QUANTILE_Z = 1.6448536269514722


def range_sd(low: float, high: float) -> float:
    """Relative sd (of ln k) of a lognormal whose 90 % interval is ``low`` - ``high``."""
    return math.log(high / low) / (2.0 * RANGE_QUANTILE_Z)


@dataclass(frozen=True)
class HandbookPhase:
    """One phase of the handbook.

    Attributes
    ----------
    name, role : str
        Phase name and ``"filler"`` or ``"matrix"``.
    conductivity, low, high : float
        Typical conductivity and the published range, W/(m K).
    density : float
        Density, g/cm^3.
    conductivity_source, density_source, note : str
        Where the values come from; what the phase stands for.
    """

    name: str
    role: str
    conductivity: float
    low: float
    high: float
    density: float
    conductivity_source: str
    density_source: str
    note: str

    @property
    def relative_sd(self) -> float:
        """The prior's relative sd: the range as a 90 % interval (:func:`range_sd`)."""
        return range_sd(self.low, self.high)


@lru_cache(maxsize=1)
def handbook() -> dict[str, HandbookPhase]:
    """Phase name -> :class:`HandbookPhase`, as shipped."""
    text = resources.files("itr_fv").joinpath("data", "handbook.csv").read_text()
    out = {}
    for r in csv.DictReader(text.splitlines()):
        out[r["phase"]] = HandbookPhase(
            r["phase"], r["role"], float(r["k_W_per_mK"]), float(r["k_low_W_per_mK"]),
            float(r["k_high_W_per_mK"]), float(r["density_g_per_cm3"]), r["k_source"],
            r["density_source"], r["note"])
    return out


def handbook_phase(name: str, argument: str = "name") -> HandbookPhase:
    """The handbook's entry of ``name`` (letter case free); a ValueError naming
    ``argument``, with the closest names, where it has none."""
    book = handbook()
    folded = {k.casefold(): k for k in book}
    if isinstance(name, str) and name.casefold() in folded:
        return book[folded[name.casefold()]]
    near = difflib.get_close_matches(str(name).casefold(), list(folded), n=1, cutoff=0.6)
    hint = f"did you mean {folded[near[0]]!r}? " if near else ""
    raise ValueError(f"{argument}: {name!r} is not in the handbook of phases ({hint}known: "
                     f"{', '.join(sorted(book))}); give its conductivity_W_per_mK")
