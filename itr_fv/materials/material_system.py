"""A material system: the matrix and the fillers a composite is made of, with their
nominal conductivities and size distributions.

The paper's system is :data:`itr_fv.materials.paper_data.PAPER_SYSTEM` (read from the shipped data);
a user's own system is built the same way. Everything that needs a phase conductivity or
a filler's size distribution by default reads it from a :class:`MaterialSystem`, and
reports print the system they used.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from .psd import LogNormalPSD

__all__ = ["Filler", "MaterialSystem"]


@dataclass(frozen=True)
class Filler:
    """One filler of a material system.

    Attributes
    ----------
    name : str
        Phase name (as in :class:`~itr_fv.materials.Materials`).
    conductivity : float
        Nominal bulk conductivity, W/(m K).
    psd : LogNormalPSD
        Size distribution of the diameters (ln(D / 1 um)).
    """

    name: str
    conductivity: float
    psd: LogNormalPSD

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name: expected a phase name, got {self.name!r}")
        if not (isinstance(self.conductivity, (int, float))
                and math.isfinite(self.conductivity) and self.conductivity > 0):
            raise ValueError(f"conductivity: expected a value > 0 in W/(m K) for {self.name}, "
                             f"got {self.conductivity!r}")


@dataclass(frozen=True)
class MaterialSystem:
    """Matrix and fillers with their nominal conductivities and size distributions.

    Attributes
    ----------
    matrix : str
        Name of the matrix phase.
    matrix_conductivity : float
        Nominal conductivity of the matrix, W/(m K).
    fillers : tuple of Filler
        The fillers, each named once.
    """

    matrix: str
    matrix_conductivity: float
    fillers: tuple[Filler, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.matrix, str) or not self.matrix:
            raise ValueError(f"matrix: expected a phase name, got {self.matrix!r}")
        k = self.matrix_conductivity
        if not (isinstance(k, (int, float)) and math.isfinite(k) and k > 0):
            raise ValueError(f"matrix_conductivity: expected a value > 0 in W/(m K), got {k!r}")
        names = [f.name for f in self.fillers]
        if len(set(names)) != len(names) or self.matrix in names:
            raise ValueError(f"fillers: each filler once and none named as the matrix, got "
                             f"{names} with matrix {self.matrix!r}")

    def filler(self, name: str) -> Filler:
        """The filler ``name`` (ValueError naming the known fillers)."""
        for f in self.fillers:
            if f.name == name:
                return f
        raise ValueError(f"filler: {name!r} is not in this material system (fillers: "
                         f"{[f.name for f in self.fillers]})")

    def conductivities(self, fillers: Iterable[str] | None = None) -> dict[str, float]:
        """Phase -> nominal conductivity, W/(m K), matrix first: of every filler, or of the
        named ``fillers`` only."""
        names = [f.name for f in self.fillers] if fillers is None else list(fillers)
        return {self.matrix: float(self.matrix_conductivity),
                **{n: float(self.filler(n).conductivity) for n in names}}

    def size_distributions(self) -> dict[str, LogNormalPSD]:
        """Filler -> size distribution."""
        return {f.name: f.psd for f in self.fillers}

    def describe(self) -> str:
        """One line: ``silicone 0.18, Al2O3 30, AlN 200 W/(m K)``."""
        return ", ".join(f"{p} {k:g}" for p, k in self.conductivities().items()) + " W/(m K)"
