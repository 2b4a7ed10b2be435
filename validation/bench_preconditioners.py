"""Benchmark: the FFT preconditioner against the particle-deflated multigrid (issue 27).

Two parts, one run, one machine, old and new side by side:

1. Iterations (tol 1e-8, load case e1) of ``itr_fft`` with ``preconditioner="fft"`` and
   ``"multigrid"`` on four RVEs at several grids, the same particles at every grid:
   ``al2o3_60`` and ``aln_60`` and ``hybrid_30_30`` of the common set under the gap
   model (contrast 167, ~1100, both), and the peer RVE (30 % RSA spheres, contrast 167,
   perfect interfaces, 16 um box).
2. Wall time: the faithful AlN-60 RVE (40 um box at 0.16 um = 250^3, gap model,
   R_AlN-silicone = 3e-8 m^2 K/W, three load cases) with both preconditioners, and the
   128^3 peer RVE (one load case) with both and with the plain NumPy/SciPy FFT-PCG
   (``scipy_fft``, the same system and preconditioner in array expressions).

Numba kernels are compiled (and cached) before any timing. Writes
``validation/results/bench_preconditioners.md`` and ``.json``.

Usage::

    python validation/bench_preconditioners.py [--sizes 64,128,256] [--faithful 250]
    python validation/bench_preconditioners.py --sizes 32,48 --faithful 0   # quick
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import itr_fft  # noqa: E402
from itr_fv import homogenize  # noqa: E402
from itr_fv.discrete.problem import DiscreteProblem  # noqa: E402
from validation.gallery import build, random_rve  # noqa: E402

TOL = 1e-8
RESULTS = ROOT / "validation" / "results"
PRECONDITIONERS = ("fft", "multigrid")


def peer(n: int):
    """30 % Al2O3 spheres (RSA) in silicone, contrast 167, perfect interfaces, 16 um box."""
    pair = ("Al2O3", "silicone")
    return random_rve(n, {"Al2O3": 0.30}, 16.0, 11, {pair: 0.0, ("Al2O3", "Al2O3"): 0.0},
                      dense=False)


def faithful_aln(n: int):
    """Dense 60 % AlN, 40 um box (250^3 = 0.16 um voxels), gap model, paper-level R."""
    ms, mat = random_rve(n, {"AlN": 0.60}, 40.0, 31,
                         {("AlN", "silicone"): 3e-8, ("AlN", "AlN"): 1e-7}, dense=True)
    from validation.gallery import with_contact
    return ms, with_contact(mat, "gap")


def rve(name: str, n: int):
    if name == "peer":
        return peer(n)
    return build(name, n, contact="gap")


def _solve(problem, mat, backend, directions=(0,)) -> dict:
    t = time.perf_counter()
    res = homogenize(problem, mat, solver=backend, tol=TOL, directions=directions,
                     store_fields=False, check_memory=False)
    wall = time.perf_counter() - t
    its = list(res.iterations)
    solve = sum(res.solve_times)
    return {"iterations": its, "wall_s": wall, "setup_s": res.setup_time, "solve_s": solve,
            "ms_per_iteration": 1e3 * solve / max(sum(its), 1),
            "k_xx": float(res.k_eff[directions[0], directions[0]]),
            "residual": float(max(res.residuals))}


def warm_up() -> None:
    ms, mat = build("aln_60", 16, contact="gap")
    for pre in PRECONDITIONERS:
        homogenize(ms, mat, solver=itr_fft.NumbaFFTBackend(preconditioner=pre), tol=1e-4,
                   store_fields=False)


def iteration_table(sizes: list[int]) -> list[dict]:
    rows = []
    for name in ("al2o3_60", "aln_60", "hybrid_30_30", "peer"):
        for n in sizes:
            ms, mat = rve(name, n)
            problem = DiscreteProblem.for_materials(ms, mat)
            row = {"rve": name, "n": n}
            for pre in PRECONDITIONERS:
                row[pre] = _solve(problem, mat, itr_fft.NumbaFFTBackend(preconditioner=pre))
            row["dk"] = abs(row["multigrid"]["k_xx"] - row["fft"]["k_xx"]) / abs(
                row["fft"]["k_xx"])
            print(f"{name:13s} {n}^3  fft {row['fft']['iterations'][0]:4d} it "
                  f"{row['fft']['solve_s']:7.2f} s | multigrid "
                  f"{row['multigrid']['iterations'][0]:4d} it "
                  f"{row['multigrid']['solve_s']:7.2f} s | dk {row['dk']:.1e}", flush=True)
            rows.append(row)
            del problem, ms
    return rows


def wall_times(faithful: int, peer_n: int) -> dict:
    out = {}
    if faithful:
        ms, mat = faithful_aln(faithful)
        problem = DiscreteProblem.for_materials(ms, mat)
        out["faithful"] = {"n": faithful, "particles": int(ms.particle_ids.max())}
        for pre in PRECONDITIONERS:
            out["faithful"][pre] = _solve(problem, mat,
                                          itr_fft.NumbaFFTBackend(preconditioner=pre),
                                          directions=(0, 1, 2))
            print(f"faithful AlN-60 {faithful}^3 {pre}: "
                  f"{out['faithful'][pre]['iterations']} it "
                  f"{out['faithful'][pre]['wall_s']:.1f} s", flush=True)
        del problem, ms
    if peer_n:
        ms, mat = peer(peer_n)
        problem = DiscreteProblem.for_materials(ms, mat)
        out["peer"] = {"n": peer_n}
        for label, backend in (("scipy_fft", itr_fft.ScipyFFTBackend()),
                               ("fft", itr_fft.NumbaFFTBackend()),
                               ("multigrid", itr_fft.NumbaFFTBackend(preconditioner="multigrid"))):
            out["peer"][label] = _solve(problem, mat, backend)
            print(f"peer {peer_n}^3 {label}: {out['peer'][label]['iterations']} it "
                  f"{out['peer'][label]['wall_s']:.2f} s", flush=True)
    return out


def write_report(rows: list[dict], walls: dict, path: Path, machine: str) -> None:
    lines = [
        "# Preconditioners of itr_fft: FFT Laplacian vs particle-deflated multigrid",
        "",
        "Generated by `python validation/bench_preconditioners.py`. "
        f"tol = {TOL:g} (relative residual, checked on the true residual). {machine}",
        "",
        "- `fft`: the exact inverse of the constant-coefficient periodic Laplacian (one "
        "real-FFT pair per iteration, FFTs in float32), the preconditioner until now.",
        "- `multigrid`: one constant per particle deflated exactly (`itr_fft.deflation`) "
        "around an aggregation-multigrid V-cycle (`itr_fft.multigrid`: 2 x 2 x 2 aggregates "
        "that stop at resistive interfaces, Galerkin coarse operators, 2 + 2 Jacobi sweeps, "
        "over-correction 1.6, float32).",
        "- Every solve is the same discrete system; `dk` is the relative difference of k_xx "
        "between the two (both at tol 1e-8).",
        "",
    ]
    if rows:
        sizes = sorted({r["n"] for r in rows})
        lines += ["## 1. Iterations (load case e1)", "",
                  "| RVE | " + " | ".join(f"{n}^3 fft / multigrid" for n in sizes) + " |",
                  "| --- |" + " --- |" * len(sizes)]
        for name in dict.fromkeys(r["rve"] for r in rows):
            cells = []
            for n in sizes:
                r = next((x for x in rows if x["rve"] == name and x["n"] == n), None)
                cells.append("-" if r is None else
                             f"{r['fft']['iterations'][0]} / **{r['multigrid']['iterations'][0]}**")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines += ["", "Solve time of that load case (s) and time per iteration (ms):", "",
                  "| RVE | grid | fft (s) | multigrid (s) | speed-up | fft ms/it | "
                  "multigrid ms/it | dk |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for r in rows:
            f, m = r["fft"], r["multigrid"]
            lines.append(f"| {r['rve']} | {r['n']}^3 | {f['solve_s']:.2f} | {m['solve_s']:.2f} | "
                         f"{f['solve_s'] / m['solve_s']:.2f}x | {f['ms_per_iteration']:.0f} | "
                         f"{m['ms_per_iteration']:.0f} | {r['dk']:.1e} |")
        lines.append("")
    if "faithful" in walls:
        w = walls["faithful"]
        f, m = w["fft"], w["multigrid"]
        lines += ["## 2. Wall time, faithful AlN-60 (three load cases)", "",
                  f"{w['n']}^3 voxels (40 um box, 0.16 um), {w['particles']} particles, gap "
                  "model, R = 3e-8 m^2 K/W; wall = set-up (geometry, conductances, "
                  "hierarchy) + three solves.", "",
                  "| preconditioner | iterations | set-up (s) | solves (s) | wall (s) | k_xx |",
                  "| --- | --- | --- | --- | --- | --- |",
                  f"| fft | {'/'.join(map(str, f['iterations']))} | {f['setup_s']:.1f} | "
                  f"{f['solve_s']:.1f} | {f['wall_s']:.1f} | {f['k_xx']:.6g} |",
                  f"| multigrid | {'/'.join(map(str, m['iterations']))} | {m['setup_s']:.1f} | "
                  f"{m['solve_s']:.1f} | {m['wall_s']:.1f} | {m['k_xx']:.6g} |", "",
                  f"Speed-up of the wall time: **{f['wall_s'] / m['wall_s']:.2f}x** "
                  f"(solves alone {f['solve_s'] / m['solve_s']:.2f}x).", ""]
    if "peer" in walls:
        w = walls["peer"]
        lines += [f"## 3. Wall time, the {w['n']}^3 peer RVE (one load case)", "",
                  "| solver | iterations | wall (s) | vs plain SciPy FFT-PCG |",
                  "| --- | --- | --- | --- |"]
        base = w["scipy_fft"]["wall_s"]
        for label in ("scipy_fft", "fft", "multigrid"):
            x = w[label]
            lines.append(f"| {label} | {x['iterations'][0]} | {x['wall_s']:.2f} | "
                         f"{base / x['wall_s']:.1f}x |")
        lines += ["", "Published figures on a 128^3 peer problem, quoted from issue 27 (not "
                  "measured here, other machines): TauFactor 12.2 s, pumapy 62-72 s.", ""]
    path.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="64,128,256")
    ap.add_argument("--faithful", type=int, default=250,
                    help="voxels per edge of the faithful AlN-60 RVE (0 skips)")
    ap.add_argument("--peer", type=int, default=128, help="peer RVE grid (0 skips)")
    ap.add_argument("--out", default=str(RESULTS / "bench_preconditioners.md"))
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",") if s]
    load = os.getloadavg()[0]
    machine = (f"Machine: {os.cpu_count()} cores, {platform.machine()}, Python "
               f"{platform.python_version()}; load average at start {load:.1f}.")
    warm_up()
    walls = wall_times(args.faithful, args.peer)
    rows = iteration_table(sizes)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_report(rows, walls, out, machine)
    out.with_suffix(".json").write_text(json.dumps({"rows": rows, "walls": walls,
                                                    "machine": machine}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
