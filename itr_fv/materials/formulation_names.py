"""Formulation names and their composition, against a material system: a name the system
gives (the paper's Table 2), or ``<filler>-<vol%>`` parts of the system's fillers
(``ZnO-50``, ``Al2O3-30-AlN-30``), or ``<filler>-<wt%>wt`` parts (``ZnO-80wt``,
converted to volume fractions with the system's densities).

The numbers are percent: a part below :data:`MIN_PERCENT` (``Al2O3-0.55``) reads as a
volume fraction written where a percentage belongs, and is refused. The parts of one name
are all by volume or all by mass; a mass share sums to less than 100 wt%, a volume share
below :data:`MAX_VOLUME_FRACTION`.

A name a user writes (a measurement file, a command-line flag) goes through
:func:`formulation_name`, the one place names are matched: letter case is free
(``al2o3-55`` is ``Al2O3-55``); a near miss (O for 0, l or I for 1, another separator, a
close spelling: ``Al203-60``, ``AlN-6O``, ``A12O3-60``) is refused with a "did you mean".
Without a system, names are read against the package's default (the paper's).
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Collection

from .material_system import MaterialSystem

__all__ = ["fractions_of", "formulation_name", "UnknownFormulationError", "MIN_PERCENT",
           "MAX_VOLUME_FRACTION", "reader_for"]

#: Smallest filler part a name may give, vol% or wt%: below it a 12 um RVE holds about one
#: particle, and a value such as 0.55 is a fraction meant as 55 %.
MIN_PERCENT = 1.0
#: Total filler volume fraction a formulation stays below (dense random packing of
#: polydisperse spheres, with the matrix film the packer keeps).
MAX_VOLUME_FRACTION = 0.7
_NUMBER_PART = re.compile(r"(\d+(?:\.\d+)?)(wt)?(?=-|$)")


def _system(system: MaterialSystem | None) -> MaterialSystem:
    if system is None:
        from . import default_system
        return default_system()
    return system


def _expected(system: MaterialSystem) -> str:
    fillers = system.filler_names
    example = "-".join(f"{f}-30" for f in fillers[:2])
    named = "a named formulation or " if system.named else ""
    return (f"expected {named}<filler>-<vol%> or <filler>-<wt%>wt parts of "
            f"{' and '.join(fillers) if len(fillers) < 3 else ', '.join(fillers)} "
            f"(e.g. {fillers[0]}-50, {example}, {fillers[0]}-80wt), below "
            f"{100 * MAX_VOLUME_FRACTION:g} vol% in all")


def _parts(name: str, system: MaterialSystem) -> list[tuple[str, float, bool]] | None:
    """``(filler, percent, by_mass)`` of each part of ``name``, or None where it is not
    made of the system's fillers."""
    fillers = sorted(system.filler_names, key=len, reverse=True)
    out, i = [], 0
    while i < len(name):
        filler = next((f for f in fillers if name.startswith(f + "-", i)), None)
        if filler is None:
            return None
        i += len(filler) + 1
        m = _NUMBER_PART.match(name, i)
        if m is None:
            return None
        out.append((filler, float(m.group(1)), m.group(2) is not None))
        i = m.end() + 1 if m.end() < len(name) else m.end()
        if m.end() < len(name) and i >= len(name):
            return None
    return out or None


