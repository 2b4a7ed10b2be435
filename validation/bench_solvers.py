"""Benchmark: itr_fv (sparse + pyamg CG) vs itr_fft (FFT-preconditioned CG, numba).

The RVE is ``al2o3_60`` of the common set (dense 60 % Al2O3 in silicone, k_p/k_m = 167,
R_fp = R_ff = 1e-7 m^2 K/W), the same particles voxelized at every grid size. Each
(solver, grid) runs in a fresh subprocess (so ``ru_maxrss`` is that case's peak memory);
three load cases, tol 1e-8, ``store_fields=False``. Also measured: iterations vs grid for
fixed spheres, the preconditioner's reference conductivity, warm starts, float32 and a
profile of one FFT load case. Writes ``validation/results/bench_solvers.md``.

With ``--baseline CHECKOUT`` every case also runs on another checkout of the package (its
own ``validation/bench_solvers.py --one``), alternating old and new ``--repeat`` times on
the same machine, and the report gets a before/after table (minimum wall time of the
repeats, and nanoseconds per voxel and CG iteration).

Usage::

    python validation/bench_solvers.py [--fv 64,96,128] [--fft 64,96,128,192,256]
    python validation/bench_solvers.py --one itr_fft 128     # one case, prints JSON
    python validation/bench_solvers.py --baseline /tmp/old --fft 64,128 --fv 64 \
        --fft32 "" --scipy 64 --repeat 3 --no-studies --out validation/results/backends.md
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import platform
import pstats
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TOL = 1e-8
CASE = "al2o3_60"
LOAD_AT_START = float("nan")


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def one(solver: str, n: int, dtype: str = "float64") -> dict:
    """Solve CASE at n^3 with ``solver``; returns times, iterations, peak RSS (MB)."""
    from itr_fv import homogenize, resolve_solver
    from validation.gallery import build
    t = time.perf_counter()
    ms, mat = build(CASE, n)
    t_build = time.perf_counter() - t
    rss_build = _rss_mb()
    if solver == "itr_fft":
        import itr_fft

        # compile/load the kernels outside the timing (cache=True makes this a load)
        from validation.gallery import build as _b
        ms8, mat8 = _b(CASE, 16)
        fft = resolve_solver("fft", dtype=np.dtype(dtype).type)
        homogenize(ms8, mat8, solver=fft, tol=1e-6, store_fields=False)
        rss_build = max(rss_build, _rss_mb())
        # float32 vectors cannot reach 1e-8: their residual floor grows like n^2
        tol = TOL if dtype == "float64" else itr_fft.float32_min_tol(ms.shape)
        res = homogenize(ms, mat, solver=fft, tol=tol, store_fields=False)
    elif solver == "scipy_fft":
        res = homogenize(ms, mat, solver="scipy_fft", tol=TOL, store_fields=False)
    else:
        res = homogenize(ms, mat, solver="fv", tol=TOL, store_fields=False)
    return dict(solver=solver, n=n, dtype=dtype, wall=res.wall_time, setup=res.setup_time,
                solve=res.solve_times, iterations=res.iterations, k=np.diag(res.k_eff).tolist(),
                rss_mb=_rss_mb(), rss_before_mb=rss_build, build_s=t_build,
                converged=res.converged, tol=res.tol)


def run_sub(solver: str, n: int, dtype: str = "float64", timeout: float = 1800,
            root: Path = ROOT) -> dict:
    """One case in a fresh interpreter, with the package of checkout ``root``."""
    script = root / "validation" / "bench_solvers.py"
    cmd = [sys.executable, str(script), "--one", solver, str(n), "--dtype", dtype]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=root)
    except subprocess.TimeoutExpired:
        return dict(solver=solver, n=n, dtype=dtype, error=f"timeout {timeout:.0f} s")
    if out.returncode != 0:
        return dict(solver=solver, n=n, dtype=dtype, error=out.stderr.strip()[-300:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def studies(n_grid: tuple[int, int] = (64, 128)) -> dict:
    """Iterations vs grid, reference conductivity, warm start, profile (in this process)."""
    import itr_fv
    from itr_fv import homogenize, resolve_solver
    from validation.gallery import build, sphere_array
    out: dict = {}
    # iterations vs grid for fixed spheres (FCC f = 0.5 and the dense RVE)
    grid = []
    for label, maker in (("fcc f=0.5 R=1e-7", lambda n: sphere_array("fcc", n, 0.5, 1e-7)),
                         ("fcc f=0.5 R=5e-5", lambda n: sphere_array("fcc", n, 0.5, 5e-5)),
                         (CASE, lambda n: build(CASE, n))):
        its = []
        for n in n_grid:
            ms, mat = maker(n)
            its.append(homogenize(ms, mat, solver="fft", tol=TOL, directions=(0,),
                                  store_fields=False).iterations[0])
        grid.append((label, its))
    out["grid"] = grid
    # reference conductivity of the preconditioner
    ms, mat = build(CASE, 64)
    refs = []
    for ref in ("min", "harmonic", "geometric", "arithmetic", "max"):
        r = homogenize(ms, mat, solver=resolve_solver("fft", reference=ref), tol=TOL,
                       directions=(0,), store_fields=False)
        refs.append((ref, r.info["g_ref"], r.iterations[0]))
    out["reference"] = refs
    # warm start: one step of Table 4 for both resistances
    geom = itr_fv.discrete.model.face_geometry(ms, contact=mat.contact)
    pairs = [("Al2O3", "silicone"), ("Al2O3", "Al2O3")]
    warm = []
    for r1, r2 in ((1e-7, 5e-7), (5e-7, 1e-6), (1e-6, 5e-6)):
        m1 = mat.with_values(resistance={p: r1 for p in pairs})
        m2 = mat.with_values(resistance={p: r2 for p in pairs})
        first = homogenize(ms, m1, solver="fft", tol=TOL, geometry=geom)
        cold = homogenize(ms, m2, solver="fft", tol=TOL, geometry=geom, store_fields=False)
        w = homogenize(ms, m2, solver="fft", tol=TOL, geometry=geom, x0=first.theta,
                       store_fields=False)
        warm.append((r1, r2, sum(cold.iterations), sum(w.iterations),
                     float(w.residual_history[0][0])))
    out["warm"] = warm
    from itr_fv.solvers.warm_start import galerkin_start
    target = mat.with_values(resistance={p: 5e-7 for p in pairs})
    snaps = {r: homogenize(ms, mat.with_values(resistance={p: r for p in pairs}), solver="fft",
                           tol=TOL, geometry=geom, directions=(0,)).theta
             for r in (1e-8, 5e-8, 1e-7, 1e-6)}
    gal = [("none (cold)", homogenize(ms, target, solver="fft", tol=TOL, geometry=geom,
                                      directions=(0,)).iterations[0], 1.0)]
    for keys in ((1e-7,), (1e-7, 1e-6), (1e-8, 5e-8, 1e-7, 1e-6)):
        x0 = galerkin_start(geom, target, [snaps[k] for k in keys], directions=(0,))
        r = homogenize(ms, target, solver="fft", tol=TOL, geometry=geom, directions=(0,),
                       x0=x0)
        gal.append((", ".join(f"{k:g}" for k in keys), r.iterations[0],
                    float(r.residual_history[0][0])))
    out["galerkin"] = gal
    # float32 vs float64
    r64 = homogenize(ms, mat, solver="fft", tol=1e-10, store_fields=False)
    r32 = homogenize(ms, mat, solver=resolve_solver("fft", dtype=np.float32), tol=2e-6,
                     store_fields=False)
    out["float32"] = dict(diff=float(np.abs(r32.k_eff - r64.k_eff).max()
                                     / np.abs(r64.k_eff).max()),
                          it32=r32.iterations, t32=r32.wall_time, t64=r64.wall_time)
    # profile one load case at 128^3
    ms, mat = build(CASE, 128)
    prof = cProfile.Profile()
    prof.enable()
    homogenize(ms, mat, solver="fft", tol=TOL, directions=(0,), store_fields=False)
    prof.disable()
    s = io.StringIO()
    pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(12)
    out["profile"] = s.getvalue()
    return out


def write_report(rows: list[dict], st: dict, path: Path) -> None:
    lines = [
        "# Solver benchmark: itr_fv vs itr_fft",
        "",
        "Generated by `python validation/bench_solvers.py`. RVE `al2o3_60` of the common set "
        "(dense 60 % Al2O3, k_p/k_m = 30/0.18 = 167, R_fp = R_ff = 1e-7 m^2 K/W, 16 um box, the "
        "same particles at every grid), 3 load cases, tol = 1e-8, `store_fields=False`. "
        "Each row is a fresh subprocess; peak RSS = `ru_maxrss` of that process (includes "
        "Python + numpy/scipy/numba, ~150-250 MB). Wall time = set-up + 3 solves (excludes "
        "building the RVE and, for FFT, loading the cached numba kernels).",
        f"Machine: {os.cpu_count()} cores, {platform.machine()}; load average when the run "
        f"started: {LOAD_AT_START:.1f}. The FFT preconditioner runs its FFTs in float32 "
        "(`fft_dtype`, default) while CG, operator and residual stay in `dtype`.",
        "",
        "| solver | grid | dtype | tol | wall (s) | set-up (s) | iterations | peak RSS (MB) | "
        "k_xx (W/mK) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['solver']} | {r['n']}^3 | {r['dtype']} | - | - | - | - | - | "
                         f"{r['error'][:80]} |")
            continue
        lines.append(f"| {r['solver']} | {r['n']}^3 | {r['dtype']} | {r.get('tol', TOL):.1e} | "
                     f"{r['wall']:.1f} | "
                     f"{r['setup']:.1f} | {'/'.join(map(str, r['iterations']))} | "
                     f"{r['rss_mb']:.0f} | {r['k'][0]:.6f} |")
    by = {(r["solver"], r["n"], r["dtype"]): r for r in rows if "error" not in r}
    lines += ["", "Speed-up FV/FFT (wall):", ""]
    for n in sorted({r["n"] for r in rows}):
        a, b = by.get(("itr_fv", n, "float64")), by.get(("itr_fft", n, "float64"))
        if a and b:
            lines.append(f"- {n}^3: {a['wall'] / b['wall']:.1f}x")
    for r in rows:
        ref = by.get(("itr_fft", r["n"], "float64"))
        if "error" not in r and r["dtype"] == "float32" and ref:
            d = max(abs(a / b - 1.0) for a, b in zip(r["k"], ref["k"]))
            lines.append(f"- float32 at {r['n']}^3 (tol {r['tol']:.1e}): diagonal within "
                         f"{d:.1e} of float64; wall {r['wall']:.1f} s vs {ref['wall']:.1f} s; "
                         f"peak RSS {r['rss_mb']:.0f} MB vs {ref['rss_mb']:.0f} MB")
    fft = sorted((r["n"], r["rss_mb"], r["wall"]) for r in rows
                 if "error" not in r and r["solver"] == "itr_fft" and r["dtype"] == "float64")
    if len(fft) >= 2:
        n1, m1, _ = fft[-2]
        n2, m2, _ = fft[-1]
        slope = (m2 - m1) / (n2 ** 3 - n1 ** 3)
        est = m2 + slope * (400 ** 3 - n2 ** 3)
        lines += ["", f"Memory scaling (FFT, float64): {slope * 1e6:.1f} MB per million voxels "
                  f"(from {n1}^3 and {n2}^3) -> 400^3 estimate {est / 1024:.1f} GB peak RSS."]
    if st:
        lines += ["", "## Iterations vs grid (FFT, load e1, tol 1e-8)", "",
                  "| microstructure | iterations at 64^3 / 128^3 |", "| --- | --- |"]
        lines += [f"| {lab} | {' / '.join(map(str, its))} |" for lab, its in st["grid"]]
        lines += ["", "## Reference conductivity of the preconditioner (64^3, load e1)", "",
                  "| choice | g_ref (W/(m^2 K)) | iterations |", "| --- | --- | --- |"]
        lines += [f"| {a} | {b:.4g} | {c} |" for a, b, c in st["reference"]]
        lines += ["", "PCG is invariant to a constant scale of the preconditioner, so the "
                  "choice only changes rounding (identical counts expected).", "",
                  "## Warm start (64^3, both resistances one Table 4 step, 3 load cases)", "",
                  "| R from | R to | cold iterations | warm iterations | initial rel. residual "
                  "|", "| --- | --- | --- | --- | --- |"]
        lines += [f"| {a:g} | {b:g} | {c} | {d} | {e:.2e} |" for a, b, c, d, e in st["warm"]]
        g = st["galerkin"]
        lines += ["", "Energy-optimal start from several solved fields "
                  "(`itr_fv.solvers.warm_start.galerkin_start`, load e1, target R = 5e-7 for both "
                  "resistances):", "",
                  "| snapshots (R) | iterations | initial rel. residual |", "| --- | --- | --- |"]
        lines += [f"| {a} | {b} | {c:.2e} |" for a, b, c in g]
        f = st["float32"]
        lines += ["", "## float32", "",
                  f"64^3, tol 2e-6 in float32 vs tol 1e-10 in float64: max |dK| / max |K| = "
                  f"{f['diff']:.1e}; iterations {f['it32']}; wall {f['t32']:.1f} s vs "
                  f"{f['t64']:.1f} s (float64 at tol 1e-10).", "",
                  "## Profile: one load case, FFT, 128^3 (cProfile, tottime)", "", "```",
                  st["profile"].strip(), "```"]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def write_comparison(pairs: list[tuple[dict, dict]], baseline: str, path: Path) -> None:
    """Before/after table: the minimum wall time over the repeats, per checkout."""
    lines = ["", "## Before / after (same machine, same run, alternating)", "",
             f"Baseline: `{baseline}`. Minimum over the repeats of the wall time (set-up + "
             "3 load cases); ns/(voxel iteration) = solve time / (voxels x iterations).", "",
             "| solver | grid | iterations old / new | wall old (s) | wall new (s) | new / old | "
             "ns per voxel-iteration old / new |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for old, new in pairs:
        if "error" in old or "error" in new:
            lines.append(f"| {new['solver']} | {new['n']}^3 | - | - | - | - | "
                         f"{(old.get('error') or new.get('error'))[:60]} |")
            continue
        vox = new["n"] ** 3

        def per(r):
            return 1e9 * sum(r["solve"]) / (vox * max(sum(r["iterations"]), 1))
        lines.append(f"| {new['solver']} | {new['n']}^3 | {sum(old['iterations'])} / "
                     f"{sum(new['iterations'])} | {old['wall']:.2f} | {new['wall']:.2f} | "
                     f"{new['wall'] / old['wall']:.3f} | {per(old):.1f} / {per(new):.1f} |")
    with path.open("a") as fh:
        fh.write("\n".join(lines) + "\n")


def _best(runs: list[dict]) -> dict:
    ok = [r for r in runs if "error" not in r]
    return min(ok, key=lambda r: r["wall"]) if ok else runs[-1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--one", nargs=2, metavar=("SOLVER", "N"))
    ap.add_argument("--dtype", default="float64")
    ap.add_argument("--fv", default="64,96,128")
    ap.add_argument("--fft", default="64,96,128,192,256")
    ap.add_argument("--fft32", default="256")
    ap.add_argument("--scipy", default="", help="grids for the plain scipy FFT backend")
    ap.add_argument("--baseline", default=None,
                    help="another checkout to time side by side (before/after table)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per case (minimum kept)")
    ap.add_argument("--no-studies", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "validation" / "results" / "bench_solvers.md"))
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(args.one[0], int(args.one[1]), args.dtype)))
        return 0
    global LOAD_AT_START
    LOAD_AT_START = os.getloadavg()[0]
    rows = []
    plan = [("itr_fft", int(n), "float64") for n in args.fft.split(",") if n]
    plan += [("itr_fft", int(n), "float32") for n in args.fft32.split(",") if n]
    plan += [("itr_fv", int(n), "float64") for n in args.fv.split(",") if n]
    plan += [("scipy_fft", int(n), "float64") for n in args.scipy.split(",") if n]
    pairs = []
    for solver, n, dt in plan:
        new_runs, old_runs = [], []
        for _ in range(max(args.repeat, 1)):
            if args.baseline and solver != "scipy_fft":
                old_runs.append(run_sub(solver, n, dt, root=Path(args.baseline).resolve()))
            new_runs.append(run_sub(solver, n, dt))
        r = _best(new_runs)
        rows.append(r)
        print(json.dumps(r), flush=True)
        if old_runs:
            pairs.append((_best(old_runs), r))
            print("baseline:", json.dumps(pairs[-1][0]), flush=True)
        write_report(rows, {}, Path(args.out))
    st = {} if args.no_studies else studies()
    write_report(rows, st, Path(args.out))
    if pairs:
        write_comparison(pairs, args.baseline, Path(args.out))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
