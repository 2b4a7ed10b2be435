"""The solve against the hardware's limit (issue 50), in one run.

Prints and writes (``bench_limit.md`` and ``.json`` under ``--out``):

1. **Bandwidth, measured here in this run**: a STREAM triad ``a = b + s c`` by a parallel
   numba kernel on three float64 arrays of 2^25 values (24 bytes per element moved; the
   best of 10), at every thread count of the scaling table, and a NumPy copy for comparison.
2. **Old and new path** on ``al2o3_60`` of the common RVE set (dense 60 % Al2O3, gap model)
   and AlN-60 (Table 1's AlN at 0.125 um voxels, R = 3e-8 m^2 K/W, gap model, the boxes of
   ``validation/bench_gpu.py``) at each ``--sizes`` grid, three load cases, tol 1e-8, on
   one built problem:

   - ``old``: the default solver (``"fft"``: the numba backend with the ``auto``
     preconditioner, the load cases one after the other, float64);
   - ``block``: the load cases in lockstep, each conductance read once per iteration for
     the three (``block=True``; the array-API backend's way);
   - ``mixed``: the block with ``precision="mixed"`` (float32 conductances and work
     vectors, float64 x, reductions and residual checks).

   Wall (conductances, preconditioner set-up, solves, tensors), CG seconds, iterations,
   time per load-case iteration against the minimal traffic of that iteration at the
   triad bandwidth (model below), and the tensor's largest difference from ``old``.
3. **Thread scaling** of the new path at the first size (1, 2, 4, ... threads up to the
   cores here).
4. **Mixed precision's accuracy** against double precision on the common RVE set at 64^3
   and the faithful AlN-60 RVE (40 um at 0.16 um, 250^3; ``--faithful 0`` skips it):
   iterations, the final true relative residual, the largest relative difference of k.
5. **The GPU** where a CUDA device is seen: the steps of ``validation/bench_gpu.py`` at
   512^3 (issue 38's check, now with the lockstep block solve and the fused block kernel),
   within ``--gpu-budget-s``; else "GPU unverified".

Minimal traffic of one load case's CG iteration, bytes per voxel (each array read or
written once, neighbours from cache; ``m`` load cases in a block share the conductances):

- operator: conductances 3 values / m, p in, q out;
- update ``x += a p, r -= a q`` (x, r read and written; p, q read) and direction
  ``p = z + b p`` (z, p read; p written);
- FFT preconditioner: r in, the half spectrum (N/2 complex = N values of the FFT precision)
  out and in again, z out (an ideal one-pass transform);
- multigrid preconditioner (particle deflation around the V-cycle,
  :mod:`itr_fft.deflation`, :mod:`itr_fft.multigrid`): per application the float64
  conductances twice (the two deflation passes, with r, r1, groups), the float32
  conductances four times (three Jacobi sweeps and the restriction, with their vectors),
  the coarse levels an eighth of the fine one each, and the final combination: itemised in
  :func:`multigrid_bytes`.

Usage::

    python validation/bench_limit.py [--sizes 128,192] [--faithful 250] [--out DIR]
    python validation/bench_limit.py --sizes 48 --faithful 0 --common 24   # quick
    python validation/bench_limit.py --gpu-only --out $OUT/limit         # a lent device

On a lent device (recipe: ``../shared/gpu/README.md``; the wheels travel with ``carry``), the
one device command, within the 8 minutes of one run::

    python3 -m pip install -q --no-index --no-deps --no-compile --target .site .whl/*.whl \
      && export PYTHONPATH=$PWD/.site PYTHONUNBUFFERED=1 \
      && python3 validation/bench_limit.py --gpu-only --gpu-budget-s 420 --out $OUT/limit
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import itr_fft  # noqa: E402,F401  (registers the backends)
from itr_fv import homogenize  # noqa: E402
from itr_fv.discrete.problem import DiscreteProblem  # noqa: E402
from itr_fv.solvers.backends import backend_for  # noqa: E402
from itr_fv.solvers.devices import cuda_device_count  # noqa: E402
from validation.bench_gpu import aln_problem  # noqa: E402
from validation.bench_preconditioners import faithful_aln  # noqa: E402
from validation.gallery import build, rve_cases  # noqa: E402

RESULTS = ROOT / "validation" / "results"
TOL = 1e-8
#: Backend options of the paths (the numba backend, ``"fft"`` solver choice).
PATHS = {"old": {"block": False}, "block": {"block": True},
         "mixed": {"block": True, "precision": "mixed"}}
#: Acceptance of issue 50 (CPU): wall at least 2x faster than ``old``, time per iteration
#: within 2x of the minimal traffic, tensors equal to 1e-8 relative.
TARGETS = {"speed_up": 2.0, "traffic_ratio": 2.0, "tensor": 1e-8}


# ----------------------------------------------------------------------- bandwidth

@numba.njit(parallel=True, cache=False)
def _triad(a, b, c, s):  # pragma: no cover - compiled
    for i in numba.prange(a.size):
        a[i] = b[i] + s * c[i]


def bandwidth(threads: int, n: int = 2**25, repeats: int = 10) -> dict:
    """Triad and copy bandwidth (bytes moved per second, the best of ``repeats``, as
    STREAM reports it) on ``threads`` threads."""
    old = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        a, b, c = np.empty(n), np.ones(n), np.full(n, 2.0)
        _triad(a, b, c, 0.5)
        best_triad = best_copy = math.inf
        for _ in range(repeats):
            t = time.perf_counter()
            _triad(a, b, c, 0.5)
            best_triad = min(best_triad, time.perf_counter() - t)
            t = time.perf_counter()
            np.copyto(a, b)
            best_copy = min(best_copy, time.perf_counter() - t)
    finally:
        numba.set_num_threads(old)
    return {"threads": threads, "triad_Bps": 3 * 8 * n / best_triad,
            "numpy_copy_Bps": 2 * 8 * n / best_copy}


# ---------------------------------------------------------------- the traffic model

def cg_bytes(*, mixed: bool, block: int) -> float:
    """Bytes per voxel of one load case's CG iteration without the preconditioner."""
    g, x, w = (4, 8, 4) if mixed else (8, 8, 8)  # conductance, x, work vectors (r, p, q)
    operator = 3 * g / block + 2 * w
    update = 2 * x + 2 * w + 2 * w  # x and r read + written, p and q read
    direction = 4 + 2 * w  # z (float32 FFT output, or the multigrid's) in, p in and out
    return operator + update + direction


