"""Benchmark: the array-API backend on a GPU (CuPy), against the memory-bandwidth limit.

For each grid (128^3 ... 512^3 and the largest that fits, by default) and each precision
(float64, float32) it solves one load case of the dense 60 % Al2O3 RVE of the common set
(``al2o3_60``, gap model, the same particles at every grid) with the ``"array_api"``
backend and reports the time per CG iteration against the time the iteration's minimal
memory traffic would take at the device's peak bandwidth, and the CPU time of the same RVE
with the numba backend ``"itr_fft"``.

Minimal traffic model, per iteration, in arrays of N values: the operator reads the three
conductances and x and writes A x (5); the FFT pair reads and writes the field once each
way (4); CG's updates and dot products touch 14 (x, r, p, q, z). So 23 N values; the real
count is higher (the array-expression operator makes temporaries, a 3-D FFT takes several
passes), so the ratio measured / limit says how far the code is from the hardware.

Where no GPU is found it runs on the CPU (NumPy namespace) at small grids and says so.
Writes ``validation/results/bench_gpu.md`` and ``.json``.

Usage::

    python validation/bench_gpu.py [--sizes 128,256,384,512] [--cpu-sizes 64,128]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import itr_fft  # noqa: E402
from itr_fft.array_api_backend import (  # noqa: E402
    FLOAT32_FLOOR_FACTOR,
    ArrayAPIBackend,
    _cuda_available,
)
from itr_fv.discrete.problem import DiscreteProblem  # noqa: E402
from itr_fv.solvers.driver import homogenize  # noqa: E402
from validation.gallery import build  # noqa: E402

RESULTS = ROOT / "validation" / "results"
CASE = "al2o3_60"
#: Arrays of N values the minimal iteration moves (module docstring).
ARRAYS_PER_ITERATION = 23
TOL = {"float64": 1e-8, "float32": None}  # float32: the backend's floor on the grid


def gpu_facts() -> dict | None:
    """Name, memory (bytes) and peak bandwidth (bytes/s) of the CUDA device, or None."""
    if _cuda_available() != "cupy":
        return None
    import cupy
    dev = cupy.cuda.Device()
    props = cupy.cuda.runtime.getDeviceProperties(dev.id)
    free, total = cupy.cuda.runtime.memGetInfo()
    # DDR/HBM: two transfers per memory clock (kHz) over the bus width (bits)
    bandwidth = 2.0 * props["memoryClockRate"] * 1e3 * props["memoryBusWidth"] / 8.0
    name = props["name"].decode() if isinstance(props["name"], bytes) else str(props["name"])
    return {"name": name, "total_bytes": int(total), "free_bytes": int(free),
            "bandwidth_Bps": bandwidth}


def _one(problem, mat, backend, tol) -> dict:
    t = time.perf_counter()
    res = homogenize(problem, mat, backend=backend, tol=tol, directions=(0,),
                     store_fields=False, check_memory=False)
    wall = time.perf_counter() - t
    it = res.iterations[0]
    return {"iterations": it, "solve_s": res.solve_times[0], "wall_s": wall,
            "s_per_iteration": res.solve_times[0] / max(it, 1),
            "k_xx": float(res.k_eff[0, 0]), "residual": float(res.residuals[0])}


def run(sizes: list[int], device: str, bandwidth: float | None, cpu_compare: set[int]
        ) -> list[dict]:
    rows = []
    for n in sizes:
        ms, mat = build(CASE, n, contact="gap")
        problem = DiscreteProblem.for_materials(ms, mat)
        for dtype in ("float64", "float32"):
            tol = TOL[dtype] or FLOAT32_FLOOR_FACTOR * itr_fft.float32_min_tol(ms.shape)
            backend = ArrayAPIBackend(device=device, dtype=np.dtype(dtype))
            try:
                r = _one(problem, mat, backend, tol)
            except MemoryError as err:  # the GPU ran out: the largest that fits is below
                print(f"{n}^3 {dtype}: out of memory ({err})", flush=True)
                continue
            itemsize = np.dtype(dtype).itemsize
            moved = ARRAYS_PER_ITERATION * itemsize * n ** 3
            r.update(n=n, dtype=dtype, tol=tol, device=device,
                     limit_s=moved / bandwidth if bandwidth else None)
            if n in cpu_compare:
                r["cpu"] = _one(problem, mat, itr_fft.NumbaFFTBackend(
                    dtype=np.dtype(dtype)), tol)
            rows.append(r)
            lim = f"{r['limit_s'] * 1e3:.2f} ms" if r["limit_s"] else "-"
            print(f"{n}^3 {dtype} on {device}: {r['iterations']} it, "
                  f"{r['s_per_iteration'] * 1e3:.2f} ms/it (bandwidth limit {lim})", flush=True)
        del problem, ms
    return rows


def write_report(rows: list[dict], facts: dict | None, device: str, machine: str,
                 path: Path) -> None:
    if facts:
        where = (f"GPU: {facts['name']}, {facts['total_bytes'] / 2**30:.0f} GiB, peak "
                 f"bandwidth {facts['bandwidth_Bps'] / 1e12:.2f} TB/s (memory clock x bus "
                 "width).")
    else:
        where = ("**No GPU here: GPU unverified.** These rows are the same code on the CPU "
                 "(NumPy namespace), to show the script and the backend run; on a machine "
                 "with CuPy and a CUDA device the script measures the GPU.")
    lines = ["# The array-API backend on a GPU", "",
             "Generated by `python validation/bench_gpu.py`. RVE `al2o3_60` of the common "
             "set (dense 60 % Al2O3, gap model), one load case; float64 at tol 1e-8, float32 "
             "at the backend's float32 floor (4 `float32_min_tol`).", "", where, machine, "",
             f"Bandwidth limit = {ARRAYS_PER_ITERATION} arrays of N values per iteration at "
             "the peak bandwidth (see the script's docstring).", "",
             "| grid | dtype | device | iterations | ms / iteration | limit (ms) | "
             "measured / limit | CPU itr_fft ms / iteration | k_xx |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lim = f"{r['limit_s'] * 1e3:.2f}" if r["limit_s"] else "-"
        ratio = f"{r['s_per_iteration'] / r['limit_s']:.1f}x" if r["limit_s"] else "-"
        cpu = f"{r['cpu']['s_per_iteration'] * 1e3:.1f}" if "cpu" in r else "-"
        lines.append(f"| {r['n']}^3 | {r['dtype']} | {r['device']} | {r['iterations']} | "
                     f"{r['s_per_iteration'] * 1e3:.2f} | {lim} | {ratio} | {cpu} | "
                     f"{r['k_xx']:.6g} |")
    path.write_text("\n".join(lines) + "\n")


def largest_fitting(facts: dict, bytes_per_voxel: float = 8 * 16) -> int:
    """Largest grid edge (multiple of 32) whose float64 solve fits the free memory."""
    n = int((facts["free_bytes"] / bytes_per_voxel) ** (1 / 3))
    return max(32, n // 32 * 32)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="128,256,384,512",
                    help="grids on a GPU (the largest that fits is added)")
    ap.add_argument("--cpu-sizes", default="64,128", help="grids when no GPU is found")
    ap.add_argument("--compare", default="128,256",
                    help="grids also solved on the CPU with itr_fft")
    ap.add_argument("--out", default=str(RESULTS / "bench_gpu.md"))
    args = ap.parse_args(argv)
    facts = gpu_facts()
    machine = (f"Host: {os.cpu_count()} cores, {platform.machine()}, Python "
               f"{platform.python_version()}, load average {os.getloadavg()[0]:.1f}.")
    if facts:
        device = "cuda"
        sizes = [int(s) for s in args.sizes.split(",") if s]
        top = largest_fitting(facts)
        if top > max(sizes):
            sizes.append(top)
    else:
        device = "cpu"
        sizes = [int(s) for s in args.cpu_sizes.split(",") if s]
        print("no CUDA device visible to CuPy: running the array-API backend on the CPU "
              "(GPU unverified)", flush=True)
    compare = {int(s) for s in args.compare.split(",") if s}
    rows = run(sizes, device, facts["bandwidth_Bps"] if facts else None, compare)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_report(rows, facts, device, machine, out)
    out.with_suffix(".json").write_text(json.dumps(
        {"rows": rows, "gpu": facts, "machine": machine}, indent=1, default=float))
    print(f"wrote {out}")
    return 0 if rows and all(math.isfinite(r["k_xx"]) for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
