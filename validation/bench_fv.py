"""Benchmark of the reference FV solver (itr_fv.homogenize) on dense random RVEs.

For 64^3, 96^3 and 128^3 Al2O3/silicone RVEs (55 vol%, 0.3125 um voxels, so 20, 30 and
40 um boxes; k_p/k_m = 30/0.18 ~ 170) and interface resistances R in 1e-8..1e-6 m^2 K/W
(filler-matrix and filler-filler alike), prints set-up time, solve time per load case,
CG iterations and peak memory, each case in a fresh process; writes
validation/results/bench_fv.md. Also compares the two pyamg hierarchies at 64^3.

Run:  python validation/bench_fv.py [--sizes 64 96 128] [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def one_case(n: int, R: float, amg: str) -> dict:
    """Run one solve in this process and return its figures."""
    import numpy as np

    from itr_fv import Materials, homogenize, resolve_solver
    from itr_fv.rve import FillerSpec, RVESpec, generate_rve

    t0 = time.perf_counter()
    ms = generate_rve(RVESpec(0.3125 * n, 0.3125, max_diameter_box_ratio=1 / 3),
                      [FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.55)], 7,
                      matrix="silicone")
    t_rve = time.perf_counter() - t0
    mat = Materials({"silicone": 0.18, "Al2O3": 30.0},
                    {("Al2O3", "silicone"): R, ("Al2O3", "Al2O3"): R}, matrix="silicone",
                    contact="area")
    res = homogenize(ms, mat, solver=resolve_solver("fv", amg=amg), tol=1e-8, store_fields=False)
    return {"n": n, "R": R, "amg": amg, "rve_s": t_rve, "setup_s": res.setup_time,
            "solve_s": res.solve_times, "iterations": res.iterations,
            "k_diag": np.diag(res.k_eff).tolist(), "wall_s": res.wall_time,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "levels": res.info["amg_levels"], "complexity": res.info["operator_complexity"]}


def run_isolated(n: int, R: float, amg: str) -> dict:
    cmd = [sys.executable, __file__, "--one", str(n), str(R), amg]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"})
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 96, 128])
    parser.add_argument("--resistances", type=float, nargs="+", default=[1e-8, 1e-7, 1e-6])
    parser.add_argument("--one", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one_case(int(args.one[0]), float(args.one[1]), args.one[2])))
        return
    rows = []
    load = os.getloadavg()[0]
    header = ("| n^3 | R (m^2K/W) | AMG | set-up (s) | solve per load case (s) | iterations | "
              "k_xx, k_yy, k_zz (W/mK) | peak RSS (MB) |")
    print(header)
    cases = [(n, R, "classical") for n in args.sizes for R in args.resistances]
    cases += [(min(args.sizes), R, "smoothed_aggregation") for R in args.resistances]
    for n, R, amg in cases:
        r = run_isolated(n, R, amg)
        row = (f"| {n}^3 | {R:.0e} | {amg} | {r['setup_s']:.1f} | "
               f"{', '.join(f'{t:.1f}' for t in r['solve_s'])} | "
               f"{', '.join(str(i) for i in r['iterations'])} | "
               f"{', '.join(f'{k:.4f}' for k in r['k_diag'])} | {r['peak_rss_mb']:.0f} |")
        print(row, flush=True)
        rows.append(row)
    RESULTS.mkdir(exist_ok=True)
    text = [
        "# FV reference solver benchmark (validation/bench_fv.py)", "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"Python {platform.python_version()}. Dense random Al2O3/silicone RVEs, 55 vol%, "
        "0.3125 um voxels (box = 0.3125 n um), k_p/k_m = 30/0.18 = 167, R applied to "
        "filler-matrix and filler-filler faces; tol = 1e-8 (relative residual); each case in "
        "a fresh process (peak RSS includes the RVE generation and Python itself). "
        f"Load average when the run started: {load:.1f} (times above ~{max(load, 2) / 2:.0f}x "
        "inflated where other jobs shared the 2 cores).", "",
        header, "|---|---|---|---|---|---|---|---|", *rows, "",
    ]
    (RESULTS / "bench_fv.md").write_text("\n".join(text))
    print(f"wrote {RESULTS / 'bench_fv.md'}")


if __name__ == "__main__":
    main()
