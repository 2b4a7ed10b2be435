"""Measured effective conductivities: tables, the tester's data reduction, replicate statistics.

Two kinds of CSV file:

- a *measurement table* (the paper's Table 3 is shipped and the default):
  ``formulation,replicate,k_W_per_mK``, one row per sample, with an optional
  ``thickness_mm`` column: the thickness at which an apparent conductivity was measured
  (read by the discrepancy workflow, :mod:`itr_identify.discrepancy`);
- *tester readings* (Methods, Eqs. 7-10): ``formulation,replicate,thickness_mm,
  impedance_K_mm2_per_W``, the thermal impedance ``I = A dT / Q`` of one sample at several
  thicknesses. The contact resistance between sample and meter bars is the intercept of
  ``I = a t + b`` (Eq. 8), so ``K = 1 / a`` (Eq. 10) with the slope's standard error.

Files are read as spreadsheets save them: UTF-8 with or without a byte-order mark ("CSV
UTF-8"), any line endings. Every formulation needs at least two replicates that differ (their
variance enters the likelihood of :mod:`itr_identify.inference.calibrate`). Formulation names
are those of :func:`~itr_identify.inference.formulations.fractions_of` (Table 2 or
``<filler>-<vol%>``), as on the command line, matched by
:func:`~itr_identify.inference.formulations.formulation_name`: in any letter case (the
canonical spelling is kept), and a near miss (``Al203-60``) is refused with a "did you mean".
Values are checked for physical sense while they are read
(:mod:`~itr_identify.inference.plausibility`: a conductivity no resistance can reach, a
thickness that is no sample's), before any solve. Errors are ValueErrors that name the file,
the line and the column.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from itr_fv.materials import default_system
from itr_fv.materials.material_system import MaterialSystem

from .formulations import formulation_name, reader_for
from .plausibility import (
    IMPEDANCE_SLIPS,
    check_auxiliary,
    check_conductivity,
    check_thickness,
)

__all__ = ["Measurements", "read_measurements", "read_tester_readings", "AUXILIARY_COLUMNS",
           "conductivity_from_impedance", "TABLE3"]

TABLE_COLUMNS = ("formulation", "replicate", "k_W_per_mK")
THICKNESS_COLUMN = "thickness_mm"
#: Optional per-sample observables besides k (blank cells allowed): the sample density,
#: the filler mass fraction, the powder's number-median diameter.
AUXILIARY_COLUMNS = ("density_g_per_cm3", "filler_mass_fraction", "d50_um")
READING_COLUMNS = ("formulation", "replicate", "thickness_mm", "impedance_K_mm2_per_W")


#: The paper's Table 3, shipped with the package.
TABLE3 = "paper Table 3"


@dataclass(frozen=True)
class Measurements:
    """Replicate conductivities per formulation, W/(m K).

    Attributes
    ----------
    values : dict of str to ndarray
        Replicate values per formulation, in file order.
    source : str
        Where they came from.
    thickness_m : dict of str to ndarray, optional
        Sample thickness of each replicate, m (where the table has a ``thickness_mm``
        column).
    auxiliary : dict of str to (dict of str to ndarray), optional
        Per column of :data:`AUXILIARY_COLUMNS` the table has: per formulation, one value
        per replicate (NaN: not measured on that sample), in the column's unit.
    """

    values: dict[str, np.ndarray]
    source: str
    thickness_m: dict[str, np.ndarray] | None = None
    auxiliary: dict[str, dict[str, np.ndarray]] | None = None

    def auxiliary_of(self, column: str, formulation: str) -> np.ndarray | None:
        """The replicate values of an auxiliary ``column`` of ``formulation`` (NaN where a
        sample was not measured); None where the table has no such column."""
        if column not in AUXILIARY_COLUMNS:
            raise ValueError(f"column: expected one of {AUXILIARY_COLUMNS}, got {column!r}")
        if not self.auxiliary or column not in self.auxiliary:
            return None
        return self.auxiliary[column].get(formulation)

    @property
    def auxiliary_columns(self) -> list[str]:
        """The auxiliary columns the table holds a value in."""
        return [c for c in AUXILIARY_COLUMNS if self.auxiliary and c in self.auxiliary
                and any(np.isfinite(v).any() for v in self.auxiliary[c].values())]

    @property
    def formulations(self) -> list[str]:
        return list(self.values)

    def mean(self, formulation: str) -> float:
        """Replicate mean, W/(m K)."""
        return float(self._get(formulation).mean())

    def variance(self, formulation: str) -> float:
        """Replicate (sample, ddof=1) variance, (W/(m K))^2."""
        return float(self._get(formulation).var(ddof=1))

    def standard_error(self, formulation: str) -> float:
        """Standard error of the mean, W/(m K)."""
        v = self._get(formulation)
        return float(v.std(ddof=1) / math.sqrt(v.size))

    def _get(self, formulation: str) -> np.ndarray:
        if formulation not in self.values:
            raise ValueError(f"formulation: {formulation!r} is not measured (measured: "
                             f"{self.formulations})")
        return self.values[formulation]

    def without(self, formulation: str) -> "Measurements":
        """The same table without one formulation (leave-one-out)."""
        self._get(formulation)
        t = None if self.thickness_m is None else {
            k: v for k, v in self.thickness_m.items() if k != formulation}
        aux = None if self.auxiliary is None else {
            c: {k: v for k, v in per.items() if k != formulation}
            for c, per in self.auxiliary.items()}
        return Measurements({k: v for k, v in self.values.items() if k != formulation},
                            f"{self.source} without {formulation}", t, aux)


def _read_text(path: Path) -> str:
    """The text of a user's file: UTF-8, a byte-order mark (a spreadsheet's "CSV UTF-8")
    dropped."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ValueError(f"path: {str(path)!r} does not exist") from None
    except IsADirectoryError:
        raise ValueError(f"path: {str(path)!r} is a folder, not a file") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        utf16 = data.startswith((b"\xff\xfe", b"\xfe\xff"))
        raise ValueError(f"path: {str(path)!r} is not a UTF-8 text file"
                         + (" (it is UTF-16, a spreadsheet's 'Unicode text')" if utf16 else "")
                         + "; save it as 'CSV UTF-8'") from None


