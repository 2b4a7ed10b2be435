"""``itr design`` (the workflow: :func:`itr_identify.workflows.design.run_design`)."""

from __future__ import annotations

import argparse

from .core import CLIError, number, output_folder
from .predict import _engine, plan, prediction_arguments, read_identified

__all__ = ["add_parser"]


def _range(text: str) -> tuple[float, float]:
    """``LO-HI`` or ``X`` in vol% as volume fractions."""
    lo, sep, hi = text.partition("-")
    try:
        a = float(lo)
        b = float(hi) if sep else a
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LO-HI in vol% (e.g. 50-65), got "
                                         f"{text!r}") from None
    return a / 100, b / 100


def _costs(items: list[str], fillers: tuple[str, ...]) -> dict[str, float]:
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        if name not in fillers:
            raise CLIError(f"--cost: {name!r} is not one of --fillers "
                           f"({', '.join(fillers)})", 2)
        try:
            v = float(value)
        except ValueError:
            v = -1.0
        if not v > 0 or v == float("inf"):
            raise CLIError(f"--cost: expected FILLER=COST with a positive cost per vol%, got "
                           f"{item!r}", 2)
        out[name] = v
    return out


def _space(args: argparse.Namespace, system):
    from ..inference.design_space import DesignSpace

    fillers = tuple(f.strip() for f in args.fillers.split(",") if f.strip())
    for f in fillers:
        if f not in system.filler_names:
            raise CLIError(f"--fillers: {f!r} is not a filler of the material system "
                           f"{system.name!r} (fillers: {', '.join(system.filler_names)})", 2)
    try:
        space = DesignSpace(fillers, args.total, total_step=args.step / 100)
    except ValueError as exc:
        msg = str(exc)
        for name, flag in (("fillers", "--fillers"), ("total_step", "--step"),
                           ("total", "--total")):
            if msg.startswith(name + ":"):
                msg = flag + msg[len(name):]
                break
        raise CLIError(msg, 2) from None
    return space


def _run(args: argparse.Namespace) -> int:
    from ..workflows.design import run_design
    from ..workflows.predict import check_names

    record, system = read_identified(args)
    space = _space(args, system)
    cost = _costs(args.cost, space.fillers)
    try:
        anchors = check_names([space.name(s, t) for s, t in space.anchors()], system, record)
        work = plan(args, record, system, anchors)
    except ValueError as exc:
        raise CLIError(str(exc).replace("formulations:", "--fillers:", 1)
                       .replace("identified:", "IDENTIFIED:", 1), 2) from None
    with output_folder(args.out, "design", folders=("solves",), workload=work) as out:
        with _engine(args, out) as engine:
            run_design(record, space, out, identified=args.identified, target=args.target,
                       probability=args.probability, cost=cost, replicates=args.replicates,
                       seed=args.seed, check=args.check, system=system,
                       progress=not args.no_progress, engine=engine)
    return 0


def add_parser(sub) -> None:
    """Register ``design`` on the ``itr`` subparsers ``sub``."""
    p = sub.add_parser("design", help="the cheapest formulation reaching a target k",
                       description="Screen blends and total filler fractions on a surrogate "
                       "of an identification's posterior (anchor formulations' forward models, "
                       "every posterior draw interpolated over the space) and report the "
                       "cheapest formulation whose measured mean reaches --target with "
                       "--probability, the formulations near it checked by their own models "
                       "and full solves; design.json, design.md, design.png, manifest.json.")
    prediction_arguments(p)
    p.add_argument("--fillers", required=True, metavar="A[,B]",
                   help="one or two fillers of the system (e.g. Al2O3,AlN)")
    p.add_argument("--total", required=True, type=_range, metavar="LO-HI",
                   help="total filler fraction range, vol% (e.g. 50-65)")
    p.add_argument("--target", required=True, type=number(float, 0, None, unit=" W/(m K)"),
                   help="the conductivity to reach, W/(m K)")
    p.add_argument("--probability", type=number(float, 0, 1), default=0.95,
                   help="probability with which the measured mean must reach the target "
                   "(default 0.95)")
    p.add_argument("--cost", action="append", default=[], metavar="FILLER=COST",
                   help="cost per vol% of a filler (default 1 each: the least total filler); "
                   "repeat per filler")
    p.add_argument("--step", type=number(float, 0, 10, hi_open=False), default=0.5,
                   help="grid step of the total fraction, vol% (default 0.5)")
    p.add_argument("--check", type=number(int, 0, 3, lo_open=False, hi_open=False), default=3,
                   help="candidates near the choice checked by their own models and full "
                   "solves (default 3: the choice and its neighbours; 0: none)")
    p.add_argument("--out", default="itr-design", help="output folder (default itr-design)")
    p.set_defaults(func=_run)
