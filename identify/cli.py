"""The ``itr`` command line."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

__all__ = ["main"]

# The paper's identified resistances (Table 5), m^2 K/W, and its conductivities, W/(m K).
PAPER_K = {"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0}
PAPER_R = {("Al2O3", "silicone"): 2.2e-8, ("AlN", "silicone"): 3.0e-8,
           ("Al2O3", "Al2O3"): 2.0e-7, ("AlN", "AlN"): 1.0e-7, ("Al2O3", "AlN"): 3.0e-7}


def _demo(args: argparse.Namespace) -> int:
    """Random Al2O3/silicone RVE -> k_eff printed, .vti and PNG written."""
    from itr_fv import Materials, homogenize
    from itr_fv.rve import FillerSpec, generate_rve

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    voxel_um = args.box_um / args.n
    ms = generate_rve([FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=args.fraction)],
                      box_um=args.box_um, voxel_um=voxel_um, seed=args.seed, matrix="silicone")
    print(f"RVE: {ms!r} ({time.perf_counter() - t0:.1f} s)")
    mat = Materials(PAPER_K, PAPER_R, matrix="silicone")
    if args.solver == "fft":
        import itr_fft
        solve = itr_fft.homogenize
    else:
        solve = homogenize
    res = solve(ms, mat, tol=args.tol)
    print(res.summary())
    vti = res.to_vtk(out / "demo.vti")
    png = res.render_png(out / "demo.png")
    summary = {"k_eff_W_per_mK": res.k_eff.tolist(), "iterations": res.iterations,
               "volume_fractions": ms.volume_fractions(), "voxel_um": voxel_um,
               "seed": args.seed, "solver": res.solver}
    (out / "demo.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {vti}, {png}, {out / 'demo.json'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="itr", description="Interfacial thermal resistance in particle-laden composites.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="random Al2O3/silicone RVE: k_eff, .vti and PNG")
    demo.add_argument("--n", type=int, default=72, help="voxels per edge (default 72)")
    demo.add_argument("--box-um", type=float, default=30.0, help="box edge, um (default 30)")
    demo.add_argument("--fraction", type=float, default=0.5,
                      help="Al2O3 volume fraction (default 0.5)")
    demo.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    demo.add_argument("--solver", choices=["fv", "fft"], default="fv")
    demo.add_argument("--tol", type=float, default=1e-8)
    demo.add_argument("--out", default="itr-demo", help="output folder (default itr-demo)")
    demo.set_defaults(func=_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``itr`` console command."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except ValueError as exc:
        print(f"itr: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
