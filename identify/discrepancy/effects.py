"""Candidate physical effects a calibrated model may lack, each an extension of the RVE model.

Every candidate has one physical parameter, a nominal value at which the base model is
recovered exactly, a grid of values on which the discrepancy workflow
(:mod:`itr_identify.discrepancy`) solves the full model, the signature it leaves in the data and
the measurement that separates it from its look-alikes. Three kinds:

- *material*: a phase conductivity changes (matrix off nominal, filler below nominal);
- *geometry*: the voxel image changes (air voids added to the matrix, filler particles
  removed); the image at a larger parameter value contains the one at a smaller value
  (voids are drawn once and taken in order, particles removed in one random order), so the
  conductivity is a smooth function of the parameter and not a new RVE draw per value;
- *measurement*: the tester's reading (a contact resistance left in an apparent
  conductivity measured at one thickness).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from itr_fv import Materials, Microstructure
from itr_fv.paper_data import PAPER_SYSTEM

__all__ = ["Effect", "MatrixConductivity", "FillerConductivity", "Porosity",
           "FillerFraction", "ContactSpots", "TesterContact", "default_effects", "by_key",
           "AIR", "AIR_CONDUCTIVITY"]

AIR = "air"
#: Conductivity of the air in voids, W/(m K).
AIR_CONDUCTIVITY = 0.026


@dataclass(frozen=True)
class Effect:
    """One candidate effect (a base class: each subclass overrides one of
    :meth:`materials`, :meth:`microstructure`, :meth:`apparent`).

    Attributes
    ----------
    key : str
        Short name (command line: ``--effects``).
    name : str
    parameter : str
        Name of its parameter (with the unit in it).
    nominal : float
        The value at which the model is the base model.
    values : tuple of float
        Grid on which the full model is solved (the nominal value among them); the
        workflow interpolates between them and does not extrapolate.
    signature : str
        The pattern it leaves in the residuals.
    separate_by : str
        The measurement that tells it apart from the effects of the same signature.
    kind : {"material", "geometry", "measurement"}
    log_scale : bool
        Interpolate (and calibrate) in the logarithm of the parameter.
    """

    key: str
    name: str
    parameter: str
    nominal: float
    values: tuple[float, ...]
    signature: str
    separate_by: str
    kind: str = "material"
    log_scale: bool = False

    def __post_init__(self) -> None:
        v = np.asarray(self.values, dtype=float)
        if v.size < 3 or np.any(np.diff(v) <= 0) or not np.all(np.isfinite(v)):
            raise ValueError(f"values: the grid of {self.name!r} must hold at least 3 finite, "
                             f"increasing values, got {self.values!r}")
        if not v[0] <= self.nominal <= v[-1]:
            raise ValueError(f"nominal: {self.nominal!r} lies outside the grid of "
                             f"{self.name!r} ({v[0]!r}..{v[-1]!r})")

    @property
    def needs_thickness(self) -> bool:
        """Whether the effect can only be seen in measurements at several thicknesses."""
        return False

    def materials(self, base: Materials, value: float) -> Materials:
        """Phase values under the effect (default: unchanged)."""
        return base

    def microstructure(self, base: Microstructure, value: float, seed: int) -> Microstructure:
        """The RVE under the effect (default: unchanged)."""
        return base

    def apparent(self, k: np.ndarray, thickness_m: np.ndarray, value: float) -> np.ndarray:
        """The conductivity the tester reports for a sample of conductivity ``k``
        (default: ``k``)."""
        return k

    def describe(self) -> dict:
        return {"key": self.key, "name": self.name, "parameter": self.parameter,
                "nominal": self.nominal,
                "grid": list(self.values), "kind": self.kind, "signature": self.signature,
                "separate_by": self.separate_by}


@dataclass(frozen=True)
class MatrixConductivity(Effect):
    """The matrix (silicone with its 4 vol% coupling agent) off its nominal conductivity
    (the material system's: 0.18 W/(m K) for the paper's), from half to twice it."""

    key: str = "matrix"
    name: str = "matrix conductivity off nominal"
    parameter: str = "k_matrix_W_per_mK"
    nominal: float = PAPER_SYSTEM.matrix_conductivity
    values: tuple[float, ...] = tuple(f * PAPER_SYSTEM.matrix_conductivity
                                      for f in (0.5, 0.75, 1.0, 1.5, 2.0))
    signature: str = ("every formulation shifts the same way; the relative shift is largest "
                      "at the lowest filler fraction and the same for both fillers")
    separate_by: str = ("the conductivity of the neat matrix (silicone + coupling agent) "
                        "and the sample density (voids lower k the same way)")

    def materials(self, base: Materials, value: float) -> Materials:
        return base.with_values(conductivity={base.matrix: float(value)})


@dataclass(frozen=True)
class FillerConductivity(Effect):
    """Every filler's intrinsic conductivity times a factor below 1 (impurities, grain
    boundaries, amorphous surface layers)."""

    key: str = "filler"
    name: str = "filler conductivity below nominal"
    parameter: str = "filler_conductivity_factor"
    nominal: float = 1.0
    values: tuple[float, ...] = (0.05, 0.1, 0.2, 0.4, 0.7, 1.0)
    signature: str = ("the loss grows with the filler fraction (conduction through "
                      "particle chains) and is larger for the more conductive filler")
    separate_by: str = ("laser-flash diffusivity of the filler powder compact, or a "
                        "particle-size series (an interface resistance matters more for "
                        "small particles, the intrinsic conductivity does not)")
    kind: str = "material"
    log_scale: bool = True

    def materials(self, base: Materials, value: float) -> Materials:
        k = {p: v * float(value) for p, v in base.conductivity.items() if p != base.matrix}
        return base.with_values(conductivity=k)


@dataclass(frozen=True)
class Porosity(Effect):
    """Air voids (k = 0.026 W/(m K)) in the matrix: spheres of :attr:`pore_diameter_um`
    placed at random where they touch no particle, up to the void volume fraction."""

    key: str = "porosity"
    name: str = "porosity (air voids)"
    parameter: str = "void_fraction"
    nominal: float = 0.0
    values: tuple[float, ...] = (0.0, 0.006, 0.012, 0.018, 0.024)
    signature: str = ("like a matrix of lower conductivity: every formulation lower, "
                      "relatively most at the lowest filler fraction")
    separate_by: str = "the sample density against the mixture's (Archimedes) or micro-CT"
    kind: str = "geometry"
    pore_diameter_um: float = 1.0

    def materials(self, base: Materials, value: float) -> Materials:
        if AIR in base.conductivity:
            return base
        k = {**base.conductivity, AIR: AIR_CONDUCTIVITY}
        r = dict(base.resistance)
        r[(AIR, base.matrix)] = 0.0            # a void is bounded by the matrix itself
        for p in base.conductivity:
            if p != base.matrix:
                r[(AIR, p)] = base.resistance_between(p, base.matrix)
        return Materials(k, r, base.matrix, contact=base.contact,
                         contact_conductance=base.contact_conductance)

    def microstructure(self, base: Microstructure, value: float, seed: int) -> Microstructure:
        if value <= 0:
            return base
        t = base.particles
        if t is None:
            raise ValueError("microstructure: porosity needs the sphere geometry "
                             "(Microstructure.from_spheres or generate_rve)")
        box = np.array(base.material_ids.shape) * base.voxel_m
        voids = _void_centres(t.centers_m, t.radii_m, box, self.pore_diameter_um * 1e-6 / 2,
                              float(self.values[-1]), seed)
        r = self.pore_diameter_um * 1e-6 / 2
        n = int(round(value * np.prod(box) / (4 / 3 * math.pi * r ** 3)))
        if n > len(voids):
            raise RuntimeError(f"porosity: room for {len(voids)} voids of "
                               f"{self.pore_diameter_um} um, {n} needed for {value}")
        c = np.vstack([t.centers_m, voids[:n]])
        radii = np.concatenate([t.radii_m, np.full(n, r)])
        mats = list(t.material) + [AIR] * n
        return Microstructure.from_spheres(c, radii, mats, box, base.material_ids.shape,
                                           matrix=base.names[0])


def _void_centres(centres: np.ndarray, radii: np.ndarray, box: np.ndarray, r: float,
                  fraction: float, seed: int, attempts: int = 400_000) -> np.ndarray:
    """Random sequential addition of voids of radius ``r`` in the periodic ``box``, clear of
    the spheres and of each other by a tenth of ``r``, until ``fraction``."""
    rng = np.random.default_rng(seed)
    target = int(math.ceil(fraction * np.prod(box) / (4 / 3 * math.pi * r ** 3)))
    margin = 0.05 * r
    out: list[np.ndarray] = []
    cand = rng.uniform(0, 1, size=(attempts, 3)) * box
    for x in cand:
        d = centres - x
        d -= box * np.round(d / box)
        if np.any(np.einsum("ij,ij->i", d, d) < (radii + r + margin) ** 2):
            continue
        if out:
            e = np.array(out) - x
            e -= box * np.round(e / box)
            if np.any(np.einsum("ij,ij->i", e, e) < (2 * r + margin) ** 2):
                continue
        out.append(x)
        if len(out) >= target:
            break
    return np.array(out).reshape(-1, 3)


@dataclass(frozen=True)
class FillerFraction(Effect):
    """Less filler than nominal (losses in mixing, settling, or the coupling agent counted
    as filler volume): particles removed from the nominal packing in one random order
    until the fraction is the factor times nominal."""

    key: str = "fraction"
    name: str = "filler fraction below nominal"
    parameter: str = "filler_fraction_factor"
    nominal: float = 1.0
    values: tuple[float, ...] = (0.8, 0.85, 0.9, 0.95, 1.0)
    signature: str = ("a loss that grows steeply with the fraction (k rises steeply near "
                      "the packing limit); the same factor for both fillers")
    separate_by: str = "ash content (TGA) or the sample density"
    kind: str = "geometry"

    def microstructure(self, base: Microstructure, value: float, seed: int) -> Microstructure:
        if value >= 1.0:
            return base
        t = base.particles
        if t is None:
            raise ValueError("microstructure: a fraction change needs the sphere geometry")
        vol = t.radii_m ** 3
        order = np.random.default_rng(seed).permutation(len(vol))
        removed = np.cumsum(vol[order]) <= (1 - value) * vol.sum()
        keep = np.ones(len(vol), dtype=bool)
        keep[order[removed]] = False
        box = np.array(base.material_ids.shape) * base.voxel_m
        return Microstructure.from_spheres(t.centers_m[keep], t.radii_m[keep],
                                           list(np.asarray(t.material)[keep]), box,
                                           base.material_ids.shape, matrix=base.names[0])


@dataclass(frozen=True)
class ContactSpots(Effect):
    """Solid contact spots (sintered necks, fused coupling-agent bridges) between touching
    particles: a conductance ``G`` (W/K) per contact of every filler pair, in parallel with
    the silicone film of the gap contact model. A spot of radius ``a`` in a solid of
    conductivity ``k`` conducts about ``2 a k`` (0.1 um in Al2O3: 6e-6 W/K)."""

    key: str = "spots"
    name: str = "solid contact spots between particles"
    parameter: str = "G_contact_W_per_K"
    nominal: float = 0.0
    values: tuple[float, ...] = (0.0, 1e-6, 3e-6, 1e-5, 3e-5)
    signature: str = ("a gain that appears only where particles touch in numbers: small at "
                      "low filler fraction, steep towards the packing limit")
    separate_by: str = ("a fraction series down to 30 vol% (few contacts) or the "
                        "conductivity after heat treatment (necks grow)")
    kind: str = "material"

    def materials(self, base: Materials, value: float) -> Materials:
        fillers = sorted(p for p in base.conductivity if p != base.matrix)
        spots = {(a, b): float(value) for i, a in enumerate(fillers) for b in fillers[i:]}
        return base.with_values(contact_conductance=spots)


@dataclass(frozen=True)
class TesterContact(Effect):
    """A contact resistance between sample and meter bars left in an apparent
    conductivity measured at one thickness ``t``: ``k_app = t / (t / k + R_c)``."""

    key: str = "tester"
    name: str = "tester contact resistance left in the data"
    parameter: str = "R_contact_m2K_per_W"
    nominal: float = 0.0
    values: tuple[float, ...] = (0.0, 1e-5, 2e-5, 4e-5, 8e-5)
    signature: str = ("the apparent conductivity rises with the sample thickness, "
                      "relatively most for the most conductive formulations")
    separate_by: str = "readings at several thicknesses per sample (Eq. 8)"
    kind: str = "measurement"

    @property
    def needs_thickness(self) -> bool:
        return True

    def apparent(self, k: np.ndarray, thickness_m: np.ndarray, value: float) -> np.ndarray:
        return thickness_m / (thickness_m / k + np.asarray(value, dtype=float))


def default_effects() -> list[Effect]:
    """The library, in the order the report lists it."""
    return [MatrixConductivity(), FillerConductivity(), Porosity(), FillerFraction(),
            ContactSpots(), TesterContact()]


def by_key(keys: Sequence[str]) -> list[Effect]:
    """Library effects by their short keys; ValueError naming an unknown one."""
    lib = {e.key: e for e in default_effects()}
    out = []
    for k in keys:
        if k not in lib:
            raise ValueError(f"effects: unknown effect {k!r} (known: {', '.join(lib)})")
        out.append(lib[k])
    if not out:
        raise ValueError("effects: expected at least one effect")
    return out
