"""The work of an identification before it starts: RVEs, solves and grids
(:class:`itr_surrogate.workload.Workload`), for ``itr identify``, ``reproduce`` and
``discrepancy`` to print and check before anything is packed.

Per formulation and parametrisation a forward model packs its cheap replicas, fits a reduced
basis of full solves that keep their fields (:data:`TYPICAL_BASIS_SOLVES`, at most
``rb_max_solves``), solves every replica at the centre (its scatter) and, in ``itr
reproduce``, again at the identified values (the validation). Where its fidelity level
corrects it at runtime (no shipped correction holds), it packs the faithful RVE's packings
and solves them at both voxels, once per correction round (counted at two rounds; at most
``max_rounds``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import replace

from itr_surrogate.workload import Grid, Workload, expected_particles

from .model import PARAMETRISATIONS, ForwardSettings, filler_specs, shipped_factor

__all__ = ["identification_workload", "side_by_side_possible", "tables_workload",
           "TYPICAL_BASIS_SOLVES",
           "TYPICAL_ROUNDS"]

#: Full solves of a reduced basis at the default settings (measured 5 under the gap and 8
#: under the area parametrisation, itr reproduce 2026-11-27), at most ``rb_max_solves``.
TYPICAL_BASIS_SOLVES = 8
#: Correction rounds of a runtime faithful correction (1-2 at the defaults).
TYPICAL_ROUNDS = 2


def _cheap_grid(settings: ForwardSettings, compositions: Mapping[str, Mapping[str, float]],
                models: int, solves_per_model: int, *, basis_solves: int) -> Grid:
    rve = settings.rve
    particles = max(expected_particles(rve, filler_specs(settings, c))
                    for c in compositions.values())
    return Grid("cheap RVEs", rve.box_um, rve.voxel_um, rves=models * settings.replicas,
                solves=models * (solves_per_model + basis_solves), particles=particles,
                fields=basis_solves > 0, kept_fields=models * basis_solves)


def _faithful_grids(settings: ForwardSettings, compositions: Mapping[str, Mapping[str, float]],
                    *, solves_per_voxel: int) -> list[Grid]:
    """The faithful RVEs of the formulations corrected at runtime (none where the level has
    no faithful RVE or a shipped correction holds for every one)."""
    fa = settings.faithful
    if fa is None:
        return []
    grids: dict[tuple[float, float], list[int]] = {}
    for comp in compositions.values():
        if fa.shipped and shipped_factor(settings, PARAMETRISATIONS["gap"], comp)[0]:
            continue
        spec = fa.spec_for(list(comp), settings.rve)
        n = expected_particles(spec, filler_specs(settings, comp))
        for voxel in (fa.voxel_um, fa.coarse_voxel_um):
            entry = grids.setdefault((spec.box_um, voxel), [0, 0])
            entry[0] += 1
            entry[1] = max(entry[1], n)
    return [Grid("faithful RVEs", box, voxel, rves=fa.packings * count,
                 solves=count * solves_per_voxel, particles=particles)
            for (box, voxel), (count, particles) in sorted(grids.items())]


def side_by_side_possible(parametrisations: int, *, distributed: bool) -> bool:
    """Whether ``parametrisations`` identifications run side by side, one process each
    (:mod:`itr_identify.workflows.side_processes`): more than one, more than one core, and
    solves in this machine's processes (a distributed engine already spreads the solves;
    its client stays in this process)."""
    return parametrisations > 1 and not distributed and (os.cpu_count() or 1) > 1


def identification_workload(settings: ForwardSettings,
                            compositions: Mapping[str, Mapping[str, float]],
                            parametrisations: Sequence[str], *, validation: bool,
                            workers: int | None = None,
                            scheduler: str | None = None) -> Workload:
    """The work of identifying ``compositions`` (formulation -> {filler: volume fraction})
    under ``parametrisations`` with ``settings``; ``validation``: the validation solves of
    ``itr reproduce`` and its temperature field too."""
    models = len(compositions) * len(parametrisations)
    per_model = settings.replicas * (2 if validation else 1) + int(validation)
    basis = min(TYPICAL_BASIS_SOLVES, settings.rb_max_solves)
    grids = [_cheap_grid(settings, compositions, models, per_model, basis_solves=basis)]
    if "gap" in parametrisations:
        fa = settings.faithful
        rounds = 0 if fa is None else fa.packings * min(TYPICAL_ROUNDS, fa.max_rounds)
        grids += _faithful_grids(settings, compositions, solves_per_voxel=rounds)
    side = side_by_side_possible(len(parametrisations),
                                 distributed=bool(workers or scheduler))
    return Workload(tuple(grids), settings.solver, workers, scheduler,
                    processes=len(parametrisations) if side else 1)


def tables_workload(settings, compositions: Mapping[str, Mapping[str, float]], *,
                    solves: int, workers: int | None = None,
                    scheduler: str | None = None) -> Workload:
    """The work of the discrepancy workflow's forward tables: ``solves`` full solves
    (:func:`itr_identify.discrepancy.tables.n_solves`) on the cheap RVEs of ``settings``
    (a DiscrepancySettings) and its faithful corrections."""
    fw = settings.forward.with_(faithful=settings.faithful)
    fa = settings.faithful
    per_voxel = 0 if fa is None else fa.packings
    faithful = _faithful_grids(fw, compositions, solves_per_voxel=per_voxel)
    cheap = solves - sum(g.solves for g in faithful)
    grid = replace(_cheap_grid(fw, compositions, len(compositions), 0, basis_solves=0),
                   solves=cheap)
    return Workload((grid, *faithful), fw.solver, workers, scheduler)
