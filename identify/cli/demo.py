"""``itr demo`` (the job: :func:`itr_identify.workflows.demo.run_demo`)."""

from __future__ import annotations

import argparse

from itr_fv.solvers.choice import default_solver

from .core import (
    CLIError,
    number,
    output_folder,
    solver_arguments,
    solver_option,
    system_arguments,
    system_option,
)

__all__ = ["add_parser"]


def _run(args: argparse.Namespace) -> int:
    from itr_fv.rve.spec import RVESpec

    from ..workflows.demo import DemoSettings, demo_workload, run_demo

    voxel = args.box_um / args.n if args.n is not None else args.voxel_um
    system = system_option(args)
    settings = DemoSettings(rve=RVESpec(box_um=args.box_um, voxel_um=voxel, seed=args.seed),
                            fraction=args.fraction, solver=solver_option(args), tol=args.tol,
                            **({"system": system} if system is not None else {}))
    with output_folder(args.out, "demo", workload=demo_workload(settings)) as out:
        try:
            run_demo(settings, out)
        except RuntimeError as exc:
            if "packing" in str(exc):
                why = str(exc).split(" -- ")[0]  # drop advice on options the CLI does not have
                raise CLIError(f"--fraction {args.fraction:g}: the packer could not place the "
                               f"particles ({why}); use a lower --fraction") from None
            raise
    return 0


def add_parser(sub) -> None:
    """Register ``demo`` on the ``itr`` subparsers ``sub``."""
    demo = sub.add_parser("demo", help="random Al2O3/silicone RVE: k_eff, .vti and figure",
                          description="One random Al2O3/silicone RVE at the paper's "
                          "resistances: k_eff, demo.vti, demo.png, demo.json, manifest.json.")
    demo.add_argument("--box-um", type=number(float, 0, None, unit=" um"), default=16.0,
                      help="box edge, um (default 16)")
    demo.add_argument("--voxel-um", type=number(float, 0, None, unit=" um"), default=0.16,
                      help="voxel edge, um (default 0.16: within 2 %% of the converged k_eff)")
    demo.add_argument("--n", type=number(int, 0, 512, hi_open=False), default=None,
                      help="voxels per edge instead of --voxel-um (voxel = box / n)")
    demo.add_argument("--fraction", type=number(float, 0, 0.68, unit=" (volume fraction)"),
                      default=0.55, help="volume fraction of the system's first filler "
                      "(default 0.55; the paper's system: Al2O3)")
    demo.add_argument("--seed", type=number(int, 0, None, lo_open=False), default=1,
                      help="random seed, >= 0 (default 1)")
    solver_arguments(demo, default=default_solver())
    demo.add_argument("--tol", type=number(float, 1e-12, 1, lo_open=False), default=1e-8,
                      help="relative residual, in [1e-12, 1) (default 1e-8)")
    demo.add_argument("--out", default="itr-demo", help="output folder (default itr-demo)")
    system_arguments(demo)
    demo.set_defaults(func=_run)
