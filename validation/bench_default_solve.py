"""The default solve against the package at fe0a979 (issue 61, acceptance 2), and where one
iteration's time goes.

Two fixed RVEs at 128^3 (16 um boxes of 0.125 um voxels, Table 1's Al2O3 and AlN at 60 vol%,
packing seed 1, made once by this package and voxelised by each version from the same sphere
table with ``Microstructure.from_spheres``), per-area contacts (R_b of Table 1's pairs,
R_ff = 2e-7 m^2 K/W), solved with the public API at its default arguments,
``homogenize(ms, mat, tol=1e-8)`` with the FFT solver (three load cases: here
``itr_fv.homogenize(ms, mat, solver="fft", tol=1e-8)``, at fe0a979
``itr_fft.homogenize(ms, mat, tol=1e-8)``), by this checkout and by a git
worktree of fe0a979, alternately, each run in a fresh process after a 24^3 warm-up (numba's
compiled kernels come from each version's cache), on the machine's threads. The figure is
the median wall of ``--repeats`` runs per version.

Then the per-operation table of this checkout at the same grid: one operator product with
its dot, one FFT preconditioner application (float64 and float32 FFTs), one multigrid
application, the CG vector updates, each timed over 20 calls, against the iteration's time.

Writes ``validation/results/bench_default_solve.md`` and ``.json``. About 5 min on 2 cores.

Usage::

    python validation/bench_default_solve.py [--repeats 3] [--old fe0a979]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
N = 128
VOXEL_UM = 0.125
#: The RVEs: name -> (filler, R_b filler-matrix, m^2 K/W); R_ff is RFF for both.
RVES = {"Al2O3-60": ("Al2O3", 2.2e-8), "AlN-60": ("AlN", 3e-8)}
RFF = 2e-7


def make_tables(folder: Path, n: int) -> dict[str, Path]:
    """Sphere tables of the two RVEs (npz: centres, radii, materials, box), this package."""
    from itr_fv.rve import FillerSpec, build_rve
    from itr_fv.rve.spec import RVESpec

    out = {}
    for name, (filler, _) in RVES.items():
        spec = RVESpec(box_um=n * VOXEL_UM, voxel_um=VOXEL_UM, seed=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ms, _ = build_rve(spec, [FillerSpec.from_table1(filler, 0.60)], 0,
                              matrix="silicone")
        t = ms.particles
        path = folder / f"{name}.npz"
        np.savez(path, centers_m=t.centers_m, radii_m=t.radii_m,
                 material=np.asarray(t.material, dtype=str), box_m=n * VOXEL_UM * 1e-6)
        out[name] = path
    return out


def materials(name: str):
    """The RVE's materials: Table 1's conductivities, its R_b, R_ff = :data:`RFF`, per-area
    contacts (public API of both versions)."""
    from itr_fv import Materials
    from itr_fv.materials.paper_data import PAPER_SYSTEM

    filler, r_b = RVES[name]
    return Materials(PAPER_SYSTEM.conductivities([filler]),
                     {(filler, "silicone"): r_b, (filler, filler): RFF}, matrix="silicone",
                     contact="area")


def voxelised(table: Path, n: int):
    """The sphere table voxelised on n^3 by the running version's ``from_spheres``."""
    from itr_fv import Microstructure

    with np.load(table, allow_pickle=False) as z:
        return Microstructure.from_spheres(z["centers_m"], z["radii_m"],
                                           [str(m) for m in z["material"]],
                                           float(z["box_m"]), n, matrix="silicone")


