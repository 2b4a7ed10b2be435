"""``itr identify`` (the workflow: :func:`itr_identify.workflows.reproduce.run_identify`)."""

from __future__ import annotations

import argparse

from .core import (
    CLIError,
    engine_options,
    identification_arguments,
    identification_plan,
    output_folder,
    read_table,
    refuse_unfit,
    reproduce_settings,
    system_arguments,
)

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    from ..inference.measurements import read_measurements, read_tester_readings
    from ..workflows.reproduce import run_identify

    settings = reproduce_settings(args)
    if (args.measurements is None) == (not args.example):
        raise CLIError("MEASUREMENTS: give a CSV file of your measurements, or --example for "
                       "the paper's Table 3 shipped with the package", 2)
    if args.example and args.readings:
        raise CLIError("--readings: the shipped Table 3 (--example) holds conductivities, not "
                       "tester readings", 2)
    meas = read_table(args.measurements,
                      read_tester_readings if args.readings else read_measurements,
                      settings.forward.system)
    plan = identification_plan(args, settings, meas.formulations, validation=False)
    if args.plan:
        refuse_unfit(plan)
        print(_system_line(settings.forward))
        print(plan.summary())
        print(plan.alternatives())
        return 0
    print(_system_line(settings.forward))
    with output_folder(args.out, "identify", folders=("solves",), workload=plan) as out:
        run_identify(meas, settings, out, progress=not args.no_progress,
                     **engine_options(args))
    return 0


def add_parser(sub) -> None:
    """Register ``identify`` on the ``itr`` subparsers ``sub``."""
    ide = sub.add_parser("identify", help="identify resistances from your measurement table",
                         description="Identify interface resistances from a measurement table "
                         "(formulation,replicate,k_W_per_mK; or tester readings with "
                         "--readings); writes identified.json, report.md, posterior figures, "
                         "manifest.json.")
    ide.add_argument("measurements", metavar="MEASUREMENTS", nargs="?", default=None,
                     help="CSV file: formulation,replicate,k_W_per_mK")
    ide.add_argument("--example", action="store_true",
                     help="identify from the paper's Table 3 shipped with the package "
                     "(itr_fv/data/measured_tc.csv; a CSV of the same columns is the "
                     "template of your own table) instead of MEASUREMENTS")
    ide.add_argument("--readings", action="store_true", help="the file holds tester readings "
                     "(formulation,replicate,thickness_mm,impedance_K_mm2_per_W)")
    ide.add_argument("--out", default="itr-identify", help="output folder "
                     "(default itr-identify)")
    identification_arguments(ide)
    system_arguments(ide)
    ide.add_argument("--corrections", default=None, metavar="FILE",
                     help="a corrections table built for this system (itr corrections build "
                     "PLAN --system FILE; its corrections.json): used where it holds, the "
                     "other formulations corrected at runtime (default: the tables shipped "
                     "with the package, for the paper's system)")
    ide.add_argument("--plan", action="store_true",
                     help="print the plan (RVEs, voxels per solve, solves, memory, time here "
                     "and on a GPU or a cluster) and stop, before any packing or solving")
    ide.set_defaults(func=_run)


def _system_line(forward) -> str:
    """One line: the material system and the RVEs its powders give."""
    s = forward.system
    fa = forward.faithful
    faithful = ("no faithful RVE (quick)" if fa is None else
                f"faithful boxes {', '.join(f'{f} {b:g}' for f, b in fa.boxes_um)} um at "
                f"{fa.voxel_um:g} and {fa.coarse_voxel_um:g} um")
    return (f"system {s.name} ({s.source or 'default'}): {s.describe()}; cheap RVE "
            f"{forward.box_um:g} um at {forward.voxel_um:g} um; {faithful}")
