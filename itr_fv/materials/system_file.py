"""The material-system file (TOML): a lab's own composite, read and checked once.

::

    name = "ZnO in epoxy"

    [matrix]
    name = "epoxy"
    conductivity_W_per_mK = 0.19      # or conductivity_range_W_per_mK = [0.17, 0.25]
    conductivity_sd = 0.10            # relative; default: the handbook range's, else 0.10
    density_g_per_cm3 = 1.15          # default: the handbook's

    [[fillers]]
    name = "ZnO"                      # no conductivity: the handbook's value and range
    density_g_per_cm3 = 5.61
    size = { d10_um = 1.6, d50_um = 2.6, d90_um = 4.2, basis = "volume" }

    [resistances]                     # optional: known, held, not identified
    # R_AlN_silicone = 1.0e-8         # m^2 K/W

A phase named without a value takes the handbook's (:mod:`itr_fv.materials.handbook`):
its typical conductivity is the nominal one, its published range the prior (a lognormal
with that range as 90 % interval). A size is stated as :mod:`itr_fv.materials.size_statement`
reads it. Everything is checked before anything is packed or solved; a fault is one
ValueError naming the key (``fillers[1].size.d50_um: ...``).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from pathlib import Path

from ..checks import phase_name, slip_hint, unknown_key
from .handbook import handbook, handbook_phase, range_sd
from .material_system import Filler, MaterialSystem, check_density, check_relative_sd
from .parameters import parse_parameter
from .size_statement import stated_size

__all__ = ["read_system", "system_from_mapping", "CONDUCTIVITY_RANGE", "RESISTANCE_RANGE",
           "DEFAULT_MATRIX_SD", "DEFAULT_FILLER_SD"]

#: Conductivities of the phases of a composite, W/(m K) (an aerogel to diamond).
CONDUCTIVITY_RANGE = (0.01, 5000.0)
#: Interface resistances, m^2 K/W (a perfect epitaxial interface to a delaminated one).
RESISTANCE_RANGE = (1e-12, 1e-4)
#: Relative sd of a stated conductivity without sd or range, for a phase the handbook
#: lacks: a matrix measured by the lab (10 %), a filler's bulk value (25 %).
DEFAULT_MATRIX_SD = 0.10
DEFAULT_FILLER_SD = 0.25
_TOP = ("name", "matrix", "fillers", "resistances")
_PHASE = ("name", "conductivity_W_per_mK", "conductivity_range_W_per_mK", "conductivity_sd",
          "density_g_per_cm3")
_FILLER = (*_PHASE, "size")


def _number(value: object, where: str, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise ValueError(f"{where}: expected a number in {unit}, got {value!r}")
    return float(value)


def _conductivity(value: object, where: str) -> float:
    k = _number(value, where, "W/(m K)")
    lo, hi = CONDUCTIVITY_RANGE
    if k <= 0:
        raise ValueError(f"{where}: a conductivity is > 0 W/(m K), got {k:g}")
    if not lo <= k <= hi:
        hint = slip_hint(k, (lo, hi), {"mW/(m K)": 1e-3}, "W/(m K)")
        raise ValueError(f"{where}: {k:g} W/(m K) is outside {lo:g} - {hi:g} W/(m K), the "
                         f"conductivities of composite phases{'; ' + hint if hint else ''}")
    return k


def _phase_values(table: Mapping, where: str, role: str) -> tuple[str, float, float,
                                                                  float | None]:
    """(name, conductivity, relative sd, density) of a [matrix] or [[fillers]] table."""
    name = phase_name(table.get("name"), f"{where}.name")
    book = handbook().get(name)
    if book is not None and book.role != role:
        raise ValueError(f"{where}.name: {name!r} is a {book.role} in the handbook of phases, "
                         f"not a {role}")
    given, span = table.get("conductivity_W_per_mK"), table.get("conductivity_range_W_per_mK")
    sd = table.get("conductivity_sd")
    if span is not None:
        if not (isinstance(span, list) and len(span) == 2):
            raise ValueError(f"{where}.conductivity_range_W_per_mK: expected [low, high] in "
                             f"W/(m K), got {span!r}")
        low, high = (_conductivity(v, f"{where}.conductivity_range_W_per_mK")
                     for v in span)
        if not low < high:
            raise ValueError(f"{where}.conductivity_range_W_per_mK: expected low < high, "
                             f"got {span!r}")
        if sd is not None:
            raise ValueError(f"{where}.conductivity_sd: a range states the spread already; "
                             "give one of conductivity_sd and conductivity_range_W_per_mK")
        k = _conductivity(given, f"{where}.conductivity_W_per_mK") if given is not None \
            else math.sqrt(low * high)
        if not low <= k <= high:
            raise ValueError(f"{where}.conductivity_W_per_mK: {k:g} lies outside its range "
                             f"{low:g} - {high:g} W/(m K)")
        rel = range_sd(low, high)
    elif given is not None:
        k = _conductivity(given, f"{where}.conductivity_W_per_mK")
        default = DEFAULT_MATRIX_SD if role == "matrix" else DEFAULT_FILLER_SD
        rel = sd if sd is not None else (book.relative_sd if book else default)
    elif book is not None:
        k = book.conductivity
        rel = sd if sd is not None else book.relative_sd
    else:
        try:
            handbook_phase(name)
            hint = ""
        except ValueError as exc:
            hint = f" ({str(exc).partition('(')[2].partition(')')[0]})"
        raise ValueError(f"{where}.conductivity_W_per_mK: missing, and {name!r} is not in "
                         f"the handbook of phases{hint}; give its conductivity")
    rel = check_relative_sd(f"{where}.conductivity_sd", rel)
    rho = table.get("density_g_per_cm3", book.density if book else None)
    if rho is not None:
        rho = check_density(f"{where}.density_g_per_cm3", rho)
    return name, k, rel, rho


def _check_keys(table: object, known: tuple[str, ...], where: str) -> Mapping:
    if not isinstance(table, Mapping):
        raise ValueError(f"{where}: expected a table, got {table!r}")
    bad = unknown_key(table, known)
    if bad:
        raise ValueError(f"{where}: {bad}")
    return table


def system_from_mapping(data: Mapping, *, source: str = "") -> MaterialSystem:
    """The :class:`MaterialSystem` of a parsed system file (see the module notes).

    Parameters
    ----------
    data : mapping
        The file's tables.
    source : str
        Where it was read from, kept on the system for reports.

    Raises
    ------
    ValueError
        One line naming the key at fault.
    """
    _check_keys(data, _TOP, "system file")
    if "matrix" not in data:
        raise ValueError("matrix: missing ([matrix] with its name and conductivity)")
    matrix = _phase_values(_check_keys(data["matrix"], _PHASE, "matrix"), "matrix", "matrix")
    raw = data.get("fillers")
    if not isinstance(raw, list) or not raw:
        raise ValueError("fillers: expected one or more [[fillers]] tables, got "
                         f"{'none' if raw is None else repr(raw)}")
    fillers = []
    for i, table in enumerate(raw):
        where = f"fillers[{i}]"
        _check_keys(table, _FILLER, where)
        name, k, rel, rho = _phase_values(table, where, "filler")
        if "size" not in table:
            raise ValueError(f"{where}.size: missing (mu_ln_um/sigma_ln, d10_um/d50_um/d90_um "
                             "or a histogram)")
        size = stated_size(table["size"], f"{where}.size")
        fillers.append(Filler(name, k, size.psd, rho, conductivity_sd=rel,
                              size_note=size.note))
    names = [matrix[0], *(f.name for f in fillers)]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise ValueError(f"fillers: {dup!r} is named twice (each phase once, the matrix "
                         "not among the fillers)")
    resistances = _resistances(data.get("resistances", {}), names)
    label = data.get("name", Path(source).stem if source else "custom")
    if not isinstance(label, str) or not label:
        raise ValueError(f"name: expected a label, got {label!r}")
    return MaterialSystem(matrix[0], matrix[1], tuple(fillers), matrix[3],
                          matrix_conductivity_sd=matrix[2], resistances=resistances,
                          name=label, source=source)


def _resistances(table: object, phases: list[str]) -> tuple[tuple[str, float], ...]:
    if not isinstance(table, Mapping):
        raise ValueError(f"resistances: expected a table of R_<A>_<B> = m^2 K/W, got "
                         f"{table!r}")
    out = []
    for key, value in table.items():
        try:
            kind, parts = parse_parameter(key)
        except ValueError as exc:
            raise ValueError(f"resistances: {exc}") from None
        if kind != "R" or phases[0] not in parts or not set(parts) <= set(phases):
            raise ValueError(f"resistances.{key}: expected R_<filler>_<matrix> of this "
                             f"system's phases ({', '.join(phases)})")
        v = _number(value, f"resistances.{key}", "m^2 K/W")
        lo, hi = RESISTANCE_RANGE
        if not lo <= v <= hi:
            hint = slip_hint(v, (lo, hi), {"mm^2 K/W": 1e-6, "cm^2 K/W": 1e-4}, "m^2 K/W")
            raise ValueError(f"resistances.{key}: {v:g} m^2 K/W is outside {lo:g} - {hi:g} "
                             f"m^2 K/W{'; ' + hint if hint else ''}")
        out.append((key, v))
    return tuple(sorted(out))


def read_system(path: str | Path) -> MaterialSystem:
    """The material system of a TOML file (see the module notes); ValueError (one line,
    naming the file and the key) for a file that is missing, not TOML, or fails a check."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise ValueError(f"system: cannot read {str(path)!r} ({exc.strerror or exc})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"system {p.name}: not TOML ({exc})") from None
    try:
        return system_from_mapping(data, source=str(path))
    except ValueError as exc:
        raise ValueError(f"system {p.name}: {exc}") from None
