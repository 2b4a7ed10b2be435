"""``itr predict`` (the workflow: :func:`itr_identify.workflows.predict.run_predict`)."""

from __future__ import annotations

import argparse

from .core import CLIError, engine_options, number, output_folder

__all__ = ["add_parser", "read_identified", "plan", "prediction_arguments"]


def read_identified(args: argparse.Namespace):
    """The identification's record and material system of IDENTIFIED (and --system); a bad
    file is a CLIError (status 2) naming IDENTIFIED or --system."""
    from ..inference.predictive import read_record
    from ..workflows.predict import system_of
    from .core import system_option

    try:
        record = read_record(args.identified, effect=not args.no_effect)
    except ValueError as exc:
        raise CLIError(str(exc).replace("identified:", "IDENTIFIED:", 1), 2) from None
    try:
        system = system_of(record, system_option(args))
    except ValueError as exc:
        raise CLIError(str(exc).replace("system:", "--system:", 1), 2) from None
    return record, system


def _engine(args: argparse.Namespace, out):
    from ..workflows.reproduce import open_engine

    opts = engine_options(args)
    return open_engine(out, workers=opts["workers"], scheduler=opts["scheduler"],
                       store=opts["store"])


def plan(args: argparse.Namespace, record, system, names):
    """The work of building ``names`` as the identification built its formulations (the
    plan printed, and refused where it cannot fit, before any work)."""
    from ..forward.work_estimate import identification_workload
    from ..inference.formulations import fractions_of
    from ..workflows.predict import forward_settings_of

    fw = forward_settings_of(record, system)
    return identification_workload(fw, {n: fractions_of(n, system) for n in names},
                                   (record.parametrisation,), validation=False,
                                   workers=args.workers, scheduler=args.scheduler)


def _run(args: argparse.Namespace) -> int:
    from ..workflows.predict import check_names, run_predict

    record, system = read_identified(args)
    try:
        names = check_names(args.formulations, system, record)
        work = plan(args, record, system, names)
    except ValueError as exc:
        raise CLIError(str(exc).replace("formulations:", "FORMULATION:", 1)
                       .replace("identified:", "IDENTIFIED:", 1), 2) from None
    with output_folder(args.out, "predict", folders=("solves",), workload=work) as out:
        with _engine(args, out) as engine:
            run_predict(record, names, out, identified=args.identified, system=system,
                        replicates=args.replicates, level=args.level, seed=args.seed,
                        progress=not args.no_progress, engine=engine)
    return 0


def prediction_arguments(p: argparse.ArgumentParser) -> None:
    """The flags ``itr predict`` and ``itr design`` share."""
    from ..inference.predictive import DEFAULT_REPLICATES
    from .core import system_arguments

    p.add_argument("identified", metavar="IDENTIFIED",
                   help="identified.json of itr identify or itr reproduce (its "
                   "posterior_<parametrisation>.parquet beside it)")
    p.add_argument("--replicates", type=number(int, 1, 100, lo_open=False, hi_open=False),
                   default=DEFAULT_REPLICATES,
                   help="samples whose measured mean is predicted (default "
                   f"{DEFAULT_REPLICATES}, as Table 3)")
    p.add_argument("--seed", type=number(int, 0, None, lo_open=False), default=0,
                   help="seed of the prediction's random draws (default 0)")
    system_arguments(p)
    p.add_argument("--workers", type=number(int, 1, 64, hi_open=False), default=None,
                   help="run the full solves on a local Dask cluster of N processes")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the full solves on a running Dask scheduler")
    p.add_argument("--store", default=None, metavar="DIR",
                   help="keep and reuse the full solves in DIR (default OUT/solves; the "
                   "identification's own store may be given: its solves are reused)")
    p.add_argument("--no-effect", action="store_true",
                   help="predict from the identification without the effect the discrepancy "
                   "workflow named (default: with it, where IDENTIFIED holds one)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(keep_fields=False)


def add_parser(sub) -> None:
    """Register ``predict`` on the ``itr`` subparsers ``sub``."""
    p = sub.add_parser("predict", help="predict formulations from an identification",
                       description="Predict the conductivity of formulations from an "
                       "identification's posterior: each formulation's forward model built "
                       "as the identification built the measured ones, evaluated at every "
                       "posterior draw (resistances, inputs, shared correction and model "
                       "form), with the noise of a measured mean; predicted.json, "
                       "predicted.md, manifest.json.")
    prediction_arguments(p)
    p.add_argument("formulations", metavar="FORMULATION", nargs="+",
                   help="formulation names of the system (e.g. Al2O3-60, "
                   "Al2O3-30-AlN-30)")
    p.add_argument("--level", type=number(float, 0, 1), default=0.9,
                   help="predictive interval level (default 0.9)")
    p.add_argument("--out", default="itr-predict", help="output folder (default itr-predict)")
    p.set_defaults(func=_run)
