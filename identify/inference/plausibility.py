"""Physical sense of a measurement, checked while it is read (before any solve).

A measured conductivity of a formulation can only lie below the Hashin-Shtrikman upper
bound of its phases at perfect interfaces: an interface resistance only lowers the effective
conductivity, so no resistance reaches above it. A value below the matrix's own conductivity
is reachable only with resistances that make the filler nearly insulating: it is warned
about, not refused. A sample is 0.01 - 20 mm thick (thermal interface materials and their
tester samples). A value outside its range is asked about a unit (mW/(m K) for a
conductivity, um or m for a thickness under a ``_mm`` column) only where that unit makes it
plausible (:func:`itr_fv.checks.unit_slip`); otherwise the message states the range.

The phase conductivities and densities are those of the material system the measurements
are read against (:class:`~itr_fv.materials.material_system.MaterialSystem`), the ones the
identification solves with.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping

from itr_fv.analytic import hashin_shtrikman_multiphase
from itr_fv.checks import slip_hint
from itr_fv.materials.material_system import MaterialSystem

from .formulations import fractions_of

__all__ = ["ImplausibleMeasurementWarning", "conductivity_range", "check_conductivity",
           "check_thickness", "THICKNESS_RANGE_MM", "density_range", "powder_scale",
           "check_auxiliary", "POWDER_SCALE_RANGE", "CONDUCTIVITY_SLIPS", "IMPEDANCE_SLIPS"]

class ImplausibleMeasurementWarning(UserWarning):
    """A measured value that physics allows but that is more likely a wrong unit."""


#: Plausible sample thickness, mm: a thermal interface material's tester sample.
THICKNESS_RANGE_MM = (0.01, 20.0)
#: Units a thickness under a ``_mm`` column may be in by mistake: the factor to mm.
THICKNESS_SLIPS = {"um": 1e-3, "m": 1e3}
#: Units a conductivity in W/(m K) may be in by mistake: the factor to W/(m K).
CONDUCTIVITY_SLIPS = {"mW/(m K)": 1e-3}
#: Units an impedance in K mm^2/W may be in by mistake, as the factor they put on the
#: conductivity ``1/slope`` derived from it (K m^2/W: the slope 1e6 times too small).
IMPEDANCE_SLIPS = {"K m^2/W": 1e-6, "K cm^2/W": 1e-2}


def conductivity_range(formulation: str, system: MaterialSystem
                       ) -> tuple[float, float] | None:
    """``(k_matrix, k_upper)`` in W/(m K) for ``formulation`` of ``system``: the matrix
    conductivity and the Hashin-Shtrikman upper bound at perfect interfaces (nominal
    conductivities); None for a name that gives no composition (a caller's own formulation
    set)."""
    try:
        fillers = fractions_of(formulation, system)
    except ValueError:
        return None
    k = system.conductivities()
    matrix = system.matrix
    fractions = [1.0 - sum(fillers.values()), *fillers.values()]
    conductivities = [k[matrix], *(k[f] for f in fillers)]
    return k[matrix], hashin_shtrikman_multiphase(fractions, conductivities)[1]


def check_conductivity(where: str, formulation: str, k_W_per_mK: float, *,
                       system: MaterialSystem, column: str = "k_W_per_mK",
                       slips: Mapping[str, float] = CONDUCTIVITY_SLIPS,
                       subject: str = "it") -> None:
    """Refuse a conductivity above what any resistance allows; warn below the matrix's.

    Either message asks about a unit only where one of ``slips`` makes the value plausible
    (e.g. 1290 as mW/(m K)); otherwise it states the formulation's range (a 25 W/(m K) of a
    60 % alumina is no unit slip: 25 mW/(m K) is below the matrix).

    Parameters
    ----------
    where : str
        ``"<file> line <n>"``, the start of the message.
    formulation : str
        Its formulation name.
    k_W_per_mK : float
        The measured (or reduced) conductivity, W/(m K).
    system : MaterialSystem
        The phases of the formulation.
    column : str
        The column it came from, named in the message.
    slips : mapping of str to float
        Units the value may be in by mistake (:func:`itr_fv.checks.unit_slip`).
    subject : str
        What may be in such a unit, named in the hint (``"it"``: the value).

    Raises
    ------
    ValueError
        Above the Hashin-Shtrikman bound of the formulation at perfect interfaces.

    Warns
    -----
    ImplausibleMeasurementWarning
        Below the matrix conductivity.
    """
    span = conductivity_range(formulation, system)
    if span is None:
        return
    k_matrix, k_upper = span
    if k_matrix <= k_W_per_mK <= k_upper:
        return
    tail = slip_hint(k_W_per_mK, span, slips, "W/(m K)", subject=subject,
                     result="that" if subject == "it" else "the conductivity") or (
        f"a sample of {formulation} can conduct {k_matrix:g} - {k_upper:.3g} W/(m K)")
    if k_W_per_mK > k_upper:
        raise ValueError(f"{where}: {column} {k_W_per_mK:g} W/(m K) is above "
                         f"{k_upper:.3g} W/(m K), the most {formulation} can conduct at any "
                         "interface resistance (Hashin-Shtrikman bound at perfect interfaces); "
                         f"{tail}")
    warnings.warn(f"{where}: {column} {k_W_per_mK:g} W/(m K) of {formulation} is below the "
                  f"matrix's own {k_matrix:g} W/(m K): only resistances that make the "
                  f"filler nearly insulating reach it; {tail}",
                  ImplausibleMeasurementWarning, stacklevel=3)


def check_thickness(where: str, thickness_mm: float, *, column: str = "thickness_mm") -> None:
    """Refuse a sample thickness outside :data:`THICKNESS_RANGE_MM` (``where`` as in
    :func:`check_conductivity`)."""
    lo, hi = THICKNESS_RANGE_MM
    if not lo <= thickness_mm <= hi:
        hint = slip_hint(thickness_mm, THICKNESS_RANGE_MM, THICKNESS_SLIPS, "mm")
        raise ValueError(f"{where}: {column} {thickness_mm:g} mm is outside the {lo:g} - "
                         f"{hi:g} mm of a thermal-interface sample{'; ' + hint if hint else ''}")


#: A powder of a size series may be this many times finer or coarser than the material
#: system's (the forward tables reach its interface resistances scaled by the size ratio).
POWDER_SCALE_RANGE = (0.25, 4.0)


def density_range(formulation: str, system: MaterialSystem) -> tuple[float, float] | None:
    """``(rho_min, rho_max)`` in g/cm^3 that a sample of ``formulation`` can have: any
    void-free mixture of its phases lies between the matrix's and the densest filler's
    density (a sample below its matrix's density would be more void than composite); None
    for a name that gives no composition or a system without densities."""
    try:
        fillers = fractions_of(formulation, system)
    except ValueError:
        return None
    rho = system.densities(fillers)
    return rho[system.matrix], max(rho[f] for f in fillers)


def powder_scale(formulation: str, d50_um: float, system: MaterialSystem) -> float:
    """The ratio of a powder's number-median diameter ``d50_um`` to the material system's
    (Table 1) for the single filler of ``formulation``."""
    fillers = fractions_of(formulation, system)
    if len(fillers) != 1:
        raise ValueError(f"d50_um: a size series needs a single-filler formulation, got "
                         f"{formulation!r}")
    psd = system.filler(next(iter(fillers))).psd
    return float(d50_um) / float(psd.median_um)


def check_auxiliary(where: str, formulation: str, column: str, value: float,
                    system: MaterialSystem) -> float:
    """Refuse an auxiliary observable no sample of ``formulation`` can have (ValueError
    starting with ``where`` and naming the column); returns ``value``.

    ``density_g_per_cm3`` outside :func:`density_range`; ``filler_mass_fraction`` outside
    (0, 1) (a percentage is refused with its fraction); ``d50_um`` whose ratio to the
    material system's median lies outside :data:`POWDER_SCALE_RANGE`.
    """
    import math

    if not math.isfinite(value):
        raise ValueError(f"{where}: {column} must be finite, got {value!r}")
    if column == "density_g_per_cm3":
        rng = density_range(formulation, system)
        if rng is not None and not rng[0] <= value <= rng[1]:
            hint = slip_hint(value, rng, {"kg/m^3": 1e-3}, "g/cm^3")
            raise ValueError(f"{where}: density_g_per_cm3 {value:g} is outside {rng[0]:g} - "
                             f"{rng[1]:g} g/cm^3, what a sample of {formulation} can have "
                             f"(its matrix's to its densest filler's density)"
                             f"{'; ' + hint if hint else ''}")
    elif column == "filler_mass_fraction":
        if not 0 < value < 1:
            hint = (f" (if it is in per cent, it is {value / 100:g})" if 1 < value < 100
                    else "")
            raise ValueError(f"{where}: filler_mass_fraction {value:g} is outside 0 - 1 (a "
                             f"mass fraction){hint}")
    elif column == "d50_um":
        if not value > 0:
            raise ValueError(f"{where}: d50_um must be > 0 um, got {value:g}")
        try:
            s = powder_scale(formulation, value, system)
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        lo, hi = POWDER_SCALE_RANGE
        if not lo <= s <= hi:
            raise ValueError(f"{where}: d50_um {value:g} um is {s:.3g} times the material "
                             f"system's median for {formulation}; a size series is modelled "
                             f"for {lo:g} - {hi:g} times")
    else:
        raise ValueError(f"column: expected an auxiliary column, got {column!r}")
    return float(value)
