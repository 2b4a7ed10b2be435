"""A lab's second measurements of a sample besides k: its density (Archimedes) and its filler
mass fraction (TGA ash content), predicted by every model from the sample's composition.

A single-filler sample of filler volume fraction ``phi`` holding a void volume fraction ``p``
(air, massless) in a matrix has, with the phase densities ``rho_f`` and ``rho_m`` of the
material system (:meth:`itr_fv.materials.MaterialSystem.densities`, g/cm^3),

    rho = phi rho_f + (1 - phi - p) rho_m                               (g/cm^3)
    w   = phi rho_f / (phi rho_f + (1 - phi - p) rho_m)                 (mass fraction)

A candidate effect says what ``(phi, p)`` a sample of nominal fraction ``phi_0`` has
(:meth:`itr_identify.discrepancy.effects.Effect.composition`): porosity lowers ``rho`` and
raises ``w`` a little; a fraction below nominal lowers both; a conductivity or a resistance
changes neither. A batch whose fraction is off nominal by a random ``delta`` moves k,
``rho`` and ``w`` together (:func:`fraction_derivatives`).

:class:`AuxGroup` is one formulation's mean of one observable with its standard error,
the replicate scatter pooled over a filler's formulations as k's is
(:func:`auxiliary_groups`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from itr_fv.materials.material_system import MaterialSystem

from ..inference.measurements import Measurements

__all__ = ["OBSERVABLES", "AuxGroup", "auxiliary_groups", "predict", "fraction_derivatives"]

#: The auxiliary observables a model predicts: column -> (label, unit).
OBSERVABLES = {"density_g_per_cm3": ("density", "g/cm^3"),
               "filler_mass_fraction": ("filler mass fraction", "")}


@dataclass(frozen=True)
class AuxGroup:
    """One formulation's replicate mean of one auxiliary observable."""

    formulation: str
    filler: str
    fraction: float
    observable: str
    mean: float
    standard_error: float
    n: int

    @property
    def label(self) -> str:
        return f"{self.formulation} {OBSERVABLES[self.observable][0]}"


def predict(observable: str, system: MaterialSystem, filler: str, phi: np.ndarray,
            voids: np.ndarray) -> np.ndarray:
    """The density (g/cm^3) or filler mass fraction of samples of filler volume fraction
    ``phi`` and void volume fraction ``voids``."""
    rho = system.densities([filler])
    filler_mass = np.asarray(phi, dtype=float) * rho[filler]
    matrix_mass = (1.0 - np.asarray(phi, dtype=float) - np.asarray(voids, dtype=float)) \
        * rho[system.matrix]
    if observable == "density_g_per_cm3":
        return filler_mass + matrix_mass
    if observable == "filler_mass_fraction":
        return filler_mass / (filler_mass + matrix_mass)
    raise ValueError(f"observable: expected one of {list(OBSERVABLES)}, got {observable!r}")


def fraction_derivatives(observable: str, system: MaterialSystem, filler: str,
                         phi: np.ndarray, voids: np.ndarray) -> np.ndarray:
    """d(observable)/d(phi) at fixed voids (a batch's fraction error moves it by this times
    the error)."""
    rho = system.densities([filler])
    rf, rm = rho[filler], rho[system.matrix]
    if observable == "density_g_per_cm3":
        return np.full(np.broadcast(phi, voids).shape, rf - rm)
    if observable == "filler_mass_fraction":
        a = np.asarray(phi, dtype=float) * rf
        b = (1.0 - np.asarray(phi, dtype=float) - np.asarray(voids, dtype=float)) * rm
        return (rf * b + a * rm) / (a + b) ** 2
    raise ValueError(f"observable: expected one of {list(OBSERVABLES)}, got {observable!r}")


def auxiliary_groups(measurements: Measurements, fractions: dict[str, dict[str, float]]
                     ) -> list[AuxGroup]:
    """Per single-filler formulation and auxiliary observable (density, mass fraction) the
    table holds: the mean of the samples measured, and its standard error from the
    replicate scatter pooled over the filler's formulations (relative for the density,
    absolute for the mass fraction); ValueError where no formulation of a filler has two
    samples of an observable (no scatter to pool)."""
    out = []
    for obs in OBSERVABLES:
        rows = []
        for f in measurements.formulations:
            comp = fractions[f]
            v = measurements.auxiliary_of(obs, f)
            if len(comp) != 1 or v is None:
                continue
            v = v[np.isfinite(v)]
            if v.size == 0:
                continue
            (filler, phi), = comp.items()
            dev = v / v.mean() - 1 if obs == "density_g_per_cm3" else v - v.mean()
            rows.append((f, filler, phi, v, float((dev ** 2).sum()), v.size - 1))
        for fl in sorted({r[1] for r in rows}):
            mine = [r for r in rows if r[1] == fl]
            dof = sum(r[5] for r in mine)
            if dof < 1:
                raise ValueError(f"measurements: {obs} of {fl} needs two samples of one "
                                 "formulation at least (its replicate scatter is the noise "
                                 "of the likelihood)")
            sd = math.sqrt(sum(r[4] for r in mine) / dof)
            for f, filler, phi, v, _, _ in mine:
                scale = v.mean() if obs == "density_g_per_cm3" else 1.0
                out.append(AuxGroup(f, filler, phi, obs, float(v.mean()),
                                    sd * scale / math.sqrt(v.size), int(v.size)))
    return out
