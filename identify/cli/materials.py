"""``itr materials``: the handbook of common phases (:mod:`itr_fv.materials.handbook`), and
``itr materials check FILE``: a material-system file read and checked, nothing solved."""

from __future__ import annotations

import argparse

from .core import CLIError, Parser

__all__ = ["add_parser"]


def _list(args: argparse.Namespace) -> int:
    from itr_fv.materials.handbook import handbook

    book = handbook()
    rows = [p for p in book.values() if args.role in (None, p.role)]
    print(f"{'phase':<14}{'role':<8}{'k W/(m K)':>10}{'range':>16}{'prior sd':>10}"
          f"{'g/cm^3':>8}  source of k")
    for p in rows:
        print(f"{p.name:<14}{p.role:<8}{p.conductivity:>10g}{f'{p.low:g} - {p.high:g}':>16}"
              f"{p.relative_sd:>10.2f}{p.density:>8g}  {p.conductivity_source}")
    print("A system file may name any of these without a conductivity or density: the "
          "value is taken from here and the range is the prior's 90 % interval "
          "(itr_fv/data/handbook.csv holds the sources of the densities and notes).")
    return 0


def _check(args: argparse.Namespace) -> int:
    from itr_fv.materials.system_file import read_system

    try:
        system = read_system(args.file)
    except ValueError as exc:
        raise CLIError(str(exc), 2) from None
    sds = system.conductivity_sds()
    print(f"system {system.name!r} ({args.file}):")
    print(f"  matrix {system.matrix}: {system.matrix_conductivity:g} W/(m K), relative sd "
          f"{sds[system.matrix]:.3g}, density {system.matrix_density or 'not stated'}")
    for f in system.fillers:
        n = f.psd.to_number()
        print(f"  filler {f.name}: {f.conductivity:g} W/(m K), relative sd {sds[f.name]:.3g}, "
              f"density {f.density or 'not stated'}; sizes {f.size_note}: number median "
              f"{n.median_um:.3g} um, sigma {n.sigma:.3f}")
    for name, value in system.resistances:
        print(f"  known {name} = {value:g} m^2 K/W (held)")
    return 0


def add_parser(sub) -> None:
    """Register ``materials`` on the ``itr`` subparsers ``sub``."""
    mat = sub.add_parser("materials", help="the handbook of common phases; check a system file",
                         description="List the handbook of common fillers and matrices "
                         "(conductivity, published range, density, source), or check a "
                         "material-system file.")
    mat.add_argument("--role", choices=["filler", "matrix"], default=None,
                     help="list only fillers or only matrices")
    mat.set_defaults(func=_list)
    actions = mat.add_subparsers(dest="action", parser_class=Parser)
    check = actions.add_parser("check", help="read and check a material-system file")
    check.add_argument("file", help="material-system file (TOML)")
    check.set_defaults(func=_check)
