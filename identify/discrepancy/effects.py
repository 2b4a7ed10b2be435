"""Candidate physical effects a calibrated model may lack, each an extension of the RVE model.

Every candidate has one physical parameter, a nominal value at which the base model is
recovered exactly, a grid of values on which the discrepancy workflow
(:mod:`itr_identify.discrepancy`) solves the full model, the signature it leaves in the data and
the measurement that separates it from its look-alikes. Four kinds:

- *material*: a phase conductivity changes (matrix off nominal, filler below nominal, air
  voids smaller than a voxel homogenised into the matrix);
- *geometry*: the voxel image changes (filler particles removed); the image at a larger
  parameter value contains the one at a smaller value (particles removed in one random
  order), so the conductivity is a smooth function of the parameter and not a new RVE draw
  per value;
- *measurement*: the tester's reading (a contact resistance left in an apparent
  conductivity measured at one thickness);
- *variance*: an error shared by a formulation's measurements (a batch whose actual filler
  fraction is off nominal by a random amount), which widens, not moves, the model.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from itr_fv import Materials, Microstructure
from itr_fv.analytic import maxwell_garnett
from itr_fv.materials import default_system
from itr_fv.materials.material_system import MaterialSystem

from .candidate import Effect
from .steepening import STEEPENING_EFFECTS

__all__ = ["Effect", "MatrixConductivity", "FillerConductivity", "Porosity",
           "FillerFraction", "ContactSpots", "TesterContact", "BatchFraction",
           "default_effects", "by_key",
           "AIR_CONDUCTIVITY"]

#: Conductivity of the air in voids, W/(m K).
AIR_CONDUCTIVITY = 0.026


@dataclass(frozen=True)
class MatrixConductivity(Effect):
    """The matrix (silicone with its 4 vol% coupling agent) off its nominal conductivity
    (the material system's: 0.18 W/(m K) for the paper's), from half to twice it."""

    key: str = "matrix"
    name: str = "matrix conductivity off nominal"
    parameter: str = "k_matrix_W_per_mK"
    nominal: float = field(default_factory=lambda: default_system().matrix_conductivity)
    values: tuple[float, ...] = field(default_factory=lambda: _matrix_values(
        default_system().matrix_conductivity))
    signature: str = ("every formulation shifts the same way; the relative shift is largest "
                      "at the lowest filler fraction and the same for both fillers")
    separate_by: str = ("the conductivity of the neat matrix (silicone + coupling agent) "
                        "and the sample density (voids lower k the same way)")

    stated_sd: float = 0.0

    @classmethod
    def for_system(cls, system: MaterialSystem) -> "MatrixConductivity":
        """The effect about ``system``'s matrix conductivity, with the relative sd the
        system states for it (the lab's measurement or the handbook's)."""
        k = system.matrix_conductivity
        return cls(nominal=k, values=_matrix_values(k),
                   stated_sd=float(system.matrix_conductivity_sd))

    def prior_weights(self, axis: np.ndarray) -> np.ndarray:
        """Lognormal about the nominal value with the stated relative sd (``stated_sd``;
        the grid's uniform prior where it is 0): a matrix conductivity the lab measured
        is not free to move far from its measurement."""
        if self.stated_sd <= 0:
            return super().prior_weights(axis)
        axis = np.asarray(axis, dtype=float)
        z = np.log(axis / self.nominal) / self.stated_sd
        # density in ln k on an axis evenly spaced in k (log_scale False) or in ln k
        w = np.exp(-0.5 * z ** 2) / (1.0 if self.log_scale else axis)
        return w / w.sum()

    def pulled_beyond_statement(self, interval: tuple[float, float]) -> bool:
        """Whether the 90 % interval of the fitted value lies wholly beyond three stated
        sds of the nominal value: the data pull a measured input far outside its
        uncertainty (then the model lacks something; the input is not to be blamed)."""
        if self.stated_sd <= 0:
            return False
        lo, hi = (np.log(np.asarray(interval, dtype=float) / self.nominal)
                  / self.stated_sd)
        return bool(lo > 3.0 or hi < -3.0)

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
    """Air voids (k = 0.026 W/(m K)) in the matrix, smaller than a voxel: the void fraction
    ``p`` of the composite displaces matrix (the filler fraction stays nominal), and the
    matrix phase takes the Maxwell-Eucken conductivity of silicone holding air spheres at
    ``p / (1 - phi)`` of its volume (``phi`` the RVE's filler fraction;
    :func:`itr_fv.analytic.maxwell_garnett`).

    Voids resolved as spheres in the RVE could not reach the physical range: random
    sequential addition of 1 um voids among a 55-65 % packing finds room for 3.4-6.5 % of the
    volume. Homogenised, the grid reaches 15 %, and the signature differs from a lower matrix
    conductivity: the same void fraction takes a larger share of the matrix, and so lowers
    k relatively more, at a higher filler fraction.
    """

    key: str = "porosity"
    name: str = "porosity (air voids)"
    parameter: str = "void_fraction"
    nominal: float = 0.0
    values: tuple[float, ...] = (0.0, 0.025, 0.05, 0.1, 0.15)
    signature: str = ("like a matrix of lower conductivity, but a void fraction of the "
                      "composite takes a larger share of the matrix at a higher filler "
                      "fraction")
    separate_by: str = "the sample density against the mixture's (Archimedes) or micro-CT"
    kind: str = "material"

    def composition(self, fraction, value):
        f = np.asarray(fraction, dtype=float)
        v = np.asarray(value, dtype=float)
        shape = np.broadcast(f, v).shape
        return np.broadcast_to(f, shape).astype(float), np.broadcast_to(v, shape).astype(float)

    def materials_in(self, microstructure: Microstructure, base: Materials,
                     value: float) -> Materials:
        if value <= 0:
            return base
        phi = 1.0 - microstructure.volume_fractions().get(microstructure.names[0], 0.0)
        share = float(value) / max(1.0 - phi, 1e-12)
        if share >= 0.6:
            raise ValueError(f"value: a void fraction {value:g} fills {share:.0%} of the "
                             f"matrix at a filler fraction {phi:.3f}; expected voids in a "
                             "continuous matrix (below 60 % of it)")
        k_m = base.conductivity[base.matrix]
        return base.with_values(conductivity={
            base.matrix: k_m * maxwell_garnett(share, AIR_CONDUCTIVITY / k_m)})


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

    def composition(self, fraction, value):
        f = np.asarray(fraction, dtype=float) * np.asarray(value, dtype=float)
        return f, np.zeros(f.shape)

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
                                           base.material_ids.shape, matrix=base.names[0],
                                           contact=t.contact)


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

    def size_equivalent(self, value, scale):
        # a conductance per contact acts through G / (k a)
        return np.asarray(value, dtype=float) / scale

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


@dataclass(frozen=True)
class BatchFraction(Effect):
    """Each formulation a batch whose actual filler fraction is off nominal by a random
    amount of standard deviation ``sd`` (volume fraction): an error shared by all the
    batch's measurements of relative size ``sd |d ln k / d phi|``, largest where k rises
    steeply with the fraction (towards the packing limit)."""

    key: str = "batch"
    name: str = "batch filler fraction off nominal"
    parameter: str = "batch_fraction_sd"
    nominal: float = 0.0
    values: tuple[float, ...] = (0.0, 0.005, 0.01, 0.015, 0.02, 0.03)
    signature: str = ("formulations scatter about the model more than their replicates "
                      "allow, most where k rises steeply with the fraction; no trend")
    separate_by: str = ("the ash content (TGA) or density of each batch, or a second batch "
                        "of the same formulation")
    kind: str = "variance"
    #: A weighed mix misses its filler fraction by well under 1 vol% (a 1 vol% error at
    #: 60 vol% is about 1.5 % of the filler's weight); more is not a batch-to-batch error.
    physical_range: tuple[float, float] | None = (0.0, 0.01)

    def formulation_sd(self, slope: np.ndarray, value: np.ndarray) -> np.ndarray:
        return np.abs(slope) * np.asarray(value, dtype=float)

    def fraction_sd(self, value):
        return np.asarray(value, dtype=float)


def _matrix_values(k: float) -> tuple[float, ...]:
    """The matrix conductivities the forward tables solve at, W/(m K): half to twice ``k``."""
    return tuple(f * k for f in (0.5, 0.75, 1.0, 1.5, 2.0))


def default_effects(system: MaterialSystem | None = None) -> list[Effect]:
    """The library, in the order the report lists it: the seven of this module, then the
    steepening candidates of :mod:`itr_identify.discrepancy.steepening` (film thinning,
    agglomeration, size basis, interphase shell); the matrix's about ``system``'s
    conductivity (default: the package's system)."""
    matrix = MatrixConductivity() if system is None else MatrixConductivity.for_system(system)
    return [matrix, FillerConductivity(), Porosity(), FillerFraction(),
            ContactSpots(), TesterContact(), BatchFraction()] + [
                cls() for cls in STEEPENING_EFFECTS]


def by_key(keys: Sequence[str], system: MaterialSystem | None = None) -> list[Effect]:
    """Library effects by their short keys (about ``system``, :func:`default_effects`);
    ValueError naming an unknown one."""
    lib = {e.key: e for e in default_effects(system)}
    out = []
    for k in keys:
        if k not in lib:
            raise ValueError(f"effects: unknown effect {k!r} (known: {', '.join(lib)})")
        out.append(lib[k])
    if not out:
        raise ValueError("effects: expected at least one effect")
    return out