def _rows(path: Path, text: str, columns: tuple[str, ...]) -> list[tuple[int, dict[str, str]]]:
    """Data rows of the CSV ``text`` (``path`` names it in errors) with their line numbers."""
    reader = csv.DictReader(text.splitlines())
    header = [h.strip() for h in (reader.fieldnames or [])]
    missing = [c for c in columns if c not in header]
    if missing and len(header) == 1:
        for sep, what in ((";", "semicolons"), ("\t", "tabs")):
            if sep in header[0]:
                raise ValueError(f"{path.name}: the columns are separated by {what}; expected "
                                 f"a comma-separated file with the columns "
                                 f"{', '.join(columns)} (and '.' as the decimal mark)")
    if missing:
        raise ValueError(f"{path.name}: missing column {missing[0]!r} (expected "
                         f"{', '.join(columns)}; found {', '.join(header) or 'nothing'})")
    out = []
    for i, row in enumerate(reader, start=2):
        row = {k.strip(): (v or "").strip() for k, v in row.items() if k is not None}
        if not any(row.values()):
            continue
        out.append((i, row))
    if not out:
        raise ValueError(f"{path.name}: no data rows")
    return out


def _number(path: Path, line: int, row: dict, column: str, *, positive: bool = True) -> float:
    text = row.get(column, "")
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{path.name} line {line}: {column} is not a number: {text!r}") from None
    if not math.isfinite(v) or (positive and v <= 0):
        raise ValueError(f"{path.name} line {line}: {column} must be finite and > 0, got {text}")
    return v


def _formulation(path: Path, line: int, name: str, known, system: MaterialSystem) -> str:
    """The canonical name of the formulation cell ``name`` (see
    :func:`~itr_identify.inference.formulations.formulation_name`)."""
    if not name:
        raise ValueError(f"{path.name} line {line}: empty formulation")
    try:
        return formulation_name(name, known, system=system)
    except ValueError as exc:
        raise ValueError(f"{path.name} line {line}: {exc}") from None


