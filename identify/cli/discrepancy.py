"""``itr discrepancy`` (the workflow:
:func:`itr_identify.workflows.discrepancy.run_discrepancy`)."""

from __future__ import annotations

import argparse

from .core import (
    CLIError,
    engine_arguments,
    engine_options,
    forward_settings,
    output_folder,
    read_table,
    rve_arguments,
    system_arguments,
    system_option,
)

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    from ..discrepancy.effects import by_key, default_effects
    from ..discrepancy.observables import auxiliary_groups
    from ..discrepancy.settings import DiscrepancySettings
    from ..discrepancy.tables import n_solves, shipped_corrections
    from ..forward.fidelity import cheap_rve_for, faithful_for
    from ..forward.work_estimate import tables_workload
    from ..inference.formulations import fractions_of
    from ..inference.measurements import read_measurements
    from ..workflows.discrepancy import run_discrepancy

    stated = system_option(args)
    base = DiscrepancySettings().forward
    if stated is not None:
        base = base.with_(system=stated, rve=cheap_rve_for(stated))
    system = _with_densities(base.system, args.density)
    meas = read_table(args.measurements, read_measurements, system)
    forward = forward_settings(base.with_(system=system), args)
    settings = DiscrepancySettings(forward=forward,
                                   faithful=faithful_for(args.fidelity, system))
    try:
        effects = (by_key(args.effects.split(","), system) if args.effects
                   else default_effects(system))
    except ValueError as exc:
        raise CLIError("--" + str(exc), 2) from None
    comps = {f: fractions_of(f, system) for f in meas.formulations}
    try:
        auxiliary_groups(meas, comps)
    except ValueError as exc:
        raise CLIError("MEASUREMENTS: " + str(exc).removeprefix("measurements: "), 2) from None
    singles = {f: c for f, c in comps.items() if len(c) == 1}
    plan = tables_workload(settings, singles, solves=n_solves(
        len(singles), settings, effects, shipped=len(shipped_corrections(singles, settings))),
                           workers=args.workers, scheduler=args.scheduler)
    with output_folder(args.out, "discrepancy", folders=("solves",), workload=plan) as out:
        run_discrepancy(meas, settings, out, effects=effects, progress=not args.no_progress,
                        **engine_options(args))
    return 0


def _with_densities(system, pairs: list[str] | None):
    """``system`` with the ``--density PHASE=G_PER_CM3`` overrides; a bad one is a one-line
    error naming the option."""
    if not pairs:
        return system
    values = {}
    for pair in pairs:
        phase, sep, text = pair.partition("=")
        try:
            if not sep:
                raise ValueError
            values[phase.strip()] = float(text)
        except ValueError:
            raise CLIError(f"--density: expected PHASE=G_PER_CM3 (e.g. Al2O3=3.98), got "
                           f"{pair!r}", 2) from None
    try:
        return system.with_densities(values)
    except ValueError as exc:
        raise CLIError(f"--density: {exc}", 2) from None


def add_parser(sub) -> None:
    """Register ``discrepancy`` on the ``itr`` subparsers ``sub``."""
    p = sub.add_parser("discrepancy", help="where model and measurements disagree, and which "
                       "missing effect explains it",
                       description="Calibrate the base model and each candidate effect "
                       "(matrix and filler conductivity, porosity, filler fraction, solid "
                       "contact spots, tester contact resistance, batch fraction; film "
                       "thinning, agglomeration, size basis, interphase shell) on a "
                       "measurement table with its optional density, mass fraction and "
                       "size-series columns, test the residuals, name the effect the data "
                       "support or list the tied set with the measurement that would decide "
                       "it; writes discrepancy.md, .json, .png and manifest.json. About 40 "
                       "min on 2 cores on Table 3 (2016 full solves: the 12 um tables and "
                       "the 24 um corrections, kept in OUT/solves or --store; 32 more per "
                       "candidate corrected at its best point); a few minutes again on the "
                       "same store.")
    p.add_argument("measurements", metavar="MEASUREMENTS", nargs="?", default=None,
                   help="CSV: formulation,replicate,k_W_per_mK[,thickness_mm] and optionally "
                   "a lab's second measurements per sample: density_g_per_cm3 (Archimedes), "
                   "filler_mass_fraction (TGA), d50_um (the powder of a size series); blank "
                   "cells where a sample was not measured (default: the paper's Table 3, "
                   "shipped)")
    p.add_argument("--density", action="append", metavar="PHASE=G_PER_CM3", default=None,
                   help="a phase density for the density and mass fraction predictions "
                   "(repeatable; default the handbook's: silicone 0.97, Al2O3 3.95, AlN "
                   "3.26 g/cm^3)")
    p.add_argument("--out", default="itr-discrepancy",
                   help="output folder (default itr-discrepancy)")
    rve_arguments(p, box="12", voxel="0.25, as itr reproduce; 0.5 reads k 9-11 %% low for "
                  "Al2O3 and 3-5 %% for AlN against 0.2 um voxels")
    p.add_argument("--fidelity", choices=["quick", "shipped", "standard", "paper"],
                   default="shipped",
                   help="where each formulation's table level is corrected: shipped (default, "
                   "the headline's level: the shipped converged-box corrections per "
                   "resistance where they hold, else as standard), standard (two 24 um "
                   "packings at 0.2 and 0.25 um, the voxel bias extrapolated away), quick "
                   "(none: the 12 um RVE's level, Al2O3 about 3 %% and AlN 10-12 %% low), "
                   "paper (40 um at 0.1 and 0.125 um; hours)")
    p.add_argument("--effects", default=None,
                   help="comma-separated candidates (default all): matrix, filler, porosity, "
                   "fraction, spots, tester, batch, film, agglomeration, basis, shell")
    engine_arguments(p)
    system_arguments(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_run)
