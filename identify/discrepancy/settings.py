"""Settings of the discrepancy workflow (:class:`DiscrepancySettings`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from itr_fv.materials.material_system import MaterialSystem
from itr_fv.rve.spec import RVESpec

from ..forward.fidelity import FaithfulRVE, faithful_for
from ..forward.model import ForwardSettings

__all__ = ["DiscrepancySettings"]


@dataclass(frozen=True)
class DiscrepancySettings:
    """Settings of the workflow.

    Attributes
    ----------
    forward : ForwardSettings
        RVE box, voxel, replicas, packing seed, solver tolerance of the tables (default
        12 um at 0.25 um, as ``itr reproduce``).
    faithful : FaithfulRVE or None
        Where each formulation's table level is corrected (default the ``shipped``
        fidelity level, the headline's: the shipped converged-box corrections, read per
        resistance, where they hold (:mod:`itr_identify.forward.shipped`), else full solves
        of two 24 um packings at 0.2 and 0.25 um with the voxel bias extrapolated away at
        :attr:`r_scatter_m2K_per_W`, as ``standard``;
        :mod:`itr_identify.forward.fidelity`); None: the tables' own level (12 um at
        0.25 um reads Al2O3-60 about 3 % and AlN-60 10-12 % low).
    r_grid_m2K_per_W : tuple of float
        Resistances solved per formulation, m^2 K/W (log spaced; also the prior range).
    r_scatter_m2K_per_W : float
        Resistance at which every replica is solved (RVE scatter, replica factor).
    fine_points : int
        Points of the calibration grid per axis.
    bic_margin : float
        BIC separation that the measurement proposed to decide a tie is expected to give
        (:mod:`.tie_breaking`); the verdict itself is the Bayes factor's.
    tie_margin : float
        BIC difference under which two candidates explain the data equally well (half of
        it in log Bayes factor for the verdict's tie).
    false_naming_rate : float
        The share of noise-only tables (drawn from the calibrated base model) on which the
        naming rule may name an effect: sets the threshold on the log Bayes factor
        (:mod:`.naming_threshold`).
    calibration_replicates : int
        Noise-only tables drawn to set that threshold (each fits every candidate once).
    calibration_seed : int
        Seed of those draws.
    significance : float
        p-value of the chi-square test under which a residual is significant.
    physical_r_m2K_per_W : (float, float)
        The range a filler-silicone resistance is physically expected in, m^2 K/W (acoustic
        and diffuse mismatch give 1e-9 to 1e-8 for clean oxide or nitride-polymer
        interfaces; adsorbed layers and coupling agents up to about 1e-7): a fit outside it
        is reported as an implausible resistance.
    auxiliary_model_sd : float
        Relative standard uncertainty of a predicted density or mass fraction given the
        stated phase densities (ideal mixing; the coupling agent's 4 vol% of the matrix at
        about 1.0 g/cm^3 moves a 60 vol% composite by 0.05 %), added to the replicate error
        of each. The phase densities themselves are stated inputs: their error would move
        every formulation of a filler together.
    fraction_sd : float
        Standard deviation of a formulation's actual filler volume fraction about its
        stated one (weighing, losses in mixing), an error shared by its k, density and mass
        fraction (a batch candidate adds its own to it). Default 0: a fraction error is the
        batch candidate's to find, not a variance the base model carries.
    assumed_thickness_mm : float
        Sample thickness at which the tester's contact resistance is fitted on a table
        without thicknesses (then only ``R_c / t`` is identified), mm.
    auxiliary_noise : dict
        The noise the workflow assumes for an auxiliary measurement it proposes (the
        measurement that would decide a tie): ``density_g_per_cm3`` relative sd per sample,
        ``filler_mass_fraction`` absolute sd per sample, ``samples`` per formulation,
        ``thicknesses_mm`` of a thickness series, ``powder_scale`` of a second powder
        (its median over the nominal one).
    correct_at_best : bool
        Correct a named or leading candidate's table level by faithful solves with the
        effect switched on at its best value (:mod:`itr_identify.discrepancy.best_point`),
        rather than by the base model's factor.
    """

    forward: ForwardSettings = field(default_factory=lambda: ForwardSettings(
        RVESpec(box_um=12.0, voxel_um=0.25), replicas=3))
    faithful: FaithfulRVE | None = field(default_factory=lambda: faithful_for("shipped"))
    r_grid_m2K_per_W: tuple[float, ...] = tuple(float(x) for x in np.logspace(-9, -6, 7))
    r_scatter_m2K_per_W: float = 3e-8
    fine_points: int = 121
    bic_margin: float = 6.0
    tie_margin: float = 2.0
    false_naming_rate: float = 0.05
    calibration_replicates: int = 40
    calibration_seed: int = 0
    significance: float = 0.01
    physical_r_m2K_per_W: tuple[float, float] = (1e-9, 1e-7)
    auxiliary_model_sd: float = 0.001
    fraction_sd: float = 0.0
    assumed_thickness_mm: float = 1.0
    auxiliary_noise: dict = field(default_factory=lambda: {
        "density_g_per_cm3": 0.003, "filler_mass_fraction": 0.003, "samples": 4,
        "thicknesses_mm": (0.5, 1.0, 1.5), "powder_scale": 0.5})
    correct_at_best: bool = True

    @property
    def system(self) -> MaterialSystem:
        """The material system (``forward.system``): phases, conductivities, sizes and the
        densities (g/cm^3) that predict a sample's density and filler mass fraction
        (default: the paper's system with handbook densities, Al2O3 3.95, AlN 3.26,
        silicone 0.97; :meth:`MaterialSystem.with_densities` overrides them)."""
        return self.forward.system

    def __post_init__(self) -> None:
        r = np.asarray(self.r_grid_m2K_per_W, dtype=float)
        if r.size < 4 or np.any(np.diff(r) <= 0) or r[0] <= 0:
            raise ValueError("r_grid_m2K_per_W: expected at least 4 increasing resistances "
                             f"> 0 m^2 K/W, got {self.r_grid_m2K_per_W!r}")
        if not isinstance(self.fine_points, int) or self.fine_points < 11:
            raise ValueError(f"fine_points: expected a whole number >= 11, got "
                             f"{self.fine_points!r}")
        for name in ("bic_margin", "tie_margin"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name}: expected >= 0, got {getattr(self, name)!r}")
        lo, hi = self.physical_r_m2K_per_W
        if not 0 < lo < hi:
            raise ValueError(f"physical_r_m2K_per_W: expected 0 < low < high m^2 K/W, got "
                             f"{self.physical_r_m2K_per_W!r}")
        if not 0 <= self.auxiliary_model_sd < 0.1:
            raise ValueError(f"auxiliary_model_sd: expected a relative sd in [0, 0.1), got "
                             f"{self.auxiliary_model_sd!r}")
        if not 0 <= self.fraction_sd < 0.05:
            raise ValueError(f"fraction_sd: expected a volume fraction in [0, 0.05), got "
                             f"{self.fraction_sd!r}")
        if not 0.01 <= self.assumed_thickness_mm <= 20:
            raise ValueError(f"assumed_thickness_mm: expected 0.01 - 20 mm, got "
                             f"{self.assumed_thickness_mm!r}")
        if not 0 < self.false_naming_rate <= 0.5:
            raise ValueError(f"false_naming_rate: expected a share in (0, 0.5], got "
                             f"{self.false_naming_rate!r}")
        if not isinstance(self.calibration_replicates, int) or self.calibration_replicates < 10:
            raise ValueError(f"calibration_replicates: expected a whole number >= 10, got "
                             f"{self.calibration_replicates!r}")
        if not 0 < self.significance < 1:
            raise ValueError(f"significance: expected a p-value in (0, 1), got "
                             f"{self.significance!r}")
