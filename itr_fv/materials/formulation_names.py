"""Formulation names and their composition: a Table 2 name, or ``<filler>-<vol%>`` and
``<filler>-<vol%>-<filler>-<vol%>`` (e.g. ``Al2O3-62``, ``Al2O3-30-AlN-30``).

The numbers are percent: a part below :data:`MIN_PERCENT` (``Al2O3-0.55``) reads as a
volume fraction written where a percentage belongs, and is refused.

A name a user writes (a measurement file, a command-line flag) goes through
:func:`formulation_name`, the one place names are matched: letter case is free
(``al2o3-55`` is ``Al2O3-55``); a near miss (O for 0, l or I for 1, another separator, a
close spelling: ``Al203-60``, ``AlN-6O``, ``A12O3-60``) is refused with a "did you mean".
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Collection

from . import paper_data

__all__ = ["fractions_of", "formulation_name", "UnknownFormulationError", "MIN_PERCENT"]

#: Smallest filler part a name may give, vol%: below it a 12 um RVE holds about one
#: particle, and a value such as 0.55 is a fraction meant as 55 %.
MIN_PERCENT = 1.0

_PART = re.compile(r"^(Al2O3|AlN)-(\d+(?:\.\d+)?)$")


def fractions_of(name: str) -> dict[str, float]:
    """Filler volume fractions (0-1) of a formulation name (Table 2 or ``<filler>-<vol%>``
    pairs); ValueError naming the formulation otherwise."""
    table2 = paper_data.formulations()
    if name in table2:
        return dict(table2[name])
    parts = name.split("-")
    out: dict[str, float] = {}
    for i in range(0, len(parts) - 1, 2):
        m = _PART.match(f"{parts[i]}-{parts[i + 1]}")
        if m is None or m.group(1) in out:
            break
        percent = float(m.group(2))
        if 0 < percent < MIN_PERCENT:
            raise ValueError(f"formulation {name!r}: {m.group(1)} at {percent:g} vol% looks "
                             f"like a volume fraction; the names give percent "
                             f"({m.group(1)}-{100 * percent:g} for {100 * percent:g} vol%)")
        out[m.group(1)] = percent / 100
    else:
        if out and len(parts) % 2 == 0 and 0 < sum(out.values()) < 0.7:
            return out
    raise ValueError(f"formulation {name!r}: expected a Table 2 name or <filler>-<vol%> "
                     "pairs of Al2O3 and AlN (e.g. Al2O3-62, Al2O3-30-AlN-30), below 70 vol% "
                     "in all")


# ----------------------------------------------------------------- names as users write them
_FILLERS = ("Al2O3", "AlN")
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


def _respelled(name: str, lookalikes: bool) -> str | None:
    """The formulation ``name`` reads as, spelled canonically: the Table 2 name, or the
    ``<filler>-<vol%>`` pairs with each filler spelled as :data:`_FILLERS` does, where they
    agree with ``name`` but for letter case (with ``lookalikes``: and for O/0, l/I/1,
    separators, a % sign, a close spelling of a filler); None where it reads as none."""
    key = _key(name, lookalikes)
    for t in paper_data.formulations():
        if _key(t, lookalikes) == key:
            return t
    parts = (_SEPARATORS if lookalikes else re.compile("-")).split(name.strip())
    if len(parts) < 2 or len(parts) % 2:
        return None
    out = []
    for text, number in zip(parts[::2], parts[1::2]):
        filler = next((f for f in _FILLERS if _key(f, lookalikes) == _key(text, lookalikes)),
                      None)
        if filler is None and lookalikes:
            close = difflib.get_close_matches(text.casefold(), [f.casefold() for f in _FILLERS],
                                              n=1, cutoff=0.6)
            filler = next((f for f in _FILLERS if close and f.casefold() == close[0]), None)
        if lookalikes:
            number = number.translate(str.maketrans("OoIl,", "0011.")).removesuffix("%")
        if filler is None or not _NUMBER.match(number):
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
                     known: Collection[str] | Callable[[str], object] | None = None) -> str:
    """The canonical spelling of a formulation a user named (the one place names are matched).

    Parameters
    ----------
    name : str
        As written (a cell of a measurement file, a flag's value).
    known : collection of str or callable, optional
        The names accepted (e.g. a campaign's), or a function that raises ValueError for a
        name it does not accept (default :func:`fractions_of`: a Table 2 name or
        ``<filler>-<vol%>`` pairs).

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
        return _by_rule(name, fractions_of if known is None else known)
    return _by_list(name, list(known))


def _by_rule(name: str, accepts: Callable[[str], object]) -> str:
    try:
        accepts(name)
        return name
    except ValueError as exc:
        error = exc
    cased = _respelled(name, lookalikes=False)
    if cased is not None and cased != name:
        accepts(cased)  # accepted but for case; or its own message (e.g. a fraction for a %)
        return cased
    near = _respelled(name, lookalikes=True)
    if near is None:  # not <filler>-<vol%> in shape (AlN60): the closest Table 2 name
        table2 = {t.casefold(): t for t in paper_data.formulations()}
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
