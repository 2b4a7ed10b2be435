"""The phase table of a segmented volume: which phase of a material system each label value
is (``0 = matrix, 1 = Al2O3, 2 = AlN``), read from ``LABEL=PHASE`` items or a small TOML
file, and checked against the volume before any work.

::

    # phases.toml
    [phases]
    0 = "matrix"        # the material system's matrix (or its name, e.g. "silicone")
    1 = "Al2O3"
    2 = "AlN"

Several labels may name the same phase. Every label of the volume must be in the table and
every label of the table must hold voxels (a label with none is a typo more often than not).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..checks import phase_name
from ..io import read_toml
from .microstructure import label_counts

__all__ = ["PhaseTable", "MATRIX_ALIAS", "label_values"]

#: The word that stands for the material system's matrix in a phase table.
MATRIX_ALIAS = "matrix"


def _label(text: object, argument: str) -> int:
    try:
        value = int(str(text).strip())
    except ValueError:
        raise ValueError(f"{argument}: expected LABEL=PHASE with an integer label >= 0, got "
                         f"{text!r}") from None
    if value < 0:
        raise ValueError(f"{argument}: labels are integers >= 0, got {value}")
    return value


@dataclass(frozen=True)
class PhaseTable:
    """Label value -> phase name, the matrix named.

    Attributes
    ----------
    entries : tuple of (int, str)
        ``(label, phase)`` pairs, sorted by label; the matrix appears under its name.
    matrix : str
        The matrix phase (a material system's :attr:`~itr_fv.materials.material_system.
        MaterialSystem.matrix`).
    """

    entries: tuple[tuple[int, str], ...]
    matrix: str

    @classmethod
    def of(cls, mapping: Mapping[int, str], matrix: str, *,
           argument: str = "phases") -> PhaseTable:
        """From ``{label: phase}``; ``"matrix"`` stands for ``matrix``. ValueError naming
        ``argument`` for a bad label or phase name, or a table without the matrix."""
        phase_name(matrix, "matrix")
        if not isinstance(mapping, Mapping) or not mapping:
            raise ValueError(f"{argument}: expected at least one LABEL=PHASE")
        out = {}
        for key, value in mapping.items():
            label = _label(key, argument)
            name = matrix if value == MATRIX_ALIAS else phase_name(value, argument)
            if label in out and out[label] != name:
                raise ValueError(f"{argument}: label {label} given twice ({out[label]}, {name})")
            out[label] = name
        if matrix not in out.values():
            raise ValueError(f"{argument}: no label is the matrix ({matrix}); give "
                             f"LABEL=matrix")
        return cls(tuple(sorted(out.items())), matrix)

    @classmethod
    def parse(cls, items: Iterable[str], matrix: str, *, argument: str = "phases"
              ) -> PhaseTable:
        """From ``LABEL=PHASE`` texts (``["0=matrix", "1=Al2O3"]``)."""
        mapping: dict[int, str] = {}
        for item in items:
            label, sep, phase = str(item).partition("=")
            if not sep or not phase.strip():
                raise ValueError(f"{argument}: expected LABEL=PHASE, got {item!r}")
            key = _label(label, argument)
            if key in mapping and mapping[key] != phase.strip():
                raise ValueError(f"{argument}: label {key} given twice ({mapping[key]}, "
                                 f"{phase.strip()})")
            mapping[key] = phase.strip()
        return cls.of(mapping, matrix, argument=argument)

    @classmethod
    def read(cls, path: str | os.PathLike, matrix: str, *, argument: str = "phases"
             ) -> PhaseTable:
        """From the ``[phases]`` table of a TOML file (see the module notes)."""
        try:
            data = read_toml(path, "phase table")
        except ValueError as exc:
            raise ValueError(f"{argument}: {exc}") from None
        extra = sorted(set(data) - {"phases"})
        if extra or not isinstance(data.get("phases"), Mapping):
            raise ValueError(f"{argument}: {path}: expected one table [phases] of LABEL = "
                             f"\"PHASE\"{f', got key {extra[0]!r}' if extra else ''}")
        return cls.of(data["phases"], matrix, argument=f"{argument}: {path}: phases")

    # ------------------------------------------------------------------------ use
    @property
    def phases(self) -> tuple[str, ...]:
        """The phases, the matrix first, then the fillers in label order."""
        fillers = [p for _, p in self.entries if p != self.matrix]
        return (self.matrix, *dict.fromkeys(fillers))

    @property
    def fillers(self) -> tuple[str, ...]:
        return self.phases[1:]

    def as_dict(self) -> dict[int, str]:
        return dict(self.entries)

    def check_phases(self, known: Sequence[str], *, argument: str = "phases",
                     where: str = "the material system") -> None:
        """ValueError naming ``argument`` where a phase is not one of ``known``."""
        for label, name in self.entries:
            if name not in known:
                raise ValueError(f"{argument}: label {label} is {name!r}, which is not a phase "
                                 f"of {where} (phases: {', '.join(known)})")

    def material_ids(self, labels: np.ndarray, *, argument: str = "volume") -> np.ndarray:
        """Material id per voxel (0 = matrix, ``i`` = ``phases[i]``), int32.

        Raises
        ------
        ValueError
            Naming ``argument`` for a label of the volume that the table lacks, or
            ``phases`` for a label of the table that no voxel holds.
        """
        values, counts, lookup = label_values(labels)
        table = self.as_dict()
        missing = [int(v) for v in values if int(v) not in table]
        if missing:
            n = int(counts[np.searchsorted(values, missing[0])])
            raise ValueError(f"{argument}: label {missing[0]} ({n} voxels) is not in the phase "
                             f"table{f' (nor {len(missing) - 1} more)' if len(missing) > 1 else ''}"
                             f"; give its phase (LABEL=PHASE; labels in the volume: "
                             f"{_listed(values)})")
        empty = [(lab, p) for lab, p in self.entries if lab not in set(values.tolist())]
        if empty:
            lab, p = empty[0]
            raise ValueError(f"phases: label {lab} ({p}) has no voxels in the volume (labels "
                             f"in the volume: {_listed(values)})")
        index = {p: i for i, p in enumerate(self.phases)}
        lut = np.array([index[table[int(v)]] for v in values], dtype=np.int32)
        return lookup(lut)

    def to_dict(self) -> dict:
        return {"matrix": self.matrix, "labels": {str(k): v for k, v in self.entries}}


#: Largest label value looked up through a dense table (bincount) rather than a sort.
DENSE_LABELS = 1 << 22


def label_values(labels: np.ndarray):
    """The label values present (sorted), their voxel counts, and a function that maps a
    table of one entry per present value onto the voxels."""
    top = int(labels.max())
    if top < DENSE_LABELS:
        if labels.dtype == np.uint64:  # bincount takes no uint64
            labels = labels.astype(np.int64)
        counts = label_counts(labels, top + 1)
        values = np.flatnonzero(counts)

        def dense(lut: np.ndarray) -> np.ndarray:
            full = np.zeros(top + 1, dtype=lut.dtype)
            full[values] = lut
            return full[labels]
        return values, counts[values], dense
    values, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    return values, counts, lambda lut: lut[inverse.reshape(labels.shape)]


def _listed(values: np.ndarray, most: int = 12) -> str:
    shown = ", ".join(str(int(v)) for v in values[:most])
    return shown + (f", ... ({values.size} in all)" if values.size > most else "")
