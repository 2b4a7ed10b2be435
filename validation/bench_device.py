"""Device check of issue 61: every GPU row of its table in one command, within 8 minutes.

Runs on the device machine's own packages as installed (no aliases, no patches): where the
fused kernels do not build there, the run says why (:func:`itr_fft.fused_kernels.
fused_failure`) and measures what a user then gets (``kernels="auto"``: the portable
kernels). Prints each row as it is measured and writes ``bench_device.md`` and ``.json``
under ``--out`` after every row (a run cut short keeps what it measured).

Rows, in this order (each timed against the budget, ``--budget-s``, default 420 s; a step
that would not fit is skipped and said so):

1. the stack: Python, NumPy, numba, numba-cuda, CuPy, the driver, the device and its copy
   bandwidth; whether the fused kernels run, else why not;
2. the small grids (``al2o3_60`` at 48^3 and 96^3) on the device and on the CPU's default
   solver, each against the cost model that sends small grids to the CPU
   (:meth:`itr_fv.solvers.choice.Solver.for_grid`); then ``al2o3_60`` of the common RVE set at 512^3 (gap model), three load cases, tol 1e-8, the
   array-API backend as ``auto`` takes it (``kernels="auto"``) and with the portable
   kernels: CG (sum of the load cases' solve times), wall, iterations, ms per iteration;
3. AlN-60 in a 64 um box at 0.125 um (512^3, Table 1's AlN, R = 3e-8 m^2 K/W, gap model):
   the problem build, then the solve as ``auto`` takes it (FFT preconditioner) and with the
   portable kernels;
4. ``itr identify`` on the ZnO example with ``--device cuda``;
5. ``itr reproduce --device cuda`` (the default job), given what is left of the budget (a run
   cut at its timeout is a row "not finished after N s");
6. the device multigrid on the AlN problem (``auto`` never takes it on a GPU: the array-API
   backend's default preconditioner is the FFT one), only where the budget leaves room.

Goals (issue 61): ``itr reproduce --device cuda`` <= 90 s; ``itr identify`` ZnO <= 40 s;
al2o3_60 512^3 CG <= 3 s, wall <= 4 s; AlN-60 64 um solve <= 8 s wall; its build <= 10 s.
Without a CUDA device the solver rows run on the CPU at ``--n`` (default 64) and the command
rows are skipped: every row then says "GPU unverified".

Usage::

    python validation/bench_device.py [--out DIR] [--budget-s 420] [--n 512]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from itr_fv.discrete.problem import DiscreteProblem  # noqa: E402
from itr_fv.solvers.devices import cuda_device_count  # noqa: E402
from validation.bench_gpu import Budget, aln_problem, device_facts, solve  # noqa: E402
from validation.gallery import build  # noqa: E402

#: Issue 61's goals (seconds).
GOALS = {"reproduce": 90.0, "identify": 40.0, "al2o3_cg": 3.0, "al2o3_wall": 4.0,
         "aln_wall": 8.0, "aln_build": 10.0}
ZNO = ROOT / "examples" / "zno_epoxy"


def versions() -> dict:
    """The installed stack, as the device machine has it."""
    out = {"python": platform.python_version()}
    for dist in ("numpy", "scipy", "numba", "numba-cuda", "cupy-cuda12x", "cupy-cuda13x",
                 "cupy"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    try:
        import cupy
        out["cuda_driver"] = cupy.cuda.runtime.driverGetVersion()
        out["cuda_runtime"] = cupy.cuda.runtime.runtimeGetVersion()
    except Exception:  # noqa: BLE001 - no CuPy or no driver: not a GPU machine
        pass
    return out


class Report:
    """Rows measured so far; printed as they come and written after each."""

    def __init__(self, out: Path, on_gpu: bool) -> None:
        self.out, self.on_gpu = out, on_gpu
        self.res: dict = {"rows": [], "log": []}

    def log(self, text: str) -> None:
        print(text, flush=True)
        self.res["log"].append(text)

    def row(self, label: str, goal_s: float | None, value_s: float | None,
            detail: str = "") -> None:
        holds = ("-" if goal_s is None or value_s is None else
                 ("yes" if value_s <= goal_s else "no"))
        if not self.on_gpu:
            holds = "GPU unverified"
        row = {"row": label, "goal_s": goal_s, "value_s": value_s, "holds": holds,
               "detail": detail}
        self.res["rows"].append(row)
        goal = f"<= {goal_s:g} s" if goal_s is not None else "-"
        value = f"{value_s:.2f} s" if value_s is not None else "-"
        self.log(f"| {label} | {goal} | {value} | {holds} | {detail} |")
        self.write()

    def write(self) -> None:
        self.out.mkdir(parents=True, exist_ok=True)
        lines = ["# Issue 61's GPU rows (validation/bench_device.py)", "",
                 f"Stack: {json.dumps(self.res.get('versions', {}))}", "",
                 f"Fused kernels: {self.res.get('fused', 'not probed')}", "",
                 "| row | goal | measured | holds | detail |", "| --- | --- | --- | --- | --- |"]
        for r in self.res["rows"]:
            goal = f"<= {r['goal_s']:g} s" if r["goal_s"] is not None else "-"
            value = f"{r['value_s']:.2f} s" if r["value_s"] is not None else "-"
            lines.append(f"| {r['row']} | {goal} | {value} | {r['holds']} | {r['detail']} |")
        lines += ["", "## Log", ""] + [f"    {t}" for t in self.res["log"]]
        for name, text in (("bench_device.md", "\n".join(lines) + "\n"),
                           ("bench_device.json", json.dumps(self.res, indent=1))):
            tmp = self.out / (name + ".tmp")
            tmp.write_text(text, encoding="utf-8")
            tmp.replace(self.out / name)


def fused_state(on_gpu: bool) -> str:
    """'run' where the fused kernels build and run here, else why not (one line)."""
    from itr_fft.fused_kernels import fused_failure

    if not on_gpu:
        return "not tried (no CUDA device)"
    import cupy
    why = fused_failure(cupy)
    return "run" if why is None else f"do not run: {why}"


def model_s(n: int, device: str) -> float:
    """The cost model's wall of three load cases at n^3 on ``device``
    (:func:`itr_fv.solvers.choice.load_case_seconds`): what the plans and the routing of
    small grids read, checked here against the measured rows."""
    from itr_fv.solvers.choice import SOLVERS, load_case_seconds

    entry = SOLVERS["gpu" if device == "cuda" else "fft"]
    return 3 * load_case_seconds(entry, n ** 3, None if device == "cuda" else os.cpu_count())


def solver_rows(rep: Report, n: int, device: str, budget: Budget) -> tuple | None:
    """Rows 2 and 3: al2o3_60 and AlN-60 at n^3, auto kernels and portable ones; returns
    the AlN problem and its materials (None where it was skipped)."""
    auto = {"device": device, "kernels": "auto", "preconditioner": "fft"}
    portable = {**auto, "kernels": "portable"}
    ms, mat = build("al2o3_60", 32, contact="gap")
    warm = DiscreteProblem.for_materials(ms, mat)
    for opts in (auto, portable):  # kernels compiled, FFT plans made
        solve(warm, mat, opts)
    on_device_small(rep, device, budget)
    if budget.allows(60, f"al2o3_60 {n}^3", rep.log):
        ms, mat = build("al2o3_60", n, contact="gap")
        problem = DiscreteProblem.for_materials(ms, mat)
        problem.system(mat)
        for name, opts in (("auto", auto), ("portable", portable)):
            r = solve(problem, mat, opts)
            detail = (f"{name} kernels: iterations {'/'.join(map(str, r['iterations']))}, "
                      f"{1e3 * r['s_per_iteration']:.1f} ms/iteration, wall "
                      f"{r['wall_s']:.2f} s")
            rep.row(f"al2o3_60 {n}^3 CG ({name})", GOALS["al2o3_cg"] if name == "auto"
                    else None, r["cg_s"], detail)
            if name == "auto":
                rep.row(f"al2o3_60 {n}^3 wall (auto)", GOALS["al2o3_wall"], r["wall_s"],
                        f"the cost model: {model_s(n, device):.2f} s")
        del problem, ms
    if budget.allows(90, f"AlN-60 {n}^3", rep.log):
        problem, mat, build_s = aln_problem(n)
        rep.row(f"AlN-60 {0.125 * n:g} um / 0.125 um: problem build", GOALS["aln_build"],
                build_s)
        for name, opts in (("auto", auto), ("portable", portable)):
            if not budget.allows(30, f"AlN-60 {name}", rep.log):
                continue
            r = solve(problem, mat, opts)
            rep.row(f"AlN-60 {0.125 * n:g} um solve wall ({name})",
                    GOALS["aln_wall"] if name == "auto" else None, r["wall_s"],
                    f"CG {r['cg_s']:.2f} s, iterations "
                    f"{'/'.join(map(str, r['iterations']))}, k_xx {r['k_eff'][0][0]:.6g}")
        return problem, mat
    return None


def on_device_small(rep: Report, device: str, budget: Budget) -> bool:
    """Rows of the small grids the cost model sends to the CPU: al2o3_60 at 48^3 and 96^3
    on the device and on the CPU's default solver, each against the model."""
    from itr_fv.solvers.choice import as_solver

    if not budget.allows(30, "small grids: device against CPU", rep.log):
        return False
    for n in (48, 96):
        ms, mat = build("al2o3_60", n, contact="gap")
        problem = DiscreteProblem.for_materials(ms, mat)
        dev = solve(problem, mat, {"device": device, "kernels": "auto",
                                   "preconditioner": "fft"})
        t = time.perf_counter()
        res = homogenize_cpu(problem, mat)
        cpu = time.perf_counter() - t
        rep.row(f"al2o3_60 {n}^3 on {device} / on the CPU", None, dev["wall_s"],
                f"CPU {cpu:.2f} s ({res.info.get('workers')} threads); the cost model "
                f"{model_s(n, device):.2f} / {model_s(n, 'cpu'):.2f} s, routes it to "
                f"{as_solver('gpu').for_grid(n ** 3).key}")
    return True


