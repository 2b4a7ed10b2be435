"""The RVE's box and voxel from the powders: rules this project measured, not constants.

A filler's size distribution (its number-weighted lognormal) fixes three lengths:

- **the voxel** (:func:`voxel_for`): the gap model's voxel bias is an interface effect,
  so it scales with the voxel over the Sauter diameter ``D32`` (volume over surface). The
  cheap RVE of the paper's system, 0.25 um for Al2O3 (``D32`` 3.77 um), reads Al2O3-60
  about 3 % low (``validation/results/voxel_bias_law.md``); a voxel of ``D32`` /
  :data:`VOXELS_PER_SAUTER_DIAMETER` keeps any powder at that bias. It must also draw the
  fine tail: twice the voxel (the smallest particle drawn) may cut at most 1 % of the
  volume and 5 % of the particles (the generator's own refusal, :func:`itr_fv.rve.size_cut`).
  The result is rounded down to the series :data:`VOXEL_SERIES` (1, 1.25, 1.6, 2, 2.5, 3.2,
  4, 5, 6.4, 8 times a power of ten), the finest filler's voxel for a formulation;
- **the cheap box** (:func:`cheap_rve`): :data:`CHEAP_VOXELS` voxels per edge, the cost of
  a reduced basis's full solves (the paper's system: 12 um at 0.25 um); the coarse tail the
  box cuts is corrected by the faithful RVE;
- **the faithful box** (:func:`faithful_box`): the smallest box whose size cut (largest
  diameter 0.45 box) removes at most :data:`MAX_VOLUME_CUT` of the filler's volume.
  Measured: Al2O3-60 converged (within 0.5 % of every larger box) at 24 um, whose cut
  removes 0.23 % of the Al2O3 volume, and not at 16 um (4.7 %); AlN-60 at 80 um (1.4 %),
  not at 64 um (3.5 %) (``validation/results/box_size.md``, ``box_study.md``). Its voxels
  are :data:`FAITHFUL_VOXEL_RATIO` times the cheap voxel and the cheap voxel (the
  Richardson pair), so the box is a whole number of both.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from scipy import special

from ..materials.psd import LogNormalPSD
from .spec import MAX_DIAMETER_BOX_RATIO, RVESpec

__all__ = ["VOXELS_PER_SAUTER_DIAMETER", "VOXEL_SERIES", "CHEAP_VOXELS", "MAX_VOLUME_CUT",
           "FAITHFUL_VOXEL_RATIO", "voxel_for", "cheap_rve", "faithful_box", "box_volume_cut",
           "sauter_diameter_um"]

#: Voxels per Sauter diameter of the finest filler (the paper's cheap voxel: 15.07).
VOXELS_PER_SAUTER_DIAMETER = 15.0
#: Voxel edges are rounded down to these mantissas (times a power of ten, um).
VOXEL_SERIES = (1.0, 1.25, 1.6, 2.0, 2.5, 3.2, 4.0, 5.0, 6.4, 8.0)
#: Voxels per edge of the cheap RVE.
CHEAP_VOXELS = 48
#: Share of a filler's volume the faithful box's size cut may remove.
MAX_VOLUME_CUT = 0.015
#: Fine voxel of the faithful pair over the cheap voxel (the paper's 0.2 / 0.25 um).
FAITHFUL_VOXEL_RATIO = 0.8
#: The fine tail the smallest drawn particle (two voxels) may cut: volume, number.
_FINE_TAIL_VOLUME, _FINE_TAIL_NUMBER = 0.01, 0.05


def sauter_diameter_um(psd: LogNormalPSD) -> float:
    """``D32 = E[D^3] / E[D^2]`` of the number-weighted distribution, um."""
    n = psd.to_number()
    return math.exp(n.mu + 2.5 * n.sigma ** 2)


def _round_down(value: float) -> float:
    exponent = math.floor(math.log10(value))
    mantissa = value / 10 ** exponent
    best = max(m for m in VOXEL_SERIES if m <= mantissa * (1 + 1e-9))
    return round(best * 10 ** exponent, 12)


def voxel_for(psds: Iterable[LogNormalPSD]) -> float:
    """The cheap voxel edge of a formulation of these fillers, um (module notes)."""
    edges = []
    for psd in psds:
        n = psd.to_number()
        bias = sauter_diameter_um(n) / VOXELS_PER_SAUTER_DIAMETER
        # twice the voxel at most the number quantile 5 % and the volume quantile 1 %
        d_number = math.exp(n.mu + n.sigma * special.ndtri(_FINE_TAIL_NUMBER))
        v = n.to_volume()
        d_volume = math.exp(v.mu + v.sigma * special.ndtri(_FINE_TAIL_VOLUME))
        edges.append(min(bias, d_number / 2, d_volume / 2))
    if not edges:
        raise ValueError("psds: expected at least one size distribution")
    return _round_down(min(edges))


def cheap_rve(psds: Iterable[LogNormalPSD], **spec) -> RVESpec:
    """The cheap RVE: :func:`voxel_for`'s voxel, :data:`CHEAP_VOXELS` of them per edge;
    ``spec`` the other fields of the :class:`RVESpec`."""
    h = voxel_for(psds)
    return RVESpec(box_um=round(CHEAP_VOXELS * h, 9), voxel_um=h, **spec)


def box_volume_cut(psd: LogNormalPSD, box_um: float,
                   ratio: float = MAX_DIAMETER_BOX_RATIO) -> float:
    """Share of the filler's volume above the box's largest diameter ``ratio * box_um``."""
    v = psd.to_volume()
    return float(special.ndtr(-(math.log(ratio * box_um) - v.mu) / v.sigma))


def faithful_box(psd: LogNormalPSD, cheap_voxel_um: float) -> float:
    """The faithful box of one filler, um: the smallest whole number of grid units (four
    cheap voxels: a whole number of both faithful voxels) whose size cut removes at most
    :data:`MAX_VOLUME_CUT` of its volume, and no smaller than the cheap box."""
    v = psd.to_volume()
    d_cut = math.exp(v.mu + v.sigma * special.ndtri(1 - MAX_VOLUME_CUT))
    unit = 4 * cheap_voxel_um
    units = max(math.ceil(d_cut / MAX_DIAMETER_BOX_RATIO / unit - 1e-9),
                math.ceil(CHEAP_VOXELS / 4))
    return round(units * unit, 9)
