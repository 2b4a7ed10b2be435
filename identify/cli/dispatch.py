"""The ``itr`` command: its parser (every command registers itself) and ``main``, the one
place that turns an exception into a line on standard error and an exit status (see
:mod:`itr_identify.cli`)."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import traceback
import warnings

from . import (
    campaign,
    corrections,
    demo,
    design,
    discrepancy,
    identify,
    materials,
    predict,
    reproduce,
    solve,
    surrogate,
)
from .core import CLIError, Parser, flagged

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    """The ``itr`` argument parser."""
    from itr_fv import __version__

    parser = Parser(prog="itr", description="Interfacial thermal resistance in "
                    "particle-laden composites.")
    parser.add_argument("--version", action="version",
                        version=f"itr {__version__} (Python {sys.version.split()[0]})")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for command in (demo, campaign, corrections, surrogate, reproduce, identify, discrepancy,
                    predict, design, materials, solve):
        command.add_parser(sub)
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
    from itr_fv.solvers.resources import InsufficientMemoryError

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
        return flagged(str(exc)), 2
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