def fft_bytes(*, mixed: bool) -> float:
    """Bytes per voxel of the FFT preconditioner (float32 transforms): r in (float64 in
    double precision), the half spectrum out and in (4 + 4), z out (4)."""
    return (4 if mixed else 8) + 4 + 4 + 4


def multigrid_bytes(*, mixed: bool) -> float:
    """Bytes per voxel of one application of the particle-deflated multigrid.

    Deflation (float64 conductances, 24 B): group sums of r (r, groups 4); r1 = r - A Z c1
    (g 24, groups 4, r, r1 8 out); the V-cycle's input copy to float32 (8 in, 4 out);
    r2 = r1 - A y with its group sums (g 24, y 4, r1 8 in and out, groups 4); z = y + Z c
    with r . z (y 4, groups 4, r, z 8 out). V-cycle on the fine level (float32
    conductances 12 B, vectors 4 B): first sweep (g, b, x out), one more sweep (g, b, x,
    tmp), the restriction (g, members 1, b, x, coarse b out 0.5), the prolongation
    (x in and out, members, coarse 0.5), two sweeps after; coarser levels add 1/7 of that.
    """
    r = 4 if mixed else 8
    deflation = (r + 4) + (24 + 4 + r + 8) + (8 + 4) + (24 + 4 + 8 + 8 + 4) \
        + (4 + 4 + r + 8)
    fine = (12 + 4 + 4) + (12 + 4 + 4 + 4) + (12 + 1 + 4 + 4 + 0.5) + (4 + 4 + 1 + 0.5) \
        + 2 * (12 + 4 + 4 + 4)
    return deflation + fine * 8 / 7


def iteration_bytes(*, preconditioner: str, mixed: bool, block: int) -> float:
    """Minimal bytes per voxel of one load case's preconditioned CG iteration."""
    pre = fft_bytes(mixed=mixed) if preconditioner == "fft" else multigrid_bytes(mixed=mixed)
    return cg_bytes(mixed=mixed, block=block) + pre


# ----------------------------------------------------------------------- the solves

