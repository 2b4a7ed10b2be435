"""``itr campaign run|status|export``: the command line of :mod:`itr_surrogate.runner`.

Every check of the campaign file happens before any work starts; errors are one line
(:mod:`itr_identify.cli` prints them), status 2 for a bad file, flag or folder, 1 for a failure
while running.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from .core import (
    CLIError,
    Parser,
    number,
    open_campaign,
    planned,
    solver_arguments,
    solver_option,
    system_arguments,
    system_option,
)

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    from itr_surrogate.campaign import Campaign, CampaignError
    from itr_surrogate.runner import local_workers, run_campaign
    from itr_surrogate.store import CampaignStore
    from itr_surrogate.workload import campaign_workload

    try:
        camp = Campaign.from_toml(args.file, system_option(args))
    except CampaignError as exc:
        raise CLIError(str(exc), 2) from None
    solver = solver_option(args, camp.solver)
    if solver != camp.solver:
        camp = replace(camp, solver=solver)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out: {args.out!r} is a file, not a folder", 2)
    try:
        CampaignStore(out).check_for(camp)        # the folder first: nothing written
    except CampaignError as exc:
        raise CLIError(str(exc), 2) from None
    planned(campaign_workload(camp, workers=local_workers(args.workers),
                              scheduler=args.scheduler))
    try:
        summary = run_campaign(camp, out, workers=args.workers, scheduler=args.scheduler,
                               progress=not args.no_progress)
    except CampaignError as exc:
        raise CLIError(str(exc), 2) from None
    return 1 if summary.tasks_failed else 0


def _status(args: argparse.Namespace) -> int:
    print(open_campaign(args.dir).status().summary())
    return 0


def _export(args: argparse.Namespace) -> int:
    from itr_fv.io import output_file
    from itr_surrogate.campaign import CampaignError

    store = open_campaign(args.dir)
    try:
        path = output_file(args.csv, ".csv", "--csv")
        rows = store.export_csv(path)
    except (ValueError, CampaignError) as exc:
        raise CLIError(str(exc), 2) from None
    print(f"wrote {path} ({rows} rows)")
    return 0


def add_parser(sub) -> None:
    """Register ``campaign run|status|export`` on the ``itr`` subparsers ``sub``."""
    camp = sub.add_parser("campaign", help="high-throughput campaigns (Dask, Parquet)",
                          description="Run a campaign file on Dask and store the results as "
                          "Parquet; show its status; export it as CSV.")
    actions = camp.add_subparsers(dest="action", required=True, parser_class=Parser)
    run = actions.add_parser("run", help="run (or resume) a campaign file")
    run.add_argument("file", help="campaign file (TOML)")
    run.add_argument("--out", required=True, help="campaign folder (new, or this campaign's)")
    run.add_argument("--workers", type=number(int, 0, 64, lo_open=False, hi_open=False),
                     default=None,
                     help="workers of the local Dask cluster (default: cores, at most 4; "
                          "0: every task in this process, without Dask)")
    run.add_argument("--scheduler", default=None,
                     help="address of a running Dask scheduler, e.g. tcp://host:8786")
    solver_arguments(run)
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    system_arguments(run)
    run.set_defaults(func=_run)
    status = actions.add_parser("status", help="done / total and failures of a campaign")
    status.add_argument("dir", help="campaign folder")
    status.set_defaults(func=_status)
    export = actions.add_parser("export", help="all finished rows as CSV")
    export.add_argument("dir", help="campaign folder")
    export.add_argument("--csv", required=True, help="CSV file to write")
    export.set_defaults(func=_export)