def fractions_of(name: str, system: MaterialSystem | None = None) -> dict[str, float]:
    """Filler volume fractions (0-1) of a formulation name; ValueError naming the
    formulation otherwise.

    Parameters
    ----------
    name : str
        A name ``system`` gives, or ``<filler>-<vol%>`` / ``<filler>-<wt%>wt`` parts.
    system : MaterialSystem, optional
        Whose fillers, names and densities (default: the package's default system).
    """
    system = _system(system)
    named = system.named_formulations()
    if name in named:
        return dict(named[name])
    parts = _parts(name, system) if isinstance(name, str) else None
    if parts is None:
        unknown = re.match(r"^([A-Za-z][A-Za-z0-9.+]*)-\d", name) if isinstance(name, str) \
            else None
        if unknown and unknown.group(1) not in system.filler_names \
                and not any(f.casefold() == unknown.group(1).casefold()
                            for f in system.filler_names):
            raise ValueError(f"formulation {name!r}: {unknown.group(1)} is not a filler of "
                             f"the material system {system.name!r} (fillers: "
                             f"{', '.join(system.filler_names)})")
        raise ValueError(f"formulation {name!r}: {_expected(system)}")
    fillers = [f for f, _, _ in parts]
    if len(set(fillers)) != len(fillers):
        raise ValueError(f"formulation {name!r}: each filler once; {_expected(system)}")
    for filler, percent, by_mass in parts:
        if 0 < percent < MIN_PERCENT:
            unit = "wt%" if by_mass else "vol%"
            raise ValueError(f"formulation {name!r}: {filler} at {percent:g} {unit} looks "
                             f"like a volume fraction; the names give percent "
                             f"({filler}-{100 * percent:g} for {100 * percent:g} {unit})")
    if len({m for _, _, m in parts}) != 1:
        raise ValueError(f"formulation {name!r}: give every part by volume or every part "
                         "by mass (wt), not both")
    if parts[0][2]:
        out = _by_mass(name, parts, system)
    else:
        out = {f: p / 100 for f, p, _ in parts}
    if not 0 < sum(out.values()) < MAX_VOLUME_FRACTION:
        raise ValueError(f"formulation {name!r}: {100 * sum(out.values()):.4g} vol% of filler "
                         f"in all; {_expected(system)}")
    return out


def _by_mass(name: str, parts: list[tuple[str, float, bool]],
             system: MaterialSystem) -> dict[str, float]:
    """Volume fractions of mass percentages, with the system's densities."""
    total = sum(p for _, p, _ in parts)
    if not total < 100:
        raise ValueError(f"formulation {name!r}: {total:g} wt% of filler in all; a mass "
                         "share is below 100 wt%")
    try:
        rho = system.densities([f for f, _, _ in parts])
    except ValueError as exc:
        raise ValueError(f"formulation {name!r}: a wt% needs the densities; {exc}") from None
    volumes = {f: p / rho[f] for f, p, _ in parts}
    matrix = (100 - total) / rho[system.matrix]
    whole = sum(volumes.values()) + matrix
    return {f: v / whole for f, v in volumes.items()}


def reader_for(system: MaterialSystem | None) -> Callable[[str], dict[str, float]]:
    """``fractions_of`` bound to ``system``: what a measurement reader accepts."""
    system = _system(system)
    return lambda name: fractions_of(name, system)


# ----------------------------------------------------------------- names as users write them
#: Characters read for one another (after case folding): the letter O for 0, l and I for 1.
_LOOKALIKE = str.maketrans("oli", "011")
#: Separators written for the hyphen: space, underscore, the Unicode dashes and minus sign.
_SEPARATORS = re.compile(r"\s*[-_\u2010-\u2015\u2212\s]\s*")
_NUMBER = re.compile(r"^\d+(?:\.\d+)?$")


class UnknownFormulationError(ValueError):
    """A formulation name that is not accepted; ``suggestion`` is the name it reads as
    (a near miss), or None."""

    def __init__(self, message: str, suggestion: str | None = None) -> None:
        super().__init__(message)
        self.suggestion = suggestion


def _key(text: str, lookalikes: bool) -> str:
    """``text`` case-folded; with ``lookalikes`` also O/0 and l/I/1 folded, separators unified,
    a decimal comma read as a point and % signs dropped."""
    key = text.strip().casefold()
    if lookalikes:
        key = _SEPARATORS.sub("-", key.translate(_LOOKALIKE)).replace(",", ".")
        key = key.replace("%", "")
    return key


def _respelled(name: str, lookalikes: bool, system: MaterialSystem) -> str | None:
    """The formulation ``name`` reads as, spelled canonically: the Table 2 name, or the
    ``<filler>-<vol%>`` pairs with each filler spelled as :data:`fillers` does, where they
    agree with ``name`` but for letter case (with ``lookalikes``: and for O/0, l/I/1,
    separators, a % sign, a close spelling of a filler); None where it reads as none."""
    key = _key(name, lookalikes)
    for t in system.named_formulations():
        if _key(t, lookalikes) == key:
            return t
    fillers = system.filler_names
    parts = (_SEPARATORS if lookalikes else re.compile("-")).split(name.strip())
    if len(parts) < 2 or len(parts) % 2:
        return None
    out = []
    for text, number in zip(parts[::2], parts[1::2]):
        filler = next((f for f in fillers if _key(f, lookalikes) == _key(text, lookalikes)),
                      None)
        if filler is None and lookalikes:
            close = difflib.get_close_matches(text.casefold(), [f.casefold() for f in fillers],
                                              n=1, cutoff=0.6)
            filler = next((f for f in fillers if close and f.casefold() == close[0]), None)
        if lookalikes:
            number = number.translate(str.maketrans("OoIl,", "0011.")).removesuffix("%")
        number = number[:-2] + "wt" if number.casefold().endswith("wt") else number
        if filler is None or not _NUMBER.match(number.removesuffix("wt")):
            return None
        out += [filler, number]
    return "-".join(out)


