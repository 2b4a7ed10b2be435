"""Forward tables of the discrepancy workflow: per single-filler formulation, full solves of
one RVE on a grid of the filler-matrix resistance for the base model and for every candidate
effect, the replica factor and RVE scatter from the other replicas, and the faithful
correction of their level (:mod:`itr_identify.forward.fidelity`: larger packings at two
voxels, the voxel bias removed by Richardson extrapolation) at the scatter's resistance."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from itr_fv.materials.parameters import parameter_name
from itr_surrogate.engine import SolveEngine
from itr_surrogate.requests import RVEData, SolveRequest

from ..forward.fidelity import Correction
from ..forward.model import PARAMETRISATIONS, ForwardModel, shipped_factor
from ..forward.shipped import ShippedFactor
from .effects import Effect, default_effects
from .settings import DiscrepancySettings

__all__ = ["ForwardTables", "build_tables", "n_solves", "resistance_name",
           "shipped_corrections"]


@dataclass(frozen=True)
class ForwardTables:
    """Full-solver k_iso (W/(m K)) per formulation: ``base[f]`` on the resistance grid and
    ``effect[name][f]`` on resistance x effect-parameter grids (the first replica), the
    replica factor and RVE scatter per formulation, and the faithful correction per
    formulation (empty without :attr:`DiscrepancySettings.faithful`); frozen (tables with
    other corrections are a new one, :func:`dataclasses.replace`)."""

    settings: DiscrepancySettings
    effects: list[Effect]
    base: dict[str, np.ndarray]
    effect: dict[str, dict[str, np.ndarray]]
    replica_factor: dict[str, float]
    rve_scatter: dict[str, float]
    solves: int = 0
    seconds: float = 0.0
    corrections: dict[str, Correction] = field(default_factory=dict)
    effect_corrections: dict[tuple[str, str], Correction] = field(default_factory=dict)
    shipped: dict[str, ShippedFactor] = field(default_factory=dict)

    def level(self, formulation: str, effect: str | None = None,
              r_m2K_per_W: np.ndarray | float | None = None) -> np.ndarray | float:
        """Factor from the first replica's table to the model's k: the replica factor
        times the faithful correction's factor (1 without one); for a candidate
        ``effect`` corrected at its best point (:mod:`.best_point`), that correction's.
        A formulation with a shipped correction (the headline's level,
        :mod:`itr_identify.forward.shipped`) takes its factor at each filler-matrix
        resistance of ``r_m2K_per_W`` (m^2 K/W; default
        :attr:`DiscrepancySettings.r_scatter_m2K_per_W`), an array where that is one."""
        c = self.effect_corrections.get((effect, formulation)) if effect else None
        if c is None and formulation in self.shipped:
            r = np.atleast_1d(np.asarray(self.settings.r_scatter_m2K_per_W
                                         if r_m2K_per_W is None else r_m2K_per_W, float))
            sf = self.shipped[formulation]
            factor = sf.factor({p: r for p in sf.fit["parameters"]}, r.size)[0]
            out = self.replica_factor[formulation] * factor
            return out if np.ndim(r_m2K_per_W) else float(out[0])
        c = c if c is not None else self.corrections.get(formulation)
        return self.replica_factor[formulation] * (c.factor if c is not None else 1.0)

    def relative_sd(self, formulation: str) -> float:
        """Relative standard uncertainty of the model's k of ``formulation``: with a
        faithful correction, the correction's (the level is then the faithful packings'
        mean, and the cheap RVE's scatter cancels from it: ``replica_factor`` times the
        factor is ``k_faithful / k_first_replica``); a shipped one's at
        :attr:`DiscrepancySettings.r_scatter_m2K_per_W`; without one, one cheap RVE's
        scatter."""
        if formulation in self.shipped:
            sf = self.shipped[formulation]
            r = np.array([self.settings.r_scatter_m2K_per_W])
            return float(sf.factor({p: r for p in sf.fit["parameters"]}, 1)[1][0])
        c = self.corrections.get(formulation)
        return c.relative_sd if c is not None else self.rve_scatter[formulation]


def n_solves(n_formulations: int, settings: DiscrepancySettings,
             effects: Sequence[Effect], *, shipped: int = 0) -> int:
    """Full solves :func:`build_tables` makes for ``n_formulations`` single-filler ones,
    ``shipped`` of which take a shipped correction (no faithful solves)."""
    cols = 1 + sum(1 for e in effects for v in e.values if e.solved and v != e.nominal)
    faithful = 0 if settings.faithful is None else 2 * settings.faithful.packings
    return (n_formulations * (len(settings.r_grid_m2K_per_W) * cols
                              + settings.forward.replicas)
            + (n_formulations - shipped) * faithful)


def shipped_corrections(fractions: dict[str, dict[str, float]],
                        settings: DiscrepancySettings) -> dict[str, ShippedFactor]:
    """The shipped correction of each single-filler formulation of ``fractions`` where the
    settings ask for them (``faithful`` the ``shipped`` level) and they hold."""
    out = {}
    for f, comp in fractions.items():
        if len(comp) == 1:
            sf, _ = shipped_factor(replace(settings.forward, faithful=settings.faithful),
                                   PARAMETRISATIONS["gap"], comp)
            if sf is not None:
                out[f] = sf
    return out


def resistance_name(filler: str, matrix: str) -> str:
    """The flat name of the filler-matrix resistance of ``filler`` in ``matrix``."""
    return parameter_name("R", filler, matrix)


def build_tables(fractions: dict[str, dict[str, float]], *,
                 settings: DiscrepancySettings | None = None,
                 effects: Sequence[Effect] | None = None,
                 tick: Callable[[], None] | None = None,
                 engine: SolveEngine | None = None) -> ForwardTables:
    """Solve the forward tables of the single-filler formulations in ``fractions``.

    Parameters
    ----------
    fractions : dict of formulation to {filler: volume fraction}
    settings : DiscrepancySettings, optional
    effects : sequence of Effect, optional
        Default: :func:`itr_identify.discrepancy.effects.default_effects`.
    tick : callable, optional
        Called after every full solve (progress bars).
    engine : SolveEngine, optional
        Where the full solves run and are kept (default: this process, no store); one
        formulation's table is one batch (parallel on a cluster, each RVE's geometry built
        once per worker).
    """
    settings = settings or DiscrepancySettings()
    effects = list(default_effects(settings.system) if effects is None else effects)
    engine = engine or SolveEngine()
    t0 = time.perf_counter()
    base, table, factor, scatter = {}, {e.name: {} for e in effects}, {}, {}
    corrections: dict[str, Correction] = {}
    shipped = shipped_corrections(fractions, settings)
    n = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for f, comp in fractions.items():
            if len(comp) != 1:
                continue
            one = _formulation_tables(f, comp, settings, effects, engine=engine, tick=tick,
                                      shipped=f in shipped)
            n += one.solves
            factor[f], scatter[f] = one.replica_factor, one.rve_scatter
            if one.correction is not None:
                corrections[f] = one.correction
            base[f] = one.base
            for e in effects:
                table[e.name][f] = one.effect[e.name]
    return ForwardTables(settings, effects, base, table, factor, scatter, n,
                         time.perf_counter() - t0, corrections, shipped=shipped)


@dataclass(frozen=True, eq=False)
class _FormulationTables:
    """One formulation's part of :class:`ForwardTables`: k_iso (W/(m K)) of the base model
    over the resistance grid and of each effect over the grid x its values, the replica
    factor, the RVE scatter, the faithful correction (None without one) and the full
    solves made."""

    base: np.ndarray
    effect: dict[str, np.ndarray]
    replica_factor: float
    rve_scatter: float
    correction: Correction | None
    solves: int


def _formulation_tables(f: str, comp: dict[str, float], settings: DiscrepancySettings,
                        effects: Sequence[Effect], *, engine: SolveEngine,
                        tick: Callable[[], None] | None, shipped: bool) -> _FormulationTables:
    """Pack and solve the replicas of formulation ``f`` at the scatter's resistance, correct
    their level on faithful packings where the settings ask and no shipped correction
    holds (``shipped``), and solve the first replica over the resistance grid for the base
    model and every value of every effect that changes the RVE or its phases."""
    s = settings.forward
    grid = list(settings.r_grid_m2K_per_W)
    (filler, _), = comp.items()
    r_name = resistance_name(filler, s.system.matrix)
    model = ForwardModel(f, comp, PARAMETRISATIONS["gap"], s, engine=engine)
    model.microstructures = [model.pack(r) for r in range(s.replicas)]
    model.replica_k = model.solve_replicas({r_name: settings.r_scatter_m2K_per_W},
                                           tick, purpose="RVE scatter")
    n = len(model.microstructures)
    factor, scatter = model.replica_factor, model.rve_scatter
    correction = None
    if not shipped and settings.faithful is not None:   # shipped: the headline's level
        # the level of the replica mean at the scatter's resistance, corrected to the
        # faithful packings' voxel-bias-free mean (one factor for the whole table of the
        # formulation)
        correction = model.correct_at(
            {r_name: settings.r_scatter_m2K_per_W}, settings.faithful,
            k_model=float(model.replica_k.mean()), tick=tick)
        n += 2 * settings.faithful.packings
    columns = _columns(model, effects, seed=s.seed)
    requests = [SolveRequest.for_materials(
        RVEData.of(ms), materials_at({r_name: R}), s.solver_tol, solver=s.solver,
        purpose="discrepancy table", formulation=f, effect=name,
        effect_value=theta) for name, theta, ms, materials_at in columns for R in grid]
    results = engine.solve(requests, tick=tick)
    n += len(results)
    k = np.array([r.k_diagonal.mean() for r in results]).reshape(len(columns), len(grid))
    solved = {(name, theta): k[i] for i, (name, theta, _, _) in enumerate(columns)}
    base = solved[("base", None)]
    table = {e.name: np.stack([base if (not e.solved or theta == e.nominal)
                               else solved[(e.name, theta)] for theta in e.values],
                              axis=1)                                   # (nR, ntheta)
             for e in effects}
    return _FormulationTables(base, table, factor, scatter, correction, n)


def _columns(model: ForwardModel, effects: Sequence[Effect], *, seed: int) -> list[tuple]:
    """One column per (effect, value) that changes the RVE or its phases, the base model
    first: (effect name, value, RVE, materials at the resistances); every column is k_iso
    over the resistance grid (an effect that packs its own RVE repacks replica 0 with its
    seed)."""
    from .steepening import Repacker

    ms0 = model.microstructures[0]
    pack = Repacker.of(model, 0)
    columns = [("base", None, ms0, model.materials)]
    for e in effects:
        for theta in e.values:
            if e.solved and theta != e.nominal:
                ms = e.rebuild(pack, ms0, theta, seed=seed)
                columns.append((e.name, theta, ms,
                                lambda v, e=e, theta=theta, ms=ms: e.materials_in(
                                    ms, model.materials(v), theta)))
    return columns
