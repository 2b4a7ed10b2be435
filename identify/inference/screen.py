"""The paper's high-throughput screening of interface resistances (Sec. 3.2, Eq. 4, Fig. 8).

For one filler system the resistances are stepped over a grid from 1e-8 to 1e-5 m^2 K/W "at
a step of one tenth of the magnitude" (1.0, 1.1, ..., 9.9 times each power of ten: 271
values per parameter, 271^2 = 73 441 combinations for two; the paper prints 7344), the
surrogate predicts every screening formulation, and

    delta = sqrt( sum_f (k_f^model - k_f^exp)^2 )                       (Eq. 4)

is formed with the measured means. The parameter sets whose delta lies in the lowest 1 % of
its cumulative frequency give the range of the resistances, the smallest delta the value.
The screening is hierarchical: filler-matrix and same-filler contact resistances from the
single-filler systems (Al2O3: 55, 60, 65 vol%; AlN: 58, 60, 62 vol%), then the Al2O3-AlN
contact resistance from the hybrids 31/31 and 32.5/32.5 with the earlier values fixed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..forward.model import ForwardModel
from .measurements import Measurements

__all__ = ["paper_grid", "ScreenResult", "screen", "hierarchical_screen",
           "PAPER_SCREENING_FORMULATIONS"]

#: The formulations the paper screens each system on (Sec. 3.2).
PAPER_SCREENING_FORMULATIONS = {
    ("Al2O3",): ("Al2O3-55", "Al2O3-60", "Al2O3-65"),
    ("AlN",): ("AlN-58", "AlN-60", "AlN-62"),
    ("Al2O3", "AlN"): ("Al2O3-31-AlN-31", "Al2O3-32.5-AlN-32.5"),
}


def paper_grid(lo: float = 1e-8, hi: float = 1e-5) -> np.ndarray:
    """Resistances from ``lo`` to ``hi`` (powers of ten) at a tenth of each decade's
    magnitude: m x 10^e for m = 1.0, 1.1, ..., 9.9, and ``hi`` itself; m^2 K/W."""
    e0, e1 = int(round(np.log10(lo))), int(round(np.log10(hi)))
    if not (np.isclose(10.0 ** e0, lo) and np.isclose(10.0 ** e1, hi) and e1 > e0):
        raise ValueError(f"lo/hi: expected two powers of ten, lo < hi, got {lo!r}, {hi!r}")
    mantissa = np.arange(10, 100) / 10.0
    values = [m * 10.0 ** e for e in range(e0, e1) for m in mantissa]
    return np.array(values + [hi])


@dataclass
class ScreenResult:
    """One screening stage.

    Attributes
    ----------
    system : tuple of str
    formulations : tuple of str
    names : list of str
        Screened parameters (flat names).
    fixed : dict
        Parameters held at earlier stages' values, m^2 K/W.
    delta : ndarray
        Eq. 4 for every grid combination, W/(m K) (row-major over ``names``).
    grid : ndarray
        The values of each screened parameter, m^2 K/W.
    quantile : float
        The selected fraction (the paper: 1 %).
    """

    system: tuple[str, ...]
    formulations: tuple[str, ...]
    names: list[str]
    fixed: dict[str, float]
    delta: np.ndarray
    grid: np.ndarray
    quantile: float = 0.01

    def _combos(self) -> np.ndarray:
        idx = np.unravel_index(np.arange(self.delta.size), (self.grid.size,) * len(self.names))
        return np.stack([self.grid[i] for i in idx], axis=1)

    @property
    def selected(self) -> np.ndarray:
        """Parameter sets (n, P) with delta in the lowest ``quantile`` of its frequency."""
        cut = np.quantile(self.delta, self.quantile)
        return self._combos()[self.delta <= cut]

    @property
    def best(self) -> dict[str, float]:
        """The parameter set of smallest delta."""
        row = self._combos()[int(np.argmin(self.delta))]
        return {n: float(v) for n, v in zip(self.names, row)}

    def at_grid_edge(self) -> dict[str, str | None]:
        """Per parameter: ``"lower"`` or ``"upper"`` where the best value is the grid's first
        or last value (the minimum of Eq. 4 may lie beyond the grid), else None."""
        lo, hi = float(self.grid.min()), float(self.grid.max())
        return {n: "lower" if v <= lo else "upper" if v >= hi else None
                for n, v in self.best.items()}

    def ranges(self) -> dict[str, tuple[float, float]]:
        """Per parameter, the range over the selected sets, m^2 K/W."""
        sel = self.selected
        return {n: (float(sel[:, j].min()), float(sel[:, j].max()))
                for j, n in enumerate(self.names)}

    def cumulative_frequency(self) -> tuple[np.ndarray, np.ndarray]:
        """(sorted delta, cumulative frequency in [0, 1]): the curve of Fig. 8."""
        d = np.sort(self.delta)
        return d, np.arange(1, d.size + 1) / d.size

    def to_dict(self) -> dict:
        return {"system": list(self.system), "formulations": list(self.formulations),
                "fixed": self.fixed, "best": self.best, "best_at_grid_edge": self.at_grid_edge(),
                "range_lowest_1pct": {n: list(r) for n, r in self.ranges().items()},
                "delta_min_W_per_mK": float(self.delta.min()),
                "delta_cut_W_per_mK": float(np.quantile(self.delta, self.quantile)),
                "combinations": int(self.delta.size)}


def screen(models: Mapping[str, ForwardModel], measurements: Measurements,
           formulations: Sequence[str], names: Sequence[str], *,
           fixed: Mapping[str, float] | None = None, grid: np.ndarray | None = None,
           quantile: float = 0.01) -> ScreenResult:
    """Eq. 4 over the grid of ``names`` (at most two) for one system's ``formulations``."""
    if not 1 <= len(names) <= 2:
        raise ValueError(f"names: screen one or two parameters at a time, got {list(names)}")
    if not 0 < quantile < 1:
        raise ValueError(f"quantile: expected a fraction in (0, 1), got {quantile!r}")
    fixed = dict(fixed or {})
    grid = paper_grid() if grid is None else np.asarray(grid, dtype=np.float64)
    mesh = np.meshgrid(*[grid] * len(names), indexing="ij")
    columns = {n: m.ravel() for n, m in zip(names, mesh)}
    columns.update({n: np.full(mesh[0].size, v) for n, v in fixed.items()})
    sq = np.zeros(mesh[0].size)
    for f in formulations:
        k, _ = models[f].predict(columns)
        sq += (k - measurements.mean(f)) ** 2
    system = tuple(sorted(models[formulations[0]].fractions))
    return ScreenResult(system, tuple(formulations), list(names), fixed, np.sqrt(sq), grid,
                        quantile)