def problems(n: int) -> dict:
    """The two RVEs of the path table at n^3: name -> (problem, materials)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ms, mat = build("al2o3_60", n, contact="gap")
        al = DiscreteProblem.for_materials(ms, mat)
        aln, aln_mat, _ = aln_problem(n)
    return {"al2o3_60": (al, mat), "AlN-60": (aln, aln_mat)}


def solve(problem: DiscreteProblem, mat, options: dict, *, tol: float = TOL,
          workers: int | None = None) -> dict:
    """Three load cases by the numba backend with ``options``: times, iterations, k."""
    backend = backend_for("itr_fft", workers=workers, **options)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # voxel-contact notes of the common set's "area" RVEs
        t = time.perf_counter()
        res = homogenize(problem, mat, solver=backend, tol=tol, store_fields=False,
                         check_memory=False, strict=False)
        wall = time.perf_counter() - t
    cg = float(sum(res.solve_times))
    its = [int(i) for i in res.iterations]
    return {"wall_s": wall, "cg_s": cg, "iterations": its,
            "s_per_iteration": cg / max(sum(its), 1), "k_eff": res.k_eff.tolist(),
            "residual": float(max(res.residuals)), "converged": bool(res.converged),
            "preconditioner": res.info["preconditioner"], "workers": res.info["workers"]}


def rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def path_table(sizes: list[int], bw: float, log) -> list[dict]:
    rows = []
    for n in sizes:
        for name, (problem, mat) in problems(n).items():
            problem.system(mat)  # the geometry is built once, outside every path's wall
            out: dict = {"rve": name, "n": n}
            for path, options in PATHS.items():
                r = solve(problem, mat, options)
                mixed = options.get("precision") == "mixed"
                block = 3 if options["block"] else 1
                need = iteration_bytes(preconditioner=r["preconditioner"], mixed=mixed,
                                       block=block)
                r["traffic_s"] = need * n**3 / bw
                r["traffic_bytes_per_voxel"] = need
                r["traffic_ratio"] = r["s_per_iteration"] / r["traffic_s"]
                out[path] = r
                log(f"{name} {n}^3 {path}: wall {r['wall_s']:.2f} s (CG {r['cg_s']:.2f} s), "
                    f"iterations {r['iterations']}, {r['preconditioner']}, "
                    f"{1e3 * r['s_per_iteration']:.1f} ms/iteration = "
                    f"{r['traffic_ratio']:.1f}x the minimal traffic ({need:.0f} B/voxel)")
            for path in ("block", "mixed"):
                out[path]["speed_up"] = out["old"]["wall_s"] / out[path]["wall_s"]
                out[path]["tensor_vs_old"] = rel(out[path]["k_eff"], out["old"]["k_eff"])
            rows.append(out)
            del problem
    return rows


def thread_table(n: int, threads: list[int], log) -> list[dict]:
    rows = []
    for name, (problem, mat) in problems(n).items():
        problem.system(mat)
        for t in threads:
            bw = bandwidth(t)
            r = solve(problem, mat, PATHS["block"], workers=t)
            rows.append({"rve": name, "n": n, "threads": t, "wall_s": r["wall_s"],
                         "s_per_iteration": r["s_per_iteration"],
                         "iterations": r["iterations"], "triad_Bps": bw["triad_Bps"]})
            log(f"threads {t}: {name} {n}^3 block wall {r['wall_s']:.2f} s, "
                f"{1e3 * r['s_per_iteration']:.1f} ms/iteration; triad "
                f"{bw['triad_Bps'] / 1e9:.1f} GB/s")
    return rows


def accuracy_table(common: int, faithful: int, log) -> list[dict]:
    cases = [(c.name, lambda c=c: build(c.name, common)) for c in rve_cases()]
    if faithful:
        cases.append((f"faithful AlN-60 {faithful}^3", lambda: faithful_aln(faithful)))
    rows = []
    for name, make in cases:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ms, mat = make()
        problem = DiscreteProblem.for_materials(ms, mat)
        d = solve(problem, mat, PATHS["block"])
        m = solve(problem, mat, PATHS["mixed"])
        row = {"rve": name, "n": int(ms.shape[0]), "iterations_double": d["iterations"],
               "iterations_mixed": m["iterations"], "residual_double": d["residual"],
               "residual_mixed": m["residual"], "k_difference": rel(m["k_eff"], d["k_eff"]),
               "wall_double_s": d["wall_s"], "wall_mixed_s": m["wall_s"]}
        rows.append(row)
        log(f"mixed vs double, {name}: iterations {m['iterations']} / {d['iterations']}, "
            f"residual {m['residual']:.1e} / {d['residual']:.1e}, k differs by "
            f"{row['k_difference']:.1e}")
    return rows


def gpu_steps(budget_s: float, log) -> dict | None:
    """Issue 38's device steps (validation/bench_gpu.py) at 512^3 where CUDA is seen."""
    if cuda_device_count() == 0:
        log("no CUDA device: GPU unverified")
        return None
    from validation import bench_gpu
    facts = bench_gpu.device_facts(True)
    log(f"device: {facts['name']}; copy bandwidth {facts['copy_Bps'] / 1e9:.0f} GB/s")
    out = bench_gpu.run_steps(512, "cuda", facts, bench_gpu.Budget(budget_s), log)
    out["facts"] = facts
    out["table"] = bench_gpu.table(out, facts)
    for line in out["table"]:
        log(line)
    return out


