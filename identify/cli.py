"""The ``itr`` command line.

Every failure is one line on standard error, ``itr: error: ...`` naming the flag where a
flag is at fault, with exit status 2 for bad input (usage, values, output folder) and 1 for a
failure while running (packing, solver, memory, disk). No traceback is shown unless the
environment sets ``ITR_DEBUG=1``. An output folder that the command created is removed
again when the run fails; files are written atomically and ``manifest.json`` last.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import shutil
import signal
import sys
import tempfile
import traceback
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

__all__ = ["main", "build_parser", "CLIError"]

#: Library argument names as the command line spells them, for error messages.
_FLAG_NAMES = {"box_um": "--box-um", "voxel_um": "--voxel-um", "volume_fraction": "--fraction",
               "seed": "--seed", "tol": "--tol", "path": "--out"}


class CLIError(Exception):
    """A failure to report as one line; ``status`` 2 for bad input, 1 for a runtime failure."""

    def __init__(self, message: str, status: int = 1) -> None:
        super().__init__(message)
        self.status = status


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage block), exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise CLIError(message, 2)


def _number(kind: Callable[[str], float], lo: float | None = None, hi: float | None = None,
            lo_open: bool = True, hi_open: bool = True, unit: str = "") -> Callable[[str], float]:
    """argparse type: a finite number in an interval (open or closed at each end)."""
    def parse(text: str) -> float:
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a {'whole ' if kind is int else ''}number: "
                                             f"{text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        bad_lo = lo is not None and (v <= lo if lo_open else v < lo)
        bad_hi = hi is not None and (v >= hi if hi_open else v > hi)
        if bad_lo or bad_hi:
            left = "(" if lo_open else "["
            right = ")" if hi_open else "]"
            span = f"{left}{'-inf' if lo is None else f'{lo:g}'}, " \
                   f"{'inf' if hi is None else f'{hi:g}'}{right}"
            raise argparse.ArgumentTypeError(f"expected a value in {span}{unit}, got {text}")
        return v
    return parse


def _flagged(message: str) -> str:
    """Translate a library message 'voxel_um: ...' into the flag's spelling '--voxel-um: ...'."""
    head, sep, rest = message.partition(":")
    name = head.strip().split("[")[0].split(" ")[0]
    if sep and name in _FLAG_NAMES:
        return f"{_FLAG_NAMES[name]}{head.strip()[len(name):]}:{rest}"
    return message


@contextlib.contextmanager
def output_folder(path: str) -> Iterator[Path]:
    """Check and create the ``--out`` folder; remove it again if the run fails and we made it.

    Raises
    ------
    CLIError
        (status 2) if ``path`` is a file, lies under a file, or cannot be written.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out: {path!r} is a file, not a folder", 2)
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise CLIError(f"--out: {str(parent)!r} is a file, not a folder", 2)
            break
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()
        raise CLIError(f"--out: cannot write to {path!r} ({exc.strerror or exc})", 2) from None
    try:
        yield out
    except BaseException:
        if created:
            shutil.rmtree(out, ignore_errors=True)
        raise


# ------------------------------------------------------------------------------- commands
def _demo(args: argparse.Namespace) -> int:
    from .demo import DemoSettings, run_demo

    voxel = args.box_um / args.n if args.n is not None else args.voxel_um
    n = args.box_um / voxel
    if abs(n - round(n)) > 1e-6 * n:
        raise CLIError(f"--voxel-um: the box ({args.box_um:g} um) is not a whole number of "
                       f"{voxel:g} um voxels ({n:.3f}); choose --box-um or --voxel-um to fit", 2)
    if round(n) > 512:
        raise CLIError(f"--voxel-um: {int(round(n))}^3 voxels is beyond the demo's 512^3 limit", 2)
    settings = DemoSettings(box_um=args.box_um, voxel_um=voxel, fraction=args.fraction,
                            seed=args.seed, solver=args.solver, tol=args.tol)
    with output_folder(args.out) as out:
        try:
            run_demo(settings, out)
        except RuntimeError as exc:
            if "packing" in str(exc):
                why = str(exc).split(" -- ")[0]  # drop advice on options the CLI does not have
                raise CLIError(f"--fraction {args.fraction:g}: the packer could not place the "
                               f"particles ({why}); use a lower --fraction") from None
            raise
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``itr`` argument parser."""
    from itr_fv import __version__

    parser = _Parser(prog="itr", description="Interfacial thermal resistance in "
                     "particle-laden composites.")
    parser.add_argument("--version", action="version",
                        version=f"itr {__version__} (Python {sys.version.split()[0]})")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    demo = sub.add_parser("demo", help="random Al2O3/silicone RVE: k_eff, .vti and figure",
                          description="One random Al2O3/silicone RVE at the paper's "
                          "resistances: k_eff, demo.vti, demo.png, demo.json, manifest.json.")
    demo.add_argument("--box-um", type=_number(float, 0, None, unit=" um"), default=16.0,
                      help="box edge, um (default 16)")
    demo.add_argument("--voxel-um", type=_number(float, 0, None, unit=" um"), default=0.16,
                      help="voxel edge, um (default 0.16: within 2 %% of the converged k_eff)")
    demo.add_argument("--n", type=_number(int, 0, 512, hi_open=False), default=None,
                      help="voxels per edge instead of --voxel-um (voxel = box / n)")
    demo.add_argument("--fraction", type=_number(float, 0, 0.68, unit=" (volume fraction)"),
                      default=0.55, help="Al2O3 volume fraction (default 0.55)")
    demo.add_argument("--seed", type=_number(int, 0, None, lo_open=False), default=1,
                      help="random seed, >= 0 (default 1)")
    demo.add_argument("--solver", choices=["fft", "fv"], default="fft",
                      help="fft (default) or the fv reference")
    demo.add_argument("--tol", type=_number(float, 1e-12, 1, lo_open=False), default=1e-8,
                      help="relative residual, in [1e-12, 1) (default 1e-8)")
    demo.add_argument("--out", default="itr-demo", help="output folder (default itr-demo)")
    demo.set_defaults(func=_demo)
    from .campaign_cli import add_campaign_parser
    add_campaign_parser(sub, _Parser, _number)
    from .surrogate_cli import add_surrogate_parser
    add_surrogate_parser(sub, _Parser, _number)
    from .identify_cli import add_identify_parsers
    add_identify_parsers(sub, _Parser, _number)
    from .discrepancy_cli import add_discrepancy_parser
    add_discrepancy_parser(sub, _Parser, _number)
    return parser


