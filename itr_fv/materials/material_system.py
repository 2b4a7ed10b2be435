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
from dataclasses import dataclass, replace

from ..checks import slip_hint
from .psd import LogNormalPSD

__all__ = ["Filler", "MaterialSystem", "check_density", "DENSITY_RANGE_G_PER_CM3"]


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
    density : float, optional
        Bulk (skeletal) density, g/cm^3 (the density and filler mass fraction of a sample
        follow from it); None: not stated.
    """

    name: str
    conductivity: float
    psd: LogNormalPSD
    density: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name: expected a phase name, got {self.name!r}")
        if not (isinstance(self.conductivity, (int, float))
                and math.isfinite(self.conductivity) and self.conductivity > 0):
            raise ValueError(f"conductivity: expected a value > 0 in W/(m K) for {self.name}, "
                             f"got {self.conductivity!r}")
        if self.density is not None:
            check_density(f"density of {self.name}", self.density)


#: Densities a solid phase of a composite can have, g/cm^3 (a value outside is a unit slip:
#: kg/m^3 or a specific volume).
DENSITY_RANGE_G_PER_CM3 = (0.5, 25.0)


def check_density(name: str, value: object) -> float:
    """``value`` as a density in g/cm^3; ValueError naming ``name`` when it is not a finite
    number in :data:`DENSITY_RANGE_G_PER_CM3`."""
    lo, hi = DENSITY_RANGE_G_PER_CM3
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name}: expected a density > 0 in g/cm^3, got {value!r}")
    if not lo <= value <= hi:
        hint = slip_hint(value, (lo, hi), {"kg/m^3": 1e-3}, "g/cm^3")
        raise ValueError(f"{name}: {value:g} g/cm^3 is outside {lo:g} - {hi:g} g/cm^3, the "
                         f"range of a solid phase{'; ' + hint if hint else ''}")
    return float(value)


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
    matrix_density : float, optional
        Density of the matrix, g/cm^3 (None: not stated).
    """

    matrix: str
    matrix_conductivity: float
    fillers: tuple[Filler, ...]
    matrix_density: float | None = None

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
        if self.matrix_density is not None:
            check_density(f"density of {self.matrix}", self.matrix_density)

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

    def densities(self, fillers: Iterable[str] | None = None) -> dict[str, float]:
        """Phase -> density, g/cm^3, matrix first (of every filler or the named ones);
        ValueError naming a phase whose density is not stated."""
        names = [f.name for f in self.fillers] if fillers is None else list(fillers)
        out = {self.matrix: self.matrix_density,
               **{n: self.filler(n).density for n in names}}
        missing = [p for p, v in out.items() if v is None]
        if missing:
            raise ValueError(f"densities: the material system states no density of "
                             f"{', '.join(missing)} (g/cm^3)")
        return {p: float(v) for p, v in out.items()}

    def with_densities(self, densities: dict[str, float]) -> "MaterialSystem":
        """The same system with the phase densities of ``densities`` (phase -> g/cm^3)
        replaced; ValueError naming an unknown phase or a value that is no density."""
        known = [self.matrix] + [f.name for f in self.fillers]
        for p, v in densities.items():
            if p not in known:
                raise ValueError(f"densities: {p!r} is not a phase of this material system "
                                 f"(phases: {', '.join(known)})")
            check_density(f"density of {p}", v)
        fillers = tuple(replace(f, density=float(densities.get(f.name, f.density)))
                        if f.name in densities else f for f in self.fillers)
        return replace(self, fillers=fillers,
                       matrix_density=float(densities.get(self.matrix, self.matrix_density)))

    def size_distributions(self) -> dict[str, LogNormalPSD]:
        """Filler -> size distribution."""
        return {f.name: f.psd for f in self.fillers}

    def describe(self) -> str:
        """One line: ``silicone 0.18, Al2O3 30, AlN 200 W/(m K)``."""
        return ", ".join(f"{p} {k:g}" for p, k in self.conductivities().items()) + " W/(m K)"