def child(table: Path, name: str, n: int, fft: str | None = None) -> dict:
    """In a fresh process of one version: voxelise, warm up, time the default solve (with
    ``fft`` where given: this checkout's optional FFT pair). The same backend in both
    versions: here the one door with the ``"fft"`` solver, at fe0a979 (no
    ``itr_fv.resolve_solver`` yet) ``itr_fft.homogenize``."""
    extra = {} if fft is None else {"fft": fft}
    try:
        from itr_fv import homogenize, resolve_solver
    except ImportError:  # the baseline checkout
        import itr_fft

        def solve(ms):
            return itr_fft.homogenize(ms, mat, tol=1e-8, **extra)
    else:
        fft_solver = resolve_solver("fft", **extra)

        def solve(ms):
            return homogenize(ms, mat, solver=fft_solver, tol=1e-8)

    mat = materials(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        solve(voxelised(table, 24))
        ms = voxelised(table, n)
        t = time.perf_counter()
        res = solve(ms)
        wall = time.perf_counter() - t
    return {"wall_s": wall, "iterations": [int(i) for i in res.iterations],
            "k_eff": np.asarray(res.k_eff).tolist(),
            "preconditioner": res.info.get("preconditioner"),
            "workers": res.info.get("workers")}


def run_child(root: Path, table: Path, name: str, n: int, fft: str | None = None) -> dict:
    env = {**os.environ, "PYTHONPATH": str(root)}
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child",
                           str(table), name, str(n), *([fft] if fft else [])], cwd=root, env=env, capture_output=True,
                          text=True, check=False, timeout=900)
    if proc.returncode:
        raise RuntimeError(f"{root} {name}: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def per_operation(table: Path, name: str, n: int, calls: int = 20) -> dict:
    """Seconds per call of each operation of one CG iteration, this checkout."""
    from itr_fft.numba_backend import NumbaFFTBackend
    from itr_fv.discrete.problem import DiscreteProblem

    mat, ms = materials(name), voxelised(table, n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        system = DiscreteProblem.for_materials(ms, mat).system(mat)
    rng = np.random.default_rng(0)
    x, r = (rng.standard_normal(ms.shape) for _ in range(2))
    out = np.empty_like(x)
    out_row: dict = {}

    def timed(label, fn):
        fn()
        t = time.perf_counter()
        for _ in range(calls):
            fn()
        out_row[label] = (time.perf_counter() - t) / calls

    from itr_fft.fft_pair import fftw_available

    ways = [("fft", np.float64, "scipy"), ("fft", np.float32, "scipy")]
    if fftw_available():
        ways.append(("fft", np.float32, "fftw"))
    ways.append(("multigrid", np.float64, "scipy"))
    for pre, fft_dtype, fft in ways:
        prepared = NumbaFFTBackend(preconditioner=pre, fft_dtype=fft_dtype,
                                   fft=fft).prepare(system, VOXEL_UM * 1e-6)
        try:
            if pre == "fft" and fft_dtype == np.float64:
                op, ops = prepared.operator, prepared.ops
                p, q, rr = x.copy(), np.empty_like(x), r.copy()
                timed("operator product and its dot",
                      lambda op=op: op.apply_dot(x, out))
                timed("CG update (x, r and r.r)",
                      lambda ops=ops: ops.update(p, rr, x, out, 1e-12))
                timed("CG direction", lambda ops=ops: ops.direction(q, x, 0.5))
                timed("dot", lambda ops=ops: ops.dot(x, r))
            label = (f"FFT preconditioner ({np.dtype(fft_dtype).name} FFTs, {fft})"
                     if pre == "fft" else "multigrid preconditioner (V-cycle + deflation)")
            timed(label, lambda pre=prepared.preconditioner: pre.apply_dot(r))
        finally:
            prepared.close()
    return out_row


def markdown(res: dict) -> str:
    lines = [f"# The default solve at {res['n']}^3 against the package at {res['old']}", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             f"Machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}.", "",
             "| RVE | version | wall (s), median | walls (s) | iterations | preconditioner | "
             "speed-up |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, rows in res["solves"].items():
        old = statistics.median(r["wall_s"] for r in rows["old"])
        for version in rows:
            walls = [r["wall_s"] for r in rows[version]]
            med = statistics.median(walls)
            label = res["old"] if version == "old" else version.replace("new", "this checkout")
            lines.append(f"| {name} | {label} | "
                         f"{med:.2f} | {', '.join(f'{w:.2f}' for w in walls)} | "
                         f"{'/'.join(map(str, rows[version][0]['iterations']))} | "
                         f"{rows[version][0]['preconditioner']} | {old / med:.2f}x |")
    lines += ["", "Largest relative difference of the tensors, this checkout against "
              f"{res['old']}: " + ", ".join(f"{k} {v:.1e}" for k, v in res["k_diff"].items()),
              "", f"## One iteration's operations (this checkout, {res['n']}^3, ms per call)", "",
              "| RVE | " + " | ".join(next(iter(res["operations"].values()))) + " |",
              "| --- |" + " --- |" * len(next(iter(res["operations"].values())))]
    for name, ops in res["operations"].items():
        lines.append(f"| {name} | " + " | ".join(f"{1e3 * v:.1f}" for v in ops.values()) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--old", default="fe0a979")
    ap.add_argument("--n", type=int, default=N, help="grid edge (default 128)")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=ROOT / "validation" / "results"
                    / "bench_default_solve.md")
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(Path(args.child[0]), args.child[1], int(args.child[2]),
                               args.child[3] if len(args.child) > 3 else None)))
        return 0
    sys.path.insert(0, str(ROOT))
    from itr_fft.fft_pair import fftw_available

    res: dict = {"old": args.old, "n": args.n, "solves": {}, "k_diff": {}, "operations": {}}
    with tempfile.TemporaryDirectory() as tmp:
        old_root = Path(tmp) / "old"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old_root),
                        args.old], check=True, capture_output=True)
        try:
            tables = make_tables(Path(tmp), args.n)
            for name, table in tables.items():
                rows: dict = {"old": [], "new": []}
                versions = [("old", old_root, None), ("new", ROOT, None)]
                if fftw_available():
                    rows["new, fft='fftw'"] = []
                    versions.append(("new, fft='fftw'", ROOT, "fftw"))
                for rep in range(args.repeats):
                    for version, root, fft in versions:
                        r = run_child(root, table, name, args.n, fft)
                        rows[version].append(r)
                        print(f"{name} {version} run {rep + 1}: {r['wall_s']:.2f} s, "
                              f"iterations {r['iterations']}, {r['preconditioner']}",
                              flush=True)
                res["solves"][name] = rows
                a, b = (np.asarray(rows[v][0]["k_eff"]) for v in ("new", "old"))
                res["k_diff"][name] = float(np.max(np.abs(a - b)) / np.max(np.abs(b)))
                res["operations"][name] = per_operation(table, name, args.n)
                print(f"{name} operations (ms): "
                      f"{ {k: round(1e3 * v, 1) for k, v in res['operations'][name].items()} }",
                      flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(old_root)], check=False, capture_output=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    for path, text in ((args.out, markdown(res)),
                       (args.out.with_suffix(".json"), json.dumps(res, indent=1))):
        tmp_path = path.with_name(path.name + ".tmp")
        tmp_path.write_text(text, encoding="utf-8")
        tmp_path.replace(path)
    print(markdown(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