# ----------------------------------------------------------------------------- reporting
def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"itr: warning: {_one_line(message)}", file=sys.stderr)


def _on_sigterm(signum, frame) -> None:
    raise SystemExit(128 + signum)


def _runtime_message(exc: BaseException) -> tuple[str, int]:
    """One line and exit status for an exception raised while running."""
    from itr_fv import ConvergenceError
    from itr_fv.resources import InsufficientMemoryError

    if isinstance(exc, CLIError):
        return str(exc), exc.status
    if isinstance(exc, ConvergenceError):
        res = exc.result
        worst = max(res.residuals) if res is not None and res.residuals else float("nan")
        its = max(res.iterations) if res is not None and res.iterations else 0
        return (f"the solver did not reach --tol {res.tol if res is not None else '?'} "
                f"(relative residual {worst:.1e} after {its} iterations); use a larger --tol "
                "or --solver fv", 1)
    if isinstance(exc, InsufficientMemoryError):
        return (f"{exc}".replace("pass check_memory=False to try anyway",
                                 "use a larger --voxel-um or a smaller --box-um"), 1)
    if isinstance(exc, ValueError):
        return _flagged(str(exc)), 2
    if isinstance(exc, MemoryError):
        return "out of memory; use a larger --voxel-um or a smaller --box-um", 1
    if isinstance(exc, OSError):
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        return f"cannot write the output{where}: {exc.strerror or exc}", 1
    return (f"internal error ({type(exc).__name__}: {exc}); set ITR_DEBUG=1 for the traceback "
            "and report it", 1)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``itr`` console command; returns the exit status."""
    old_handler = None
    with contextlib.suppress(ValueError):  # not in the main thread: keep Python's default
        old_handler = signal.signal(signal.SIGTERM, _on_sigterm)
    old_show = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        args = build_parser().parse_args(argv)
        return int(args.func(args))
    except SystemExit as exc:  # --version, --help, SIGTERM
        code = exc.code if isinstance(exc.code, int) else 0
        if code >= 128:
            print(f"itr: error: stopped by signal {code - 128}; nothing half-written is left "
                  "under a final name", file=sys.stderr)
        return code
    except KeyboardInterrupt:
        print("itr: error: interrupted", file=sys.stderr)
        return 130
    except BaseException as exc:  # noqa: BLE001 - the one place that turns errors into a line
        if os.environ.get("ITR_DEBUG") == "1":
            traceback.print_exc()
        message, status = _runtime_message(exc)
        print(f"itr: error: {_one_line(message)}", file=sys.stderr)
        return status
    finally:
        warnings.showwarning = old_show
        if old_handler is not None:
            signal.signal(signal.SIGTERM, old_handler)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
