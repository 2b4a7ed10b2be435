"""``itr reproduce`` and ``itr identify`` (registered by :func:`identify.cli.build_parser`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["add_identify_parsers", "forward_settings", "rve_arguments", "read_table"]


def forward_settings(fw, args: argparse.Namespace):
    """``fw`` (a ForwardSettings) with the command line's --box-um, --voxel-um, --replicas,
    --seed; a bad value is a CLIError naming the flag."""
    changes = {k: v for k, v in (("box_um", args.box_um), ("voxel_um", args.voxel_um),
                                 ("replicas", args.replicas), ("seed", args.seed))
               if v is not None}
    try:
        return fw.with_(**changes)
    except ValueError as exc:
        msg = str(exc)
        for name, flag in (("box_um/voxel_um", "--box-um/--voxel-um"), ("box_um", "--box-um"),
                           ("voxel_um", "--voxel-um"), ("replicas", "--replicas")):
            if msg.startswith(name + ":"):
                msg = flag + msg[len(name):]
                break
        from .cli import CLIError
        raise CLIError(msg, 2) from None


def read_table(path: str | None, reader: Callable):
    """``reader(path)`` with formulations named by composition; a bad file is a CLIError
    (status 2) naming MEASUREMENTS."""
    from .cli import CLIError
    from .pipeline import fractions_of

    try:
        return reader(path, formulations=fractions_of)
    except ValueError as exc:
        msg = str(exc)
        raise CLIError("MEASUREMENTS: " + (msg[len("path: "):] if msg.startswith("path: ")
                                           else msg), 2) from None


def _settings(args: argparse.Namespace, full: bool = False):
    from .reproduce import ReproduceSettings

    base = ReproduceSettings.full() if full else ReproduceSettings()
    fw = forward_settings(base.forward, args)
    pars = ("area", "gap") if args.parametrisation == "both" else (args.parametrisation,)
    return ReproduceSettings(forward=fw, parametrisations=pars,
                             leave_one_out=not getattr(args, "no_leave_one_out", False))


def _reproduce(args: argparse.Namespace) -> int:
    from .cli import output_folder
    from .reproduce import run_reproduce

    settings = _settings(args, full=args.full)
    with output_folder(args.out) as out:
        run_reproduce(settings, out, progress=not args.no_progress)
    return 0


def _identify(args: argparse.Namespace) -> int:
    from .cli import output_folder
    from .measurements import read_measurements, read_tester_readings
    from .reproduce import run_identify

    settings = _settings(args)
    meas = read_table(args.measurements,
                      read_tester_readings if args.readings else read_measurements)
    with output_folder(args.out) as out:
        run_identify(meas, settings, out, progress=not args.no_progress)
    return 0


def _common(p: argparse.ArgumentParser, number: Callable) -> None:
    p.add_argument("--parametrisation", choices=["area", "gap", "both"], default="both",
                   help="area (the paper's per-area contact resistance), gap (physical "
                   "contacts) or both (default)")
    rve_arguments(p, number, box="12; --full 40", voxel="0.25; --full 0.1")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def rve_arguments(p: argparse.ArgumentParser, number: Callable, *, box: str,
                  voxel: str) -> None:
    """--box-um, --voxel-um, --replicas, --seed (read by :func:`forward_settings`); ``box``
    and ``voxel`` are the defaults as the help shows them."""
    p.add_argument("--box-um", type=number(float, 0, None, unit=" um"), default=None,
                   help=f"RVE edge, um (default {box})")
    p.add_argument("--voxel-um", type=number(float, 0, None, unit=" um"), default=None,
                   help=f"voxel edge, um (default {voxel})")
    p.add_argument("--replicas", type=number(int, 1, 20, hi_open=False), default=None,
                   help="RVE replicas per formulation, 2-20 (default 3)")
    p.add_argument("--seed", type=number(int, 0, None, lo_open=False), default=None,
                   help="packing seed of the first replica (default 1)")


def add_identify_parsers(sub, parser_class, number: Callable) -> None:
    rep = sub.add_parser("reproduce", help="the paper's whole pipeline on the shipped data",
                         description="Identify the interface resistances from the shipped "
                         "Table 3 under both parametrisations, validate with full solves and "
                         "leave-one-formulation-out; report.md, identified.json, figures, "
                         ".vti, full_solves.parquet, manifest.json. About 10 min on 2 cores.")
    rep.add_argument("--out", default="itr-reproduce", help="output folder "
                     "(default itr-reproduce)")
    rep.add_argument("--full", action="store_true", help="the paper's RVE: 40 um box, 0.1 um "
                     "voxels (400^3; not measured here: expect hours)")
    rep.add_argument("--no-leave-one-out", action="store_true",
                     help="skip the leave-one-formulation-out study")
    _common(rep, number)
    rep.set_defaults(func=_reproduce)
    ide = sub.add_parser("identify", help="identify resistances from your measurement table",
                         description="Identify interface resistances from a measurement table "
                         "(formulation,replicate,k_W_per_mK; or tester readings with "
                         "--readings); writes identified.json, report.md, posterior figures, "
                         "manifest.json.")
    ide.add_argument("measurements", metavar="MEASUREMENTS",
                     help="CSV file: formulation,replicate,k_W_per_mK")
    ide.add_argument("--readings", action="store_true", help="the file holds tester readings "
                     "(formulation,replicate,thickness_mm,impedance_K_mm2_per_W)")
    ide.add_argument("--out", default="itr-identify", help="output folder "
                     "(default itr-identify)")
    _common(ide, number)
    ide.set_defaults(func=_identify)
