"""Peak memory per voxel of each solver: the figures behind :mod:`itr_fv.solvers.resources`.

Each (solver, dtype, grid) runs in a fresh interpreter (``bench_solvers.py --one``: the
dense 60 % Al2O3 RVE of the common set, three load cases, store_fields=False); the cost per
voxel is (peak RSS - RSS before the solve) / voxels. Writes
``validation/results/memory.md`` and compares the measured peaks with the estimates the
memory guard uses.

Usage::

    python validation/bench_memory.py [--fv 64,96,128] [--fft 96,160,192]
"""

from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from validation.bench_solvers import run_sub  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fv", default="64,96,128")
    ap.add_argument("--fft", default="96,160,192")
    ap.add_argument("--out", default=str(ROOT / "validation" / "results" / "memory.md"))
    args = ap.parse_args()
    from itr_fv.solvers import resources

    cases = [("itr_fv", int(n), "float64") for n in args.fv.split(",") if n]
    cases += [("itr_fft", int(n), dt) for dt in ("float64", "float32")
              for n in args.fft.split(",") if n]
    lines = ["# Peak memory per voxel (memory guard calibration)", "",
             f"Machine: {platform.platform()}, Python {platform.python_version()}. Dense 60 % "
             "Al2O3 RVE, 3 load cases, store_fields=False, each case in a fresh process. The guard "
             "estimates the growth (peak minus before), not the interpreter's baseline; MB = "
             "2^20 bytes.", "",
             "| solver | dtype | grid | peak RSS (MB) | before solve (MB) | bytes/voxel | "
             "guard estimate (MB) |", "|---|---|---|---|---|---|---|"]
    for solver, n, dt in cases:
        r = run_sub(solver, n, dt)
        if "error" in r:
            lines.append(f"| {solver} | {dt} | {n}^3 | error: {r['error'][:80]} | | | |")
            continue
        per = (r["rss_mb"] - r["rss_before_mb"]) * 2**20 / n**3
        est = resources.estimate_peak_memory((n, n, n), solver, dtype=dt, store_fields=False)
        lines.append(f"| {solver} | {dt} | {n}^3 | {r['rss_mb']:.0f} | {r['rss_before_mb']:.0f} "
                     f"| {per:.0f} | {est / 2**20:.0f} |")
        print(lines[-1], flush=True)
    lines += ["", "Constants used by the guard (bytes per voxel): "
              f"FV {resources.FV_BYTES_PER_VOXEL}, FFT float64 {resources.FFT64_BYTES_PER_VOXEL}, "
              f"FFT float32 {resources.FFT32_BYTES_PER_VOXEL}, fields "
              f"{resources.FIELD_BYTES_PER_VOXEL_CASE} per load case."]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