# --------------------------------------------------------------------------- report

def markdown(res: dict) -> list[str]:
    bw = res["bandwidth"]
    lines = ["# The solve against the hardware's limit (validation/bench_limit.py)", "",
             f"Machine: {res['machine']}. tol = {TOL:g}, three load cases. Bandwidth measured "
             f"in this run: triad {bw['triad_Bps'] / 1e9:.1f} GB/s on {bw['threads']} "
             f"threads (NumPy copy {bw['numpy_copy_Bps'] / 1e9:.1f} GB/s).", "",
             "## Old and new path", "",
             "`old`: the load cases one after the other (the default solver `fft`); "
             "`block`: in lockstep, conductances read once per iteration for the three "
             "(`block=True`); `mixed`: the block in mixed precision. Traffic: minimal "
             "bytes of one load case's iteration (module docstring) at the triad "
             "bandwidth.", "",
             "| RVE | grid | path | preconditioner | wall (s) | speed-up | iterations | "
             "ms/iteration | traffic (ms) | ratio | tensor vs old |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for row in res["paths"]:
        for path in PATHS:
            r = row[path]
            lines.append(
                f"| {row['rve']} | {row['n']}^3 | {path} | {r['preconditioner']} | "
                f"{r['wall_s']:.2f} | {r.get('speed_up', 1.0):.2f}x | "
                f"{sum(r['iterations'])} | {1e3 * r['s_per_iteration']:.1f} | "
                f"{1e3 * r['traffic_s']:.1f} | {r['traffic_ratio']:.1f}x | "
                f"{r.get('tensor_vs_old', 0.0):.1e} |")
    best = [max(row["block"]["speed_up"], row["mixed"]["speed_up"]) for row in res["paths"]]
    ratio = [min(row["block"]["traffic_ratio"], row["mixed"]["traffic_ratio"])
             for row in res["paths"]]
    tensor = [max(row["block"]["tensor_vs_old"], row["mixed"]["tensor_vs_old"])
              for row in res["paths"]]
    lines += ["", "Acceptance (issue 50, CPU): speed-up >= 2x: "
              f"{'holds' if min(best) >= TARGETS['speed_up'] else 'missed'} (best new path "
              f"{min(best):.2f}x to {max(best):.2f}x); per-iteration time within 2x of the "
              f"minimal traffic: {'holds' if max(ratio) <= TARGETS['traffic_ratio'] else 'missed'}"
              f" ({min(ratio):.1f}x to {max(ratio):.1f}x); tensors equal to 1e-8: "
              f"{'holds' if max(tensor) <= TARGETS['tensor'] else 'missed'} (largest "
              f"{max(tensor):.1e}).", "", "## Thread scaling (block path)", "",
              "| RVE | grid | threads | wall (s) | ms/iteration | speed-up | triad (GB/s) |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    first = {}
    for r in res["threads"]:
        base = first.setdefault(r["rve"], r["wall_s"])
        lines.append(f"| {r['rve']} | {r['n']}^3 | {r['threads']} | {r['wall_s']:.2f} | "
                     f"{1e3 * r['s_per_iteration']:.1f} | {base / r['wall_s']:.2f}x | "
                     f"{r['triad_Bps'] / 1e9:.1f} |")
    lines += ["", "## Mixed precision against double precision", "",
              "| RVE | grid | iterations mixed / double | true residual mixed / double | "
              "k difference | wall mixed / double (s) |", "| --- | --- | --- | --- | --- | --- |"]
    for r in res["accuracy"]:
        lines.append(f"| {r['rve']} | {r['n']}^3 | {sum(r['iterations_mixed'])} / "
                     f"{sum(r['iterations_double'])} | {r['residual_mixed']:.1e} / "
                     f"{r['residual_double']:.1e} | {r['k_difference']:.1e} | "
                     f"{r['wall_mixed_s']:.2f} / {r['wall_double_s']:.2f} |")
    lines += ["", "## GPU", ""]
    gpu = res.get("gpu")
    lines += (gpu["table"] if gpu else
              ["GPU unverified: no CUDA device in this run (the same script runs issue 38's "
               "device steps at 512^3 where one is seen)."])
    lines += ["", "## Log", "", *[f"    {line}" for line in res["log"]]]
    return lines


def write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="128,192", help="grid edges of the path table")
    ap.add_argument("--threads", default=None,
                    help="thread counts of the scaling table (default 1, 2, 4, ... cores)")
    ap.add_argument("--common", type=int, default=64, help="grid of the accuracy table")
    ap.add_argument("--faithful", type=int, default=250,
                    help="grid of the faithful AlN-60 RVE in the accuracy table (0: none)")
    ap.add_argument("--gpu-budget-s", type=float, default=420.0,
                    help="seconds for the GPU steps where a device is seen")
    ap.add_argument("--out", default=str(RESULTS), help="folder for bench_limit.md/.json")
    ap.add_argument("--gpu-only", action="store_true",
                    help="only the GPU steps (bench_limit_gpu.md/.json): the device run")
    ap.add_argument("--render", action="store_true",
                    help="only write bench_limit.md again from the bench_limit.json there")
    args = ap.parse_args(argv)
    if args.render:
        res = json.loads((Path(args.out) / "bench_limit.json").read_text())
        write_atomic(Path(args.out) / "bench_limit.md", "\n".join(markdown(res)) + "\n")
        return 0
    try:
        sizes = [int(s) for s in args.sizes.split(",") if s]
        cores = numba.config.NUMBA_NUM_THREADS
        threads = ([int(t) for t in args.threads.split(",")] if args.threads else
                   [t for t in (1, 2, 4, 8, 16, 32, 64) if t <= cores])
    except ValueError:
        ap.error("--sizes, --threads: comma-separated integers expected")
    if not sizes or min(sizes) < 8 or min(threads) < 1:
        ap.error("--sizes: grids of at least 8; --threads: at least 1")
    folder = Path(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    lines: list[str] = []

    def log(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    res: dict = {"machine": f"{os.cpu_count()} cores, {platform.machine()}, Python "
                            f"{platform.python_version()}, numba {numba.__version__}"}
    res["gpu"] = gpu_steps(args.gpu_budget_s, log)  # first: a lent device's time runs out
    if args.gpu_only:
        gpu = res["gpu"]
        text = ["# The GPU steps of validation/bench_limit.py", "", f"Host: {res['machine']}.",
                "", *(gpu["table"] if gpu else ["GPU unverified: no CUDA device seen."]),
                "", "## Log", "", *[f"    {line}" for line in lines]]
        write_atomic(folder / "bench_limit_gpu.json", json.dumps(res, indent=1, default=float))
        write_atomic(folder / "bench_limit_gpu.md", "\n".join(text) + "\n")
        return 0
    res["bandwidth"] = bandwidth(max(threads))
    log(f"bandwidth: triad {res['bandwidth']['triad_Bps'] / 1e9:.1f} GB/s on "
        f"{max(threads)} threads, NumPy copy {res['bandwidth']['numpy_copy_Bps'] / 1e9:.1f}"
        " GB/s")
    res["paths"] = path_table(sizes, res["bandwidth"]["triad_Bps"], log)
    res["threads"] = thread_table(sizes[0], threads, log)
    res["accuracy"] = accuracy_table(args.common, args.faithful, log)
    res["log"] = lines
    write_atomic(folder / "bench_limit.json", json.dumps(res, indent=1, default=float))
    write_atomic(folder / "bench_limit.md", "\n".join(markdown(res)) + "\n")
    print(f"wrote {folder / 'bench_limit.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
