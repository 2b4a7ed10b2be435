"""A filler's size distribution as a lab states it, read into a lognormal.

Three statements are accepted (diameters in micrometres):

- ``mu_ln_um``, ``sigma_ln`` and ``basis``: the lognormal itself, of ln(D / 1 um);
- ``d10_um``, ``d50_um``, ``d90_um`` and ``basis`` (``"volume"`` if not named: what a laser
  diffractometer reports): a lognormal fitted to the three quantiles by least squares in
  ln D; the largest relative miss of a quantile is reported;
- ``edges_um`` with ``volume_percent`` or ``number_percent``: a measured histogram,
  fitted by :func:`itr_fv.materials.psd.fit_histogram`; its root-mean-square miss (in
  percentage points) is reported.

Every diameter is checked against the range of filler powders (:data:`DIAMETER_RANGE_UM`):
a value in metres or nanometres is refused with what it would be in micrometres.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy import special

from ..checks import slip_hint, unknown_key
from .psd import LogNormalPSD, fit_histogram

__all__ = ["StatedSize", "stated_size", "DIAMETER_RANGE_UM", "SIGMA_RANGE",
           "MAX_QUANTILE_MISFIT"]

#: Particle diameters of filler powders, um (10 nm to 1 mm).
DIAMETER_RANGE_UM = (0.01, 1000.0)
#: Accepted sigma of ln D (a sigma above 1.5 spans more than 4 decades in its 1-99 % range).
SIGMA_RANGE = (0.0, 1.5)
#: Largest relative miss of a stated quantile by the fitted lognormal: beyond it the
#: powder is not lognormal (bimodal, say) and one lognormal would misstate it.
MAX_QUANTILE_MISFIT = 0.25
_Z = {"d10_um": special.ndtri(0.1), "d50_um": 0.0, "d90_um": special.ndtri(0.9)}
_FORMS = {"lognormal": ("mu_ln_um", "sigma_ln", "basis"),
          "quantiles": ("d10_um", "d50_um", "d90_um", "basis"),
          "histogram": ("edges_um", "volume_percent", "number_percent")}


@dataclass(frozen=True)
class StatedSize:
    """A size distribution read from a statement.

    Attributes
    ----------
    psd : LogNormalPSD
        The lognormal, in the statement's basis.
    note : str
        How it was stated and how well the lognormal meets it.
    misfit : float
        Largest relative quantile miss (quantiles), rms miss in percentage points
        (histogram), 0 (lognormal).
    """

    psd: LogNormalPSD
    note: str
    misfit: float = 0.0


def _diameter(value: object, where: str) -> float:
    lo, hi = DIAMETER_RANGE_UM
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{where}: expected a diameter > 0 in um, got {value!r}")
    if not lo <= value <= hi:
        hint = slip_hint(value, (lo, hi), {"m": 1e6, "mm": 1e3, "nm": 1e-3}, "um")
        raise ValueError(f"{where}: {value:g} um is outside {lo:g} - {hi:g} um, the sizes of "
                         f"filler powders{'; ' + hint if hint else ''}")
    return float(value)


def _basis(table: Mapping, where: str, default: str | None) -> str:
    basis = table.get("basis", default)
    if basis is None:
        raise ValueError(f"{where}.basis: name the basis of the distribution, 'number' "
                         "(counted particles, a microscope) or 'volume' (a laser "
                         "diffractometer)")
    if basis not in ("number", "volume"):
        raise ValueError(f"{where}.basis: expected 'number' or 'volume', got {basis!r}")
    return basis


def stated_size(table: object, where: str = "size") -> StatedSize:
    """The lognormal of a size statement (a TOML table of one of the three forms).

    Parameters
    ----------
    table : mapping
        The statement (see the module notes).
    where : str
        The statement's place in its file, for the messages (``fillers[1].size``).

    Raises
    ------
    ValueError
        One line naming ``where`` and the key at fault: an unknown or missing key, a
        mixture of forms, a diameter out of range (in metres or nm), quantiles that do not
        increase or that no lognormal meets, a bad histogram.
    """
    if not isinstance(table, Mapping):
        raise ValueError(f"{where}: expected a table (mu_ln_um/sigma_ln, d10_um/d50_um/"
                         f"d90_um or edges_um/volume_percent), got {table!r}")
    known = {k for keys in _FORMS.values() for k in keys}
    bad = unknown_key(table, known)
    if bad:
        raise ValueError(f"{where}: {bad}")
    forms = [name for name, keys in _FORMS.items()
             if any(k in table for k in keys if k != "basis")]
    if len(forms) != 1:
        raise ValueError(f"{where}: state the sizes one way: mu_ln_um and sigma_ln, d10_um/"
                         f"d50_um/d90_um, or edges_um with volume_percent (got "
                         f"{', '.join(sorted(table)) or 'nothing'})")
    return {"lognormal": _lognormal, "quantiles": _quantiles,
            "histogram": _histogram}[forms[0]](table, where)


def _lognormal(table: Mapping, where: str) -> StatedSize:
    for key in ("mu_ln_um", "sigma_ln"):
        if key not in table:
            raise ValueError(f"{where}.{key}: missing (a lognormal needs mu_ln_um and "
                             "sigma_ln)")
    basis = _basis(table, where, None)
    mu, sigma = table["mu_ln_um"], table["sigma_ln"]
    for key, v in (("mu_ln_um", mu), ("sigma_ln", sigma)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{where}.{key}: expected a number, got {v!r}")
    _diameter(math.exp(mu), f"{where}.mu_ln_um (exp(mu), the median)")
    if not SIGMA_RANGE[0] < sigma <= SIGMA_RANGE[1]:
        raise ValueError(f"{where}.sigma_ln: expected a value in ({SIGMA_RANGE[0]:g}, "
                         f"{SIGMA_RANGE[1]:g}], the sd of ln D, got {sigma!r}")
    return StatedSize(LogNormalPSD(float(mu), float(sigma), basis),
                      f"lognormal mu/sigma, {basis} basis")


def _quantiles(table: Mapping, where: str) -> StatedSize:
    missing = [k for k in _Z if k not in table]
    if missing:
        raise ValueError(f"{where}.{missing[0]}: missing (the quantiles are d10_um, d50_um "
                         "and d90_um)")
    basis = _basis(table, where, "volume")
    d = {k: _diameter(table[k], f"{where}.{k}") for k in _Z}
    if not d["d10_um"] < d["d50_um"] < d["d90_um"]:
        raise ValueError(f"{where}: expected d10_um < d50_um < d90_um, got "
                         f"{d['d10_um']:g}, {d['d50_um']:g}, {d['d90_um']:g} um")
    z = np.array(list(_Z.values()))
    y = np.log(np.array(list(d.values())))
    sigma, mu = np.polyfit(z, y, 1)
    fitted = np.exp(mu + sigma * z)
    miss = float(np.max(np.abs(fitted / np.exp(y) - 1)))
    if miss > MAX_QUANTILE_MISFIT:
        raise ValueError(f"{where}: no lognormal meets d10/d50/d90 = {d['d10_um']:g}/"
                         f"{d['d50_um']:g}/{d['d90_um']:g} um (a quantile missed by "
                         f"{100 * miss:.0f} %); give the measured histogram (edges_um, "
                         "volume_percent)")
    if not SIGMA_RANGE[0] < sigma <= SIGMA_RANGE[1]:
        raise ValueError(f"{where}: d10/d90 spread gives sigma {sigma:.3g}, outside "
                         f"({SIGMA_RANGE[0]:g}, {SIGMA_RANGE[1]:g}]")
    return StatedSize(LogNormalPSD(float(mu), float(sigma), basis),
                      f"d10/d50/d90 ({basis} basis) fitted, largest quantile miss "
                      f"{100 * miss:.1f} %", miss)


def _histogram(table: Mapping, where: str) -> StatedSize:
    kinds = [k for k in ("volume_percent", "number_percent") if k in table]
    if "edges_um" not in table or len(kinds) != 1:
        raise ValueError(f"{where}: a histogram is edges_um with one of volume_percent or "
                         "number_percent")
    if "basis" in table:
        raise ValueError(f"{where}.basis: a histogram's basis is its percent key "
                         "(volume_percent or number_percent)")
    edges, percent = table["edges_um"], table[kinds[0]]
    if not isinstance(edges, list) or not isinstance(percent, list):
        raise ValueError(f"{where}: edges_um and {kinds[0]} are lists of numbers")
    for i, e in enumerate(edges):
        _diameter(e, f"{where}.edges_um[{i}]")
    try:
        total = float(sum(percent))
    except TypeError:
        raise ValueError(f"{where}.{kinds[0]}: expected numbers, got {percent!r}") from None
    if not 90.0 <= total <= 110.0:
        raise ValueError(f"{where}.{kinds[0]}: the bins sum to {total:g} %, expected 100 % "
                         "(per cent, not fractions)")
    basis = kinds[0].split("_")[0]
    try:
        fit = fit_histogram(edges, percent, basis)
    except ValueError as exc:
        raise ValueError(f"{where}.{exc}") from None
    return StatedSize(fit.psd, f"histogram ({basis} %) fitted, rms miss "
                      f"{fit.rmse_percent:.2f} points, r2 {fit.r2:.3f}", fit.rmse_percent)
