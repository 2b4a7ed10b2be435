"""``itr discrepancy`` (registered by :func:`identify.cli.build_parser`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["add_discrepancy_parser"]


def _run(args: argparse.Namespace) -> int:
    from .cli import CLIError, output_folder
    from .discrepancy import DiscrepancySettings
    from .discrepancy_report import run_discrepancy
    from .identify_cli import forward_settings, read_table
    from .measurements import read_measurements

    meas = read_table(args.measurements, read_measurements)

    settings = DiscrepancySettings(
        forward=forward_settings(DiscrepancySettings().forward, args))
    from .effects import by_key, default_effects

    try:
        effects = by_key(args.effects.split(",")) if args.effects else default_effects()
    except ValueError as exc:
        raise CLIError("--" + str(exc), 2) from None
    with output_folder(args.out) as out:
        run_discrepancy(meas, settings, out, effects=effects, progress=not args.no_progress)
    return 0


def add_discrepancy_parser(sub, parser_class, number: Callable) -> None:
    p = sub.add_parser("discrepancy", help="where model and measurements disagree, and which "
                       "missing effect explains it",
                       description="Calibrate the base model and each candidate effect "
                       "(matrix and filler conductivity, porosity, filler fraction, solid "
                       "contact spots, tester contact resistance) on a measurement table, "
                       "test the residuals and name the effect the data support; writes "
                       "discrepancy.md, .json, .png and manifest.json.")
    p.add_argument("measurements", metavar="MEASUREMENTS", nargs="?", default=None,
                   help="CSV: formulation,replicate,k_W_per_mK[,thickness_mm] (default: the "
                   "paper's Table 3, shipped)")
    p.add_argument("--out", default="itr-discrepancy",
                   help="output folder (default itr-discrepancy)")
    from .identify_cli import rve_arguments

    rve_arguments(p, number, box="12", voxel="0.5")
    p.add_argument("--effects", default=None,
                   help="comma-separated candidates (default all): matrix, filler, porosity, "
                   "fraction, spots, tester")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_run)
