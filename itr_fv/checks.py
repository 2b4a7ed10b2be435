"""Argument checks shared across the package: bad input raises a ValueError naming it."""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable, Mapping

import numpy as np

__all__ = ["PhysicalScaleWarning", "VoxelContactWarning", "finite_number", "phase_name",
           "real_number", "slip_hint", "unit_slip", "unknown_key"]


class PhysicalScaleWarning(UserWarning):
    """An input whose scale is implausible for this domain (e.g. micrometres given as metres)."""


class VoxelContactWarning(UserWarning):
    """A per-area contact resistance (contact="area"): its value depends on the voxel size."""

#: Phase names: ASCII letters and digits, starting with a letter, with ``-`` ``+`` ``.`` allowed
#: inside. Not ``_``: the package's flat parameter names are ``k_<phase>`` and
#: ``R_<phaseA>_<phaseB>``, which a name holding ``_`` would make ambiguous. Not non-ASCII:
#: names go into VTK files and Parquet column names.
_PHASE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9.+-]*\Z")


def real_number(value: object, argument: str) -> float:
    """``float(value)`` of a real number; a ValueError naming ``argument`` otherwise.

    ``True``/``False`` are refused: ``float(True)`` is 1.0, which would let a flag pass as
    a conductivity of 1 W/(m K).
    """
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{argument}: expected a number, got the boolean {value!r}")
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{argument}: not a number: {value!r}") from None


def finite_number(value: object, argument: str) -> float:
    """``float(value)``, or a ValueError naming ``argument`` if it is no finite number."""
    v = real_number(value, argument)
    if not math.isfinite(v):
        raise ValueError(f"{argument} must be finite, got {v!r}")
    return v


def phase_name(name: object, argument: str) -> str:
    """``name`` if it is a valid phase name (see ``_PHASE_NAME``); a ValueError otherwise."""
    if not isinstance(name, str) or not _PHASE_NAME.match(name):
        raise ValueError(f"{argument}: phase names are ASCII letters, digits and '-', '+', '.', "
                         f"starting with a letter (no '_': it separates the parts of "
                         f"parameter names such as R_Al2O3_silicone), got {name!r}")
    return name


def unknown_key(given: Iterable[str], known: Iterable[str], *, detail: str = "") -> str | None:
    """The message for the first key of ``given`` (in sorted order) that ``known`` lacks, or
    None where every key is known: the one wording of an unknown key in a settings file.

    Parameters
    ----------
    given : iterable of str
        The keys a file's table holds (a dict gives its keys).
    known : iterable of str
        The keys that table may hold.
    detail : str, optional
        Words after the key, e.g. ``" for kind 'grid'"``.

    Returns
    -------
    str or None
        ``unknown key 'voxl_um' (did you mean 'voxel_um'? known: box_um, voxel_um)``; the
        "did you mean" only where a known key is close (:func:`difflib.get_close_matches`).
    """
    names = sorted(str(k) for k in known)
    unknown = sorted(str(k) for k in given if str(k) not in names)
    if not unknown:
        return None
    key = unknown[0]
    near = difflib.get_close_matches(key, names, n=1)
    hint = f"did you mean {near[0]!r}? " if near else ""
    return f"unknown key {key!r}{detail} ({hint}known: {', '.join(names)})"


def unit_slip(value: float, plausible: tuple[float, float],
              slips: Mapping[str, float]) -> tuple[str, float] | None:
    """The unit slip that explains a value outside its plausible range, or None.

    Parameters
    ----------
    value : float
        The value as read, in the unit its column or argument states.
    plausible : (float, float)
        The closed range of plausible values, in that unit.
    slips : mapping of str to float
        Per unit a user may have written the value in by mistake, the factor that takes a
        number in that unit to the stated one (e.g. ``{"mW/(m K)": 1e-3}`` for a
        conductivity in W/(m K)); tried in order.

    Returns
    -------
    (str, float) or None
        The first slip whose converted value is plausible, and that value; None where the
        value is plausible or no slip makes it so (then the value is implausible for
        another reason, and a unit hint would mislead).
    """
    lo, hi = plausible
    if lo <= value <= hi:
        return None
    for unit, factor in slips.items():
        if lo <= value * factor <= hi:
            return unit, value * factor
    return None


def slip_hint(value: float, plausible: tuple[float, float], slips: Mapping[str, float],
              unit: str, *, subject: str = "it", result: str = "that") -> str | None:
    """``is it in mW/(m K)? (that would be 1.29 W/(m K))`` where :func:`unit_slip` finds a
    slip explaining ``value``, else None. ``unit`` is the stated unit (``""`` for none);
    ``subject`` names what may be in the other unit, ``result`` the corrected quantity."""
    slip = unit_slip(value, plausible, slips)
    if slip is None:
        return None
    name, converted = slip
    return f"is {subject} in {name}? ({result} would be {converted:.3g}" \
           f"{' ' + unit if unit else ''})"