def _finish(path: Path, values: dict[str, list[float]], source: str,
            thickness: dict[str, list[float]] | None = None,
            auxiliary: dict[str, dict[str, list[float]]] | None = None) -> Measurements:
    for name, v in values.items():
        if len(v) < 2:
            raise ValueError(f"{path.name}: formulation {name!r} has {len(v)} replicate; at "
                             "least 2 are needed for its variance")
        if max(v) == min(v):
            raise ValueError(f"{path.name}: the {len(v)} replicates of {name!r} are all "
                             f"{v[0]:g}; their variance (zero) enters the likelihood, so they "
                             "must be separate measurements")
    t = None if not thickness else {k: np.array(v) * 1e-3 for k, v in thickness.items()}
    aux = None if not auxiliary else {c: {k: np.array(v, dtype=float) for k, v in per.items()}
                                      for c, per in auxiliary.items()}
    return Measurements({k: np.array(v) for k, v in values.items()}, source, t, aux)


def _known(formulations: set[str] | Callable[[str], object] | None,
           system: MaterialSystem) -> set[str] | Callable[[str], object]:
    if formulations is None:
        return reader_for(system)
    return formulations if callable(formulations) else set(formulations)


def read_measurements(path: str | Path | None = None, *,
                      formulations: set[str] | Callable[[str], object] | None = None,
                      system: MaterialSystem | None = None) -> Measurements:
    """A measurement table (default: the paper's Table 3, shipped).

    Parameters
    ----------
    path : str or Path, optional
        CSV (UTF-8, a byte-order mark allowed) with columns
        ``formulation,replicate,k_W_per_mK`` and optionally ``thickness_mm`` (then on every
        row).
    formulations : set of str or callable, optional
        Names the table may use, or a function that raises ValueError for a name it does not
        accept (default: :func:`itr_identify.inference.formulations.fractions_of` of
        ``system``, the command line's: named formulations, ``<filler>-<vol%>`` and
        ``<filler>-<wt%>wt`` parts). Matched in any letter case; the result is keyed by the
        canonical spelling (``al2o3-55`` -> ``Al2O3-55``).
    system : MaterialSystem, optional
        The phases: their conductivities bound a measured k, their densities a sample's
        density (default: the package's default system, the paper's).

    Raises
    ------
    ValueError
        Naming file, line and column: missing column (or a separator other than the comma),
        non-numeric, NaN, zero or negative k, k above what any resistance allows, unknown or
        fraction-like formulation (a near miss such as ``Al203-60`` with "did you mean
        'Al2O3-60'?"), a replicate given twice, fewer than 2 replicates or
        identical ones, a missing, non-positive or implausible thickness where the column
        exists; an auxiliary value no sample of the formulation can have
        (:mod:`~itr_identify.inference.plausibility`: a density outside the range of its
        phases' mixtures, a mass fraction outside 0-1, a powder median far from the
        material system's).

    Warns
    -----
    itr_identify.inference.plausibility.ImplausibleMeasurementWarning
        A k below the matrix's conductivity.
    """
    if path is None:
        from itr_fv.materials import paper_data

        p, text = Path("measured_tc.csv"), paper_data.table_text("measured_tc")
    else:
        p = Path(path)
        text = _read_text(p)
    system = system or default_system()
    known = _known(formulations, system)
    values: dict[str, list[float]] = {}
    thickness: dict[str, list[float]] = {}
    seen: set[tuple[str, str]] = set()
    rows = _rows(p, text, TABLE_COLUMNS)
    with_thickness = THICKNESS_COLUMN in rows[0][1]
    aux_columns = [c for c in AUXILIARY_COLUMNS if c in rows[0][1]]
    auxiliary: dict[str, dict[str, list[float]]] = {c: {} for c in aux_columns}
    for line, row in rows:
        name = _formulation(p, line, row["formulation"], known, system)
        rep = row["replicate"]
        if (name, rep) in seen:
            raise ValueError(f"{p.name} line {line}: replicate {rep!r} of {name!r} given twice")
        seen.add((name, rep))
        k = _number(p, line, row, "k_W_per_mK")
        check_conductivity(f"{p.name} line {line}", name, k, system=system)
        values.setdefault(name, []).append(k)
        if with_thickness:
            t = _number(p, line, row, THICKNESS_COLUMN)
            check_thickness(f"{p.name} line {line}", t)
            thickness.setdefault(name, []).append(t)
        for c in aux_columns:
            v = math.nan
            if row.get(c, ""):
                v = check_auxiliary(f"{p.name} line {line}", name, c,
                                    _number(p, line, row, c, positive=False), system)
            auxiliary[c].setdefault(name, []).append(v)
    auxiliary = {c: per for c, per in auxiliary.items()
                 if any(math.isfinite(x) for v in per.values() for x in v)}
    return _finish(p, values, TABLE3 if path is None else str(p), thickness, auxiliary)


