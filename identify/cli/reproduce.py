"""``itr reproduce`` (the workflow: :func:`itr_identify.workflows.reproduce.run_reproduce`)."""

from __future__ import annotations

import argparse

from .core import (
    engine_options,
    identification_arguments,
    identification_plan,
    output_folder,
    reproduce_settings,
)

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    from ..inference.measurements import read_measurements
    from ..workflows.reproduce import run_reproduce

    settings = reproduce_settings(args)
    plan = identification_plan(args, settings, read_measurements().formulations,
                               validation=True)
    with output_folder(args.out, "reproduce", folders=("solves",), workload=plan) as out:
        run_reproduce(settings, out, progress=not args.no_progress, **engine_options(args))
    return 0


def add_parser(sub) -> None:
    """Register ``reproduce`` on the ``itr`` subparsers ``sub``."""
    rep = sub.add_parser("reproduce", help="the paper's whole pipeline on the shipped data",
                         description="Identify the interface resistances from the shipped "
                         "Table 3 under both parametrisations, validate with full solves and "
                         "leave-one-formulation-out; report.md, identified.json, figures, "
                         ".vti, full_solves.parquet, manifest.json. About 4 min on 2 cores at "
                         "the default --fidelity shipped (6 min from a fresh install).")
    rep.add_argument("--out", default="itr-reproduce", help="output folder "
                     "(default itr-reproduce)")
    rep.add_argument("--no-leave-one-out", action="store_true",
                     help="skip the leave-one-formulation-out study")
    identification_arguments(rep)
    rep.set_defaults(func=_run)
