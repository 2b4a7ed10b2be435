"""Device check of issue 38: the accelerator path against its acceptance table, in one run.

Prints the acceptance table as it goes and writes it (``bench_gpu.md`` and ``.json``) under
``--out``. Each step is timed against a budget (``--budget-s``, default 450 s: the script
ends within 8 minutes on a lent device); a step that would not fit is skipped and said so.

Steps (on a CUDA device; with none, the same steps on the CPU at small grids, marked
"GPU unverified"):

1. the device: name, memory, and the copy bandwidth measured here (``dst[...] = src`` on
   two 1 GiB arrays: bytes read + written / time);
2. warm-up at 64^3 (kernels compiled, FFT plans made) for every path;
3. ``al2o3_60`` of the common RVE set at 512^3 (dense 60 % Al2O3, gap model), three load
   cases, float64, tol 1e-8: the *old* path (``kernels="portable"``: whole-array
   expressions, as before issue 38) and the *new* path (``kernels="fused"`` where numba's
   CUDA target is usable); CG seconds (sum of the load cases' solve times), wall seconds,
   iterations, time per iteration against the minimal traffic at the measured bandwidth;
4. AlN-60 in a 64 um box at 0.125 um (512^3, Table 1's AlN, R = 3e-8 m^2 K/W, gap model),
   three load cases: the problem build (geometry + conductances) and the solve wall, old
   path (FFT preconditioner) and new path (multigrid preconditioner on the device);
5. the new path's tensor against the old path's (both to tol 1e-8: they must agree to
   about 1e-7 relative) and, on a small grid, against the numba CPU backend;
6. ``--reproduce``: ``itr reproduce --parametrisation gap --no-leave-one-out`` on the CPU
   and with ``--device cuda``; their ``identified.json`` compared to 1e-6 relative (only
   where the budget leaves room: it is the longest step).

Acceptance (issue 38): 512^3 al2o3_60 CG <= 3 s and wall <= 4 s; AlN-60 solve wall <= 8 s
and problem build <= 10 s; time per iteration <= 2x the minimal traffic.

Minimal traffic of one FFT-preconditioned CG iteration, in arrays of N values read or
written: the operator reads g (3) and p and writes q (5), the fused updates and dot
products move 11 (x, r, p, q, z; see ``itr_fft.fused_kernels.TRAFFIC``), the real FFT pair
and the spectral scaling move about 7 (r in, half spectrum out and in twice, the symbol,
z out): 23 N values, as in the earlier version of this script.

Usage::

    python validation/bench_gpu.py [--out DIR] [--budget-s 450] [--reproduce] [--n 512]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import itr_fft  # noqa: E402,F401  (registers the backends)
from itr_fv import Materials, homogenize  # noqa: E402
from itr_fv.discrete.problem import DiscreteProblem  # noqa: E402
from itr_fv.materials.paper_data import PAPER_SYSTEM  # noqa: E402
from itr_fv.rve import FillerSpec, build_rve  # noqa: E402
from itr_fv.rve.spec import RVESpec  # noqa: E402
from itr_fv.solvers.backends import backend_for  # noqa: E402
from itr_fv.solvers.devices import cuda_device_count  # noqa: E402
from validation.gallery import build  # noqa: E402

RESULTS = ROOT / "validation" / "results"
#: Arrays of N values one FFT-preconditioned CG iteration must move (module docstring).
ARRAYS_PER_ITERATION = 23
TOL = 1e-8
TARGETS = {"al2o3_cg_s": 3.0, "al2o3_wall_s": 4.0, "aln_solve_s": 8.0, "aln_build_s": 10.0,
           "traffic_ratio": 2.0}


class Budget:
    """Seconds left of the run; a step that needs more is skipped (and said so)."""

    def __init__(self, seconds: float) -> None:
        self.end = time.perf_counter() + seconds

    def left(self) -> float:
        return self.end - time.perf_counter()

    def allows(self, need_s: float, what: str, log: Callable[[str], None]) -> bool:
        if self.left() >= need_s:
            return True
        log(f"skipped: {what} (needs ~{need_s:.0f} s, {self.left():.0f} s left)")
        return False


def device_facts(on_gpu: bool) -> dict:
    """Name, memory and the measured copy bandwidth (bytes read + written per second)."""
    if not on_gpu:
        src = np.ones(2**27)
        dst = np.empty_like(src)
        t = time.perf_counter()
        for _ in range(5):
            dst[...] = src
        seconds = (time.perf_counter() - t) / 5
        return {"name": f"CPU ({os.cpu_count()} cores, NumPy)", "total_bytes": None,
                "copy_Bps": 2 * src.nbytes / seconds}
    import cupy
    props = cupy.cuda.runtime.getDeviceProperties(cupy.cuda.Device().id)
    free, total = cupy.cuda.runtime.memGetInfo()
    src = cupy.ones(2**27)
    dst = cupy.empty_like(src)
    dst[...] = src
    cupy.cuda.Device().synchronize()
    t = time.perf_counter()
    for _ in range(20):
        dst[...] = src
    cupy.cuda.Device().synchronize()
    seconds = (time.perf_counter() - t) / 20
    name = props["name"].decode() if isinstance(props["name"], bytes) else str(props["name"])
    del src, dst
    return {"name": name, "total_bytes": int(total), "free_bytes": int(free),
            "copy_Bps": 2 * 2**27 * 8 / seconds}


def paths(device: str) -> dict[str, dict]:
    """Backend options of the old and the new path (the new one where its parts exist)."""
    from itr_fft.fused_kernels import fused_available

    old = {"device": device, "kernels": "portable", "preconditioner": "fft"}
    fused = "fused" if device == "cuda" and fused_available() else "portable"
    return {"old": old,
            "new": {"device": device, "kernels": fused, "preconditioner": "fft"},
            "new_mg": {"device": device, "kernels": fused, "preconditioner": "multigrid"}}


def solve(problem: DiscreteProblem, mat: Materials, options: dict, tol: float = TOL) -> dict:
    """Three load cases on one backend: times, iterations, the tensor."""
    backend = backend_for("array_api", **options)
    t = time.perf_counter()
    res = homogenize(problem, mat, solver=backend, tol=tol, store_fields=False,
                     check_memory=False)
    wall = time.perf_counter() - t
    cg = float(sum(res.solve_times))
    its = [int(i) for i in res.iterations]
    return {"wall_s": wall, "cg_s": cg, "iterations": its,
            "s_per_iteration": cg / max(sum(its), 1), "k_eff": res.k_eff.tolist(),
            "converged": bool(res.converged)}


def traffic_s(n_voxels: int, facts: dict) -> float:
    """Seconds the minimal traffic of one iteration takes at the measured bandwidth."""
    return ARRAYS_PER_ITERATION * 8 * n_voxels / facts["copy_Bps"]


def rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def aln_problem(n: int) -> tuple[DiscreteProblem, Materials, float]:
    """AlN-60 in a box of n voxels of 0.125 um (64 um at n = 512): problem and build time."""
    spec = RVESpec(box_um=0.125 * n, voxel_um=0.125, seed=1)
    ms, _ = build_rve(spec, [FillerSpec.from_table1("AlN", 0.60)], 0, matrix="silicone")
    mat = Materials(PAPER_SYSTEM.conductivities(["AlN"]), {("AlN", "silicone"): 3e-8},
                    matrix="silicone", contact="gap")
    t = time.perf_counter()
    problem = DiscreteProblem.for_materials(ms, mat)
    problem.system(mat)
    return problem, mat, time.perf_counter() - t


def run_steps(n: int, device: str, facts: dict, budget: Budget, log) -> dict:
    out: dict = {"n": n, "device": device, "paths": paths(device)}
    ways = out["paths"]
    log(f"paths: old {ways['old']}, new {ways['new']}, new (AlN) {ways['new_mg']}")
    ms, mat = build("al2o3_60", 32, contact="gap")
    warm = DiscreteProblem.for_materials(ms, mat)
    for name, opts in ways.items():
        try:
            solve(warm, mat, opts)
        except Exception as err:  # noqa: BLE001 - a path that cannot run is reported
            log(f"warm-up {name}: {type(err).__name__}: {err}")
    ref = homogenize(warm, mat, solver="itr_fft", tol=1e-12, store_fields=False).k_eff
    small = solve(warm, mat, ways["new"], tol=1e-12)
    out["small_vs_numba"] = rel(small["k_eff"], ref)
    log(f"32^3 al2o3_60 at tol 1e-12: new path vs the numba CPU backend, max relative "
        f"difference {out['small_vs_numba']:.1e} (acceptance: 1e-10)")
    if budget.allows(60, f"al2o3_60 {n}^3", log):
        t = time.perf_counter()
        ms, mat = build("al2o3_60", n, contact="gap")
        problem = DiscreteProblem.for_materials(ms, mat)
        problem.system(mat)
        log(f"al2o3_60 {n}^3: problem built in {time.perf_counter() - t:.1f} s")
        out["al2o3"] = {}
        for name in ("old", "new"):
            r = solve(problem, mat, ways[name])
            r["traffic_ratio"] = r["s_per_iteration"] / traffic_s(n**3, facts)
            out["al2o3"][name] = r
            log(f"  {name}: CG {r['cg_s']:.2f} s, wall {r['wall_s']:.2f} s, iterations "
                f"{r['iterations']}, {1e3 * r['s_per_iteration']:.2f} ms/iteration = "
                f"{r['traffic_ratio']:.1f}x the minimal traffic")
        out["al2o3"]["new_vs_old"] = rel(out["al2o3"]["new"]["k_eff"],
                                         out["al2o3"]["old"]["k_eff"])
        del problem, ms
    if budget.allows(120, f"AlN-60 {n}^3", log):
        problem, mat, build_s = aln_problem(n)
        out["aln"] = {"build_s": build_s}
        log(f"AlN-60 {0.125 * n:g} um / 0.125 um ({n}^3): problem built in {build_s:.1f} s")
        for name in ("old", "new_mg"):
            if not budget.allows(40, f"AlN-60 {name}", log):
                continue
            r = solve(problem, mat, ways[name])
            out["aln"][name] = r
            log(f"  {name}: solve wall {r['wall_s']:.2f} s (CG {r['cg_s']:.2f} s), "
                f"iterations {r['iterations']}, k_xx {r['k_eff'][0][0]:.6g} W/(m K)")
        if "old" in out["aln"] and "new_mg" in out["aln"]:
            out["aln"]["new_vs_old"] = rel(out["aln"]["new_mg"]["k_eff"],
                                           out["aln"]["old"]["k_eff"])
    return out


def reproduce_check(device: str, budget: Budget, log, folder: Path) -> dict | None:
    """``itr reproduce`` (gap only, no leave-one-out) on the CPU and on ``device``."""
    if device != "cuda" or not budget.allows(240, "itr reproduce CPU vs cuda", log):
        return None
    runs = {}
    for dev in ("cpu", "cuda"):
        target = folder / f"reproduce-{dev}"
        t = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "itr_identify.cli", "reproduce",
                               "--parametrisation", "gap", "--no-leave-one-out",
                               "--no-progress", "--device", dev, "--out", str(target)],
                              capture_output=True, text=True)
        runs[dev] = {"rc": proc.returncode, "wall_s": time.perf_counter() - t,
                     "tail": proc.stderr[-400:]}
        log(f"itr reproduce --device {dev}: exit {proc.returncode} in "
            f"{runs[dev]['wall_s']:.0f} s")
        if proc.returncode:
            return runs
    a = json.loads((folder / "reproduce-cpu" / "identified.json").read_text())
    b = json.loads((folder / "reproduce-cuda" / "identified.json").read_text())
    runs["max_relative_difference"] = max_json_difference(a, b)
    log(f"identified.json, cuda vs cpu: max relative difference "
        f"{runs['max_relative_difference']:.1e} (acceptance: 1e-6)")
    return runs


def max_json_difference(a, b) -> float:
    """Largest relative difference between the numbers of two JSON trees (inf where their
    shapes differ; strings and the solver's name are not compared)."""
    if isinstance(a, dict) and isinstance(b, dict):
        keys = set(a) | set(b)
        return max((max_json_difference(a.get(k), b.get(k)) for k in keys
                    if k not in ("solver", "device", "wall_s", "seconds")), default=0.0)
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return math.inf
        return max((max_json_difference(x, y) for x, y in zip(a, b)), default=0.0)
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and \
            not isinstance(a, bool):
        if a == b:
            return 0.0
        return abs(a - b) / max(abs(a), abs(b))
    return 0.0


def table(out: dict, facts: dict) -> list[str]:
    """The acceptance table of issue 38 from the measured figures."""
    on_gpu = out["device"] == "cuda"
    rows = ["| acceptance | target | old path | new path | holds |",
            "| --- | --- | --- | --- | --- |"]

    def row(label, target, old, new, fmt="{:.2f} s"):
        o = fmt.format(old) if old is not None else "-"
        v = fmt.format(new) if new is not None else "-"
        ok = "yes" if new is not None and new <= target else "no"
        rows.append(f"| {label} | <= {fmt.format(target)} | {o} | {v} | "
                    f"{ok if on_gpu else 'GPU unverified'} |")

    al = out.get("al2o3", {})
    n = out["n"]
    row(f"al2o3_60 {n}^3, 3 load cases: CG", TARGETS["al2o3_cg_s"],
        al.get("old", {}).get("cg_s"), al.get("new", {}).get("cg_s"))
    row(f"al2o3_60 {n}^3, 3 load cases: wall", TARGETS["al2o3_wall_s"],
        al.get("old", {}).get("wall_s"), al.get("new", {}).get("wall_s"))
    row("time per iteration / minimal traffic", TARGETS["traffic_ratio"],
        al.get("old", {}).get("traffic_ratio"), al.get("new", {}).get("traffic_ratio"),
        "{:.1f}x")
    aln = out.get("aln", {})
    row(f"AlN-60 {0.125 * n:g} um / 0.125 um: solve wall", TARGETS["aln_solve_s"],
        aln.get("old", {}).get("wall_s"), aln.get("new_mg", {}).get("wall_s"))
    row(f"AlN-60 {0.125 * n:g} um / 0.125 um: problem build", TARGETS["aln_build_s"],
        None, aln.get("build_s"))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(RESULTS), help="folder for bench_gpu.md and .json")
    ap.add_argument("--budget-s", type=float, default=450.0, help="seconds for the run")
    ap.add_argument("--n", type=int, default=None,
                    help="grid edge (default 512 on a GPU, 96 on the CPU)")
    ap.add_argument("--reproduce", action="store_true",
                    help="also compare itr reproduce on the CPU and on the GPU")
    args = ap.parse_args(argv)
    budget = Budget(args.budget_s)
    folder = Path(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    lines: list[str] = []

    def log(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    on_gpu = cuda_device_count() > 0
    device = "cuda" if on_gpu else "cpu"
    if not on_gpu:
        log("no CUDA device: the same steps on the CPU at a small grid (GPU unverified)")
    facts = device_facts(on_gpu)
    log(f"device: {facts['name']}; copy bandwidth {facts['copy_Bps'] / 1e9:.0f} GB/s "
        "(read + write)")
    n = args.n or (512 if on_gpu else 96)
    out = run_steps(n, device, facts, budget, log)
    if args.reproduce:
        out["reproduce"] = reproduce_check(device, budget, log, folder)
    rows = table(out, facts)
    for r in rows:
        log(r)
    machine = (f"Host: {os.cpu_count()} cores, {platform.machine()}, Python "
               f"{platform.python_version()}.")
    text = ["# Issue 38 device check (validation/bench_gpu.py)", "",
            f"Device: {facts['name']}. {machine}", "", *rows, "", "## Log", "",
            *[f"    {line}" for line in lines]]
    (folder / "bench_gpu.md").write_text("\n".join(text) + "\n")
    (folder / "bench_gpu.json").write_text(json.dumps({"facts": facts, "results": out},
                                                      indent=1, default=float))
    log(f"wrote {folder / 'bench_gpu.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