def hierarchical_screen(models: Mapping[str, ForwardModel], measurements: Measurements, *,
                        formulations: Mapping[tuple[str, ...], Sequence[str]] | None = None
                        ) -> list[ScreenResult]:
    """The paper's two-level screening over the systems that ``models`` hold.

    ``formulations`` maps a system (sorted filler names) to its screening formulations
    (default :data:`PAPER_SCREENING_FORMULATIONS`, restricted to the modelled and measured
    ones; a system without any of them is screened on all of its formulations).
    """
    chosen = dict(PAPER_SCREENING_FORMULATIONS if formulations is None else formulations)
    systems: dict[tuple[str, ...], list[str]] = {}
    for name, m in models.items():
        if name in measurements.values:
            systems.setdefault(tuple(sorted(m.fractions)), []).append(name)
    out, known = [], {}
    for system in sorted(systems, key=lambda s: (len(s), s)):
        forms = [f for f in chosen.get(system, ()) if f in systems[system]] or systems[system]
        params = models[forms[0]].parameters
        new = [p for p in params if p not in known]
        if not new:
            continue
        # a later stage's forward model holds the earlier parameters at its own values
        fixed = {**{p: known[p] for p in params if p in known}, **models[forms[0]].fixed}
        res = screen(models, measurements, forms, new, fixed=fixed)
        known.update(res.best)
        out.append(res)
    return out
