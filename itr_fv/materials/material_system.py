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

__all__ = ["Filler", "MaterialSystem", "check_density", "check_relative_sd",
           "DENSITY_RANGE_G_PER_CM3"]


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
    conductivity_sd : float
        Relative standard deviation of the conductivity (its lognormal prior in the
        identification's intervals), in [0, 1); 0 holds it at :attr:`conductivity`.
    size_note : str
        How the size distribution was stated (``"lognormal mu/sigma, volume basis"``,
        ``"d10/d50/d90 (volume) fitted, misfit 1.2 %"``); for reports.
    """

    name: str
    conductivity: float
    psd: LogNormalPSD
    density: float | None = None
    conductivity_sd: float = 0.25
    size_note: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name: expected a phase name, got {self.name!r}")
        if not (isinstance(self.conductivity, (int, float))
                and math.isfinite(self.conductivity) and self.conductivity > 0):
            raise ValueError(f"conductivity: expected a value > 0 in W/(m K) for {self.name}, "
                             f"got {self.conductivity!r}")
        if self.density is not None:
            check_density(f"density of {self.name}", self.density)
        check_relative_sd(f"conductivity_sd of {self.name}", self.conductivity_sd)


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


def check_relative_sd(name: str, value: object) -> float:
    """``value`` as a relative standard deviation in [0, 1); ValueError naming ``name``
    otherwise (an sd as large as its value leaves a conductivity free to be zero)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value < 0:
        raise ValueError(f"{name}: expected a relative standard deviation >= 0, got "
                         f"{value!r}")
    if value >= 1:
        raise ValueError(f"{name}: a relative sd of {value:g} is as large as the value "
                         "itself; give it relative to the value (0.1 for 10 %)")
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
    matrix_conductivity_sd : float
        Relative standard deviation of the matrix conductivity, in [0, 1).
    resistances : tuple of (flat name, value)
        Interface resistances the system states as known, ``R_<A>_<B>`` in m^2 K/W: held
        at these values, not identified.
    named : tuple of (name, ((filler, volume fraction), ...))
        Formulations the system names by a label of their own (the paper's Table 2:
        ``Al2O3-Hybrid-1``); any other is named by its composition (``ZnO-50``).
    name : str
        A label for reports (``"paper"``, or the system file's ``name``).
    source : str
        Where the system was read from (a file path, or the package's tables).
    """

    matrix: str
    matrix_conductivity: float
    fillers: tuple[Filler, ...]
    matrix_density: float | None = None
    matrix_conductivity_sd: float = 0.10
    resistances: tuple[tuple[str, float], ...] = ()
    named: tuple[tuple[str, tuple[tuple[str, float], ...]], ...] = ()
    name: str = "custom"
    source: str = ""

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
        check_relative_sd(f"conductivity_sd of {self.matrix}", self.matrix_conductivity_sd)

    @property
    def filler_names(self) -> tuple[str, ...]:
        """The fillers' names, in the system's order."""
        return tuple(f.name for f in self.fillers)

    @property
    def phases(self) -> tuple[str, ...]:
        """Matrix first, then the fillers."""
        return (self.matrix, *self.filler_names)

    def conductivity_sds(self) -> dict[str, float]:
        """Phase -> relative standard deviation of its conductivity, matrix first."""
        return {self.matrix: float(self.matrix_conductivity_sd),
                **{f.name: float(f.conductivity_sd) for f in self.fillers}}

    def named_formulations(self) -> dict[str, dict[str, float]]:
        """The formulations named by a label: name -> {filler: volume fraction}."""
        return {n: dict(parts) for n, parts in self.named}

    def solve_inputs(self) -> tuple:
        """What a full solve of this system depends on (conductivities, size
        distributions, known resistances): two systems equal here give the same solves."""
        return (self.matrix, float(self.matrix_conductivity),
                tuple((f.name, float(f.conductivity), f.psd.to_number()) for f in self.fillers),
                self.resistances)

    def to_dict(self) -> dict:
        """Plain JSON-able form, for reports and manifests (units in the keys)."""
        return {"name": self.name, "source": self.source,
                "matrix": {"name": self.matrix,
                           "conductivity_W_per_mK": float(self.matrix_conductivity),
                           "conductivity_sd": float(self.matrix_conductivity_sd),
                           "density_g_per_cm3": self.matrix_density},
                "fillers": [{"name": f.name, "conductivity_W_per_mK": float(f.conductivity),
                             "conductivity_sd": float(f.conductivity_sd),
                             "density_g_per_cm3": f.density,
                             "size": {"basis": f.psd.basis, "mu_ln_um": f.psd.mu,
                                      "sigma_ln": f.psd.sigma, "stated_as": f.size_note}}
                            for f in self.fillers],
                "resistances_m2K_per_W": dict(self.resistances),
                "named_formulations": self.named_formulations()}

    def filler(self, name: str) -> Filler:
        """The filler ``name`` (ValueError naming the known fillers)."""
        for f in self.fillers:
            if f.name == name:
                return f
        where = f" ({self.source})" if self.source else ""
        raise ValueError(f"filler: {name!r} is not in the material system{where} (fillers: "
                         f"{', '.join(self.filler_names)})")

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