def homogenize_cpu(problem, mat):
    """The CPU's default solve (``fft``) of ``problem``."""
    from itr_fv import homogenize

    return homogenize(problem, mat, solver="fft", tol=1e-8, store_fields=False,
                      check_memory=False)


def command_row(rep: Report, label: str, args: list[str], goal_s: float,
                timeout_s: float) -> None:
    """One ``itr`` command, timed; a run past ``timeout_s`` is a row 'not finished'."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "itr_identify.cli", *args, "--no-progress",
               "--out", str(Path(tmp) / "out")]
        t = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s,
                                  check=False)
        except subprocess.TimeoutExpired:
            rep.row(label, goal_s, None, f"not finished after {timeout_s:.0f} s")
            return
        wall = time.perf_counter() - t
    if proc.returncode:
        tail = " ".join(proc.stderr.strip().splitlines()[-2:])[:300]
        rep.row(label, goal_s, None, f"exit {proc.returncode}: {tail}")
        return
    rep.row(label, goal_s, wall, "exit 0")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "validation" / "results")
    ap.add_argument("--budget-s", type=float, default=420.0)
    ap.add_argument("--n", type=int, default=None,
                    help="grid edge of the solver rows (default 512 on a GPU, 64 without)")
    args = ap.parse_args(argv)
    budget = Budget(args.budget_s)
    on_gpu = cuda_device_count() > 0
    device = "cuda" if on_gpu else "cpu"
    n = args.n or (512 if on_gpu else 64)
    rep = Report(args.out, on_gpu)
    rep.res["versions"] = versions()
    rep.log(f"stack: {rep.res['versions']}")
    facts = device_facts(on_gpu)
    rep.log(f"device: {facts['name']}; copy bandwidth {facts['copy_Bps'] / 1e9:.0f} GB/s")
    rep.res["fused"] = fused_state(on_gpu)
    rep.log(f"fused kernels: {rep.res['fused']}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fallback's warning is in the log line above
        aln = solver_rows(rep, n, device, budget)
    if on_gpu:
        if budget.allows(60, "itr identify ZnO", rep.log):
            command_row(rep, "itr identify ZnO --device cuda", [
                "identify", str(ZNO / "measurements.csv"), "--system",
                str(ZNO / "system.toml"), "--device", "cuda"], GOALS["identify"],
                min(180.0, budget.left() - 100))
        if budget.allows(100, "itr reproduce --device cuda", rep.log):
            command_row(rep, "itr reproduce --device cuda", ["reproduce", "--device", "cuda"],
                        GOALS["reproduce"], budget.left() - 10)
    else:
        rep.log("no CUDA device: the command rows need one (GPU unverified)")
    if aln is not None and budget.allows(100, "AlN-60 device multigrid", rep.log):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = solve(aln[0], aln[1], {"device": device, "kernels": "auto",
                                       "preconditioner": "multigrid"})
        rep.row("AlN-60 solve wall (device multigrid, not auto's)", None, r["wall_s"],
                f"iterations {'/'.join(map(str, r['iterations']))}")
    rep.write()
    rep.log(f"wrote {args.out / 'bench_device.md'} ({os.cpu_count()} host cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