def conductivity_from_impedance(thickness_m: np.ndarray,
                                impedance_m2K_per_W: np.ndarray) -> tuple[float, float]:
    """``K = 1 / a`` from ``I = a t + b`` (Eqs. 8-10) and its standard error.

    Parameters
    ----------
    thickness_m : array
        Sample thicknesses t, m, strictly increasing, at least 2.
    impedance_m2K_per_W : array
        Thermal impedances I = A dT / Q at those thicknesses, m^2 K/W.

    Returns
    -------
    K : float
        Conductivity, W/(m K).
    sigma_K : float
        Its standard error from the slope's (``sigma_a / a^2``), W/(m K); NaN with 2 points.
    """
    t = np.asarray(thickness_m, dtype=np.float64)
    imp = np.asarray(impedance_m2K_per_W, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or imp.shape != t.shape:
        raise ValueError("thickness_m, impedance_m2K_per_W: expected two 1-D arrays of the "
                         "same length >= 2")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(imp))):
        raise ValueError("thickness_m, impedance_m2K_per_W: NaN or inf")
    if np.any(np.diff(t) <= 0):
        raise ValueError("thickness_m: thicknesses must increase")
    A = np.column_stack([t, np.ones_like(t)])
    (a, b), *_ = np.linalg.lstsq(A, imp, rcond=None)
    if a <= 0:
        raise ValueError(f"impedance_m2K_per_W: the impedance does not grow with thickness "
                         f"(slope {a:.3g} m K/W); K = 1/a needs a positive slope")
    if t.size == 2:
        return float(1.0 / a), math.nan
    resid = imp - A @ np.array([a, b])
    s2 = float(resid @ resid) / (t.size - 2)
    var_a = s2 / float(np.sum((t - t.mean()) ** 2))
    return float(1.0 / a), float(math.sqrt(var_a) / a ** 2)


def read_tester_readings(path: str | Path, *,
                         formulations: set[str] | Callable[[str], object] | None = None,
                         system: MaterialSystem | None = None) -> Measurements:
    """Tester readings (impedance vs thickness per sample) reduced to one K per replicate.

    Columns ``formulation,replicate,thickness_mm,impedance_K_mm2_per_W``; the rows of one
    (formulation, replicate) are one sample, in increasing thickness.
    """
    p = Path(path)
    system = system or default_system()
    known = _known(formulations, system)
    samples: dict[tuple[str, str], list[tuple[int, float, float]]] = {}
    for line, row in _rows(p, _read_text(p), READING_COLUMNS):
        name = _formulation(p, line, row["formulation"], known, system)
        t_mm = _number(p, line, row, "thickness_mm")
        check_thickness(f"{p.name} line {line}", t_mm)
        t = t_mm * 1e-3
        imp = _number(p, line, row, "impedance_K_mm2_per_W") * 1e-6
        samples.setdefault((name, row["replicate"]), []).append((line, t, imp))
    values: dict[str, list[float]] = {}
    for (name, rep), pts in samples.items():
        ts = np.array([q[1] for q in pts])
        if ts.size < 2:
            raise ValueError(f"{p.name} line {pts[0][0]}: sample {name!r} replicate {rep!r} "
                             "has one thickness; Eq. 8 needs at least 2")
        if np.any(np.diff(ts) <= 0):
            bad = pts[int(np.flatnonzero(np.diff(ts) <= 0)[0]) + 1][0]
            raise ValueError(f"{p.name} line {bad}: thicknesses of {name!r} replicate {rep!r} "
                             "do not increase")
        try:
            k, _ = conductivity_from_impedance(ts, np.array([q[2] for q in pts]))
        except ValueError as exc:
            raise ValueError(f"{p.name} line {pts[0][0]}: {name!r} replicate {rep!r}: "
                             f"{exc}") from None
        check_conductivity(f"{p.name} lines {pts[0][0]}-{pts[-1][0]}", name, k,
                           system=system, column="K = 1/slope of impedance_K_mm2_per_W",
                           slips=IMPEDANCE_SLIPS, subject="impedance_K_mm2_per_W")
        values.setdefault(name, []).append(k)
    return _finish(p, values, str(p))
