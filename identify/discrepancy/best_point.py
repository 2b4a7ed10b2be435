"""A candidate's table level corrected at its best point (issue 40, point 2).

The forward tables are solved on the cheap RVE; their level is corrected to the faithful
fidelity once per formulation, without any effect (:mod:`.tables`). An effect can change
that correction: solid contact spots, for one, conduct differently through a contact drawn
at another voxel. :func:`corrector` returns the step that, for the candidates that would be
named (a log Bayes factor over the naming threshold), solves the faithful packings
of every formulation with the effect switched on at the candidate's best value and
resistance (both voxels, the voxel bias extrapolated away, on the solve engine and in its
store), replaces that candidate's level by the corrected one and refits it. The table value
it is compared with is the first replica's at that point times the replica factor.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from itr_fv.rve import build_rve
from itr_surrogate.engine import SolveEngine
from itr_surrogate.requests import RVEData, SolveRequest

from ..forward.fidelity import Correction
from ..forward.model import PARAMETRISATIONS, ForwardModel, filler_specs
from ..inference.formulations import fractions_of
from .candidate import Effect
from .fit import Group, ModelFit, evaluate, fit_model
from .observables import AuxGroup
from .steepening import Repacker
from .tables import ForwardTables, resistance_name

__all__ = ["Corrected", "corrector", "effect_correction"]


def effect_correction(tables: ForwardTables, effect, value: float,
                      resistances: dict[str, float], formulation: str,
                      engine: SolveEngine, tick: Callable[[], None] | None = None
                      ) -> Correction:
    """The faithful correction of ``formulation``'s table level with ``effect`` at
    ``value`` and the given resistances (full solves on the faithful packings)."""
    st = tables.settings
    fa = st.faithful
    comp = fractions_of(formulation, st.system)
    (filler, phi), = comp.items()
    model = ForwardModel(formulation, comp, PARAMETRISATIONS["gap"], st.forward, engine=engine)
    r_name = resistance_name(filler, st.system.matrix)
    base_mat = model.materials({r_name: resistances[r_name]})
    spec = fa.spec_for([filler], st.forward.rve)
    coarse = fa.coarse_shape([filler])
    requests, seeds = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for j in range(fa.packings):
            ms, seed = build_rve(spec, filler_specs(st.forward, comp), j,
                                 matrix=st.system.matrix, warn_box_cut=False)
            seeds.append(seed)
            ms = effect.rebuild(Repacker(spec.with_(seed=seed), comp, st.forward.psd_basis,
                                         st.system), ms, value, seed)
            mat = effect.materials_in(ms, base_mat, value)
            rve = RVEData.of(ms)
            for grid, label in ((rve, "fine"), (replace(rve, shape=coarse), "coarse")):
                requests.append(SolveRequest.for_materials(
                    grid, mat, st.forward.solver_tol, solver=st.forward.solver,
                    purpose=f"best-point {label}", formulation=formulation,
                    effect=effect.name, effect_value=float(value)))
    results = engine.solve(requests, tick=tick)
    k = np.array([r.k_diagonal for r in results])
    g = Group(formulation, filler, phi, None, 1.0, 1.0, 1)
    params = {r_name: resistances[r_name], effect.parameter: float(value)}
    k_table = evaluate(_uncorrected(tables), effect, params, [g])[0][0]
    return Correction({r_name: resistances[r_name]}, fa.box_for([filler]), fa.voxel_um,
                      fa.coarse_voxel_um, seeds, float(k_table), k[0::2], k[1::2])


def _uncorrected(tables):
    """The tables with no correction for any effect (the level the best point is compared
    with: the replica factor times the base model's correction is divided out below)."""
    return replace(tables, corrections={}, effect_corrections={})


def corrector(engine: SolveEngine, *, tick: Callable[[], None] | None = None
              ) -> Callable[..., "Corrected"]:
    """The step :func:`~.decision.find_discrepancy` takes before deciding (its ``correct``):
    every solved candidate whose log Bayes factor exceeds the naming threshold is refitted
    with its level corrected at its best point. It returns a :class:`Corrected`: new
    tables holding the corrections (:attr:`~.tables.ForwardTables.effect_corrections`),
    the refitted candidates and the factors; the tables it was given are not changed."""
    def correct(tables: ForwardTables, groups: Sequence[Group], aux: Sequence[AuxGroup],
                base: ModelFit, fits: Sequence[ModelFit], effects: Sequence[Effect],
                threshold: float) -> Corrected:
        st = tables.settings
        if st.faithful is None:
            return Corrected(tables, list(fits), {})
        found: dict = {}
        chosen = []
        for m in fits:
            e = next(x for x in effects if x.name == m.name)
            value = m.parameters[e.parameter]
            if (not e.solved or m.log_evidence - base.log_evidence <= threshold
                    or m.at_grid_edge or value == e.nominal):
                continue
            chosen.append(e)
            for f in sorted({g.formulation for g in groups}):
                found[(e.name, f)] = effect_correction(tables, e, value, m.parameters, f,
                                                       engine, tick)
        corrected = replace(tables, effect_corrections={**tables.effect_corrections, **found})
        refit = {e.name: fit_model(corrected, groups, e, aux) for e in chosen}
        factors = {e.name: {f: c.factor for (name, f), c in found.items() if name == e.name}
                   for e in chosen}
        return Corrected(corrected, [refit.get(m.name, m) for m in fits], factors)
    return correct


@dataclass(frozen=True)
class Corrected:
    """What :func:`corrector` returns: the tables with the best-point corrections, the
    candidates (those corrected refitted) and, per corrected candidate, each formulation's
    correction factor."""

    tables: ForwardTables
    fits: list[ModelFit]
    factors: dict[str, dict[str, float]]