_CHARACTERS = {"0": "the digit 0", "O": "the letter O", "o": "the letter o",
               "1": "the digit 1", "l": "the letter l", "I": "the letter I", "i": "the letter i"}


def _did_you_mean(name: str, suggestion: str) -> str:
    """The one-line refusal of a near miss; where the two differ by look-alike characters
    (which the same font may draw alike), it says which."""
    message = f"formulation {name!r} is unknown; did you mean {suggestion!r}?"
    if len(name) == len(suggestion):
        swaps = [f"{_CHARACTERS[a]} for {_CHARACTERS[b]} at character {i + 1}"
                 for i, (a, b) in enumerate(zip(name, suggestion))
                 if a.casefold() != b.casefold() and a in _CHARACTERS and b in _CHARACTERS]
        if swaps:
            message += f" ({'; '.join(swaps)})"
    return message


def formulation_name(name: str,
                     known: Collection[str] | Callable[[str], object] | None = None, *,
                     system: MaterialSystem | None = None) -> str:
    """The canonical spelling of a formulation a user named (the one place names are matched).

    Parameters
    ----------
    name : str
        As written (a cell of a measurement file, a flag's value).
    known : collection of str or callable, optional
        The names accepted (e.g. a campaign's), or a function that raises ValueError for a
        name it does not accept (default :func:`fractions_of` of ``system``).
    system : MaterialSystem, optional
        Whose fillers and named formulations a near miss is matched against (default:
        the package's default system).

    Returns
    -------
    str
        ``name`` where it is accepted as written; the accepted name it equals but for letter
        case otherwise (``al2o3-55`` -> ``Al2O3-55``).

    Raises
    ------
    UnknownFormulationError
        (a ValueError, one line, naming the formulation) for any other name; for a near
        miss, a name that differs from an accepted one by O for 0, l or I for 1, another
        separator or a close spelling (``Al203-60``, ``AlN-6O``, ``A12O3-60``), it ends in
        "did you mean 'Al2O3-60'?" and carries that name as ``suggestion``. A near miss is
        never accepted silently: ``Al203-60`` might be a typo, or a file meant for another
        table.
    """
    if known is None or callable(known):
        return _by_rule(name, reader_for(system) if known is None else known, _system(system))
    return _by_list(name, list(known))


def _by_rule(name: str, accepts: Callable[[str], object], system: MaterialSystem) -> str:
    try:
        accepts(name)
        return name
    except ValueError as exc:
        error = exc
    cased = _respelled(name, False, system)
    if cased is not None and cased != name:
        accepts(cased)  # accepted but for case; or its own message (e.g. a fraction for a %)
        return cased
    near = _respelled(name, True, system)
    if near is None:  # not <filler>-<vol%> in shape (AlN60): the closest named formulation
        table2 = {t.casefold(): t for t in system.named_formulations()}
        close = difflib.get_close_matches(name.casefold(), list(table2), n=1, cutoff=0.85)
        near = table2[close[0]] if close else None
    if near is not None and near != name:
        try:
            accepts(near)
        except ValueError:
            pass
        else:
            raise UnknownFormulationError(_did_you_mean(name, near), near) from None
    raise UnknownFormulationError(str(error)) from None


def _by_list(name: str, known: list[str]) -> str:
    if name in known:
        return name
    listing = ", ".join(sorted(known))
    cased = [k for k in known if _key(k, False) == _key(name, False)]
    if len(cased) == 1:
        return cased[0]
    near = cased or [k for k in known if _key(k, True) == _key(name, True)]
    if not near:
        folded = {k.casefold(): k for k in known}
        near = [folded[c] for c in difflib.get_close_matches(name.casefold(), list(folded),
                                                            n=1, cutoff=0.75)]
    if near:
        raise UnknownFormulationError(f"{_did_you_mean(name, near[0])} (known: {listing})",
                                      near[0])
    raise UnknownFormulationError(f"unknown formulation {name!r} (known: {listing})")
