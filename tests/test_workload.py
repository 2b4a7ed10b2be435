"""One estimate of memory and time before any work: every command that packs or solves
refuses in one line, within seconds and before it touches anything, what cannot fit in this
machine's memory, and says what would; the estimate follows the package's measured costs."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from itr_fv.solvers.choice import Solver
from refusals import refuses

from itr_fv.rve import FillerSpec, build_rve
from itr_fv.rve.spec import RVESpec
from itr_fv.solvers.resources import estimate_peak_memory
from itr_surrogate.workload import (
    PROCESS_BASE_BYTES,
    Grid,
    Workload,
    WorkloadRefused,
    expected_particles,
)

SHIPPED_TABLE = str(Path(__file__).resolve().parents[1] / "itr_fv" / "data" / "measured_tc.csv")

CAMPAIGN_1200 = """name = "huge"
box_um = 6.0
voxel_um = 0.005
replicas = 1
contact = "gap"
[[formulation]]
name = "Al2O3-40"
fractions = { Al2O3 = 0.40 }
[design]
kind = "grid"
values = { R_Al2O3_silicone = [1e-8] }
"""

CORRECTIONS_HUGE = """name = "huge"
packings = 2
seed = 9001
solver = "fft"
tol = 1e-6
[[system]]
name = "Al2O3"
box_um = 200.0
voxel_um = 0.05
formulations = ["Al2O3-60"]
values = { R_Al2O3_silicone = [1e-8] }
"""

#: (command line, what the refusal names). Each must be refused before any work.
TOO_BIG = {
    "identify fine voxel": ["identify", SHIPPED_TABLE, "--voxel-um", "0.005"],
    "identify 200 um box": ["identify", SHIPPED_TABLE, "--box-um", "200", "--voxel-um", "0.05"],
    "reproduce fine voxel": ["reproduce", "--voxel-um", "0.005"],
    "reproduce 200 um box": ["reproduce", "--box-um", "200", "--voxel-um", "0.05"],
    "discrepancy fine voxel": ["discrepancy", "--voxel-um", "0.005"],
    "discrepancy 200 um box": ["discrepancy", "--box-um", "200", "--voxel-um", "0.05"],
    "campaign 1200^3": ["campaign", "run", "huge.toml", "--out", "camp"],
    "campaign 1200^3 in this process": ["campaign", "run", "huge.toml", "--out", "camp",
                                        "--workers", "0"],
    "corrections 4000^3": ["corrections", "build", "corr.toml", "--out", "corr"],
}


def run_itr(*args, cwd, timeout=120):
    env = dict(os.environ)
    env.pop("ITR_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "itr_identify.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("args", list(TOO_BIG.values()), ids=list(TOO_BIG))
def test_what_cannot_fit_is_refused_in_one_line_before_any_work(args, tmp_path):
    (tmp_path / "huge.toml").write_text(CAMPAIGN_1200)
    (tmp_path / "corr.toml").write_text(CORRECTIONS_HUGE)
    before = sorted(p.name for p in tmp_path.iterdir())
    t = time.perf_counter()
    out = ["--out", "run"] if args[0] in ("identify", "reproduce", "discrepancy") else []
    r = run_itr(*args, *out, cwd=tmp_path)
    seconds = time.perf_counter() - t
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and lines[0].startswith("itr: error: memory: "), r.stderr
    assert "GB is available" in lines[0] and "fit" in lines[0]
    assert "voxels fit: a voxel of at least" in lines[0]       # what would fit
    assert sorted(p.name for p in tmp_path.iterdir()) == before   # nothing written
    assert seconds < 5.0, f"refused after {seconds:.1f} s"      # the bound


def test_a_command_that_fits_prints_its_plan_first(tmp_path):
    r = run_itr("demo", "--box-um", "6", "--voxel-um", "0.25", "--fraction", "0.4", "--out",
                "d", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    first = r.stdout.splitlines()[0]
    assert first.startswith("plan: 1 RVE of 24^3 (demo RVE, 6 um at 0.25 um")
    assert "GB available" in first and "cores (solver fft" in first


# ------------------------------------------------------------------ the estimate itself
def test_expected_particles_match_what_the_packer_draws():
    """The expectation from the size cuts is the packer's count to within its sampling."""
    spec = RVESpec(box_um=16.0, voxel_um=0.25, seed=1)
    for filler in (FillerSpec.from_table1("Al2O3", 0.55), FillerSpec.from_table1("AlN", 0.55)):
        drawn = [build_rve(spec, [filler], r, matrix="silicone")[0].n_particles
                 for r in range(2)]
        expect = expected_particles(spec, [filler])
        assert all(abs(n / expect - 1) < 0.25 for n in drawn), (filler.material, drawn, expect)


def test_memory_is_the_solvers_measured_cost_plus_what_the_run_holds():
    g = Grid("g", 12.0, 0.25, rves=10, solves=20, fields=True, kept_fields=4)
    n = 48 ** 3
    solve = estimate_peak_memory((48, 48, 48), "itr_fft", store_fields=True) + 64 * n
    assert g.solve_bytes(Solver("fft")) == solve
    w = Workload((g,), Solver("fft"))
    assert w.peak_bytes() == PROCESS_BASE_BYTES + solve + 10 * 64 * n + 4 * 3 * 8 * n
    # a Dask worker is sized as the engine sizes it: the task plus its base, at the pause mark
    from itr_surrogate.cluster import worker_memory_limit
    assert Workload((g,), Solver("fft"), workers=2).peak_bytes() == worker_memory_limit(solve)


def test_the_refusal_names_the_largest_grid_that_fits():
    big = Grid("big", 24.0, 0.02, rves=1, solves=1)             # 1200^3
    w = Workload((Grid("small", 12.0, 0.25, rves=3, solves=9), big), Solver("fft"))
    assert w.largest is big
    with pytest.raises(WorkloadRefused) as err:
        w.check(available=8 * 10**9)
    msg = str(err.value)
    assert msg.startswith("memory: the run on 1200^3 voxels (big: 24 um box at 0.02 um")
    fit = int(msg.split("at most ~")[1].split("^3")[0])
    # the grid it names fits, one voxel per edge more does not
    ok = Workload((Grid("small", 12.0, 0.25, rves=3, solves=9),
                   Grid("big", 24.0, 24.0 / fit, rves=1, solves=1)), Solver("fft"))
    over = Workload((Grid("small", 12.0, 0.25, rves=3, solves=9),
                     Grid("big", 24.0, 24.0 / (fit + 1), rves=1, solves=1)), Solver("fft"))
    assert ok.refusal(available=8 * 10**9) is None
    assert over.refusal(available=8 * 10**9) is not None
    assert w.refusal(available=10**15) is None


def test_an_external_scheduler_is_not_judged_by_this_machine():
    big = Grid("big", 24.0, 0.02, rves=1, solves=1)
    assert Workload((big,), Solver("fft"), scheduler="tcp://x:8786").refusal(available=10**9) is None


def test_time_grows_with_solves_voxels_and_particles():
    a = Grid("a", 12.0, 0.25, rves=3, solves=10, particles=70)
    b = Grid("b", 12.0, 0.125, rves=3, solves=10, particles=70)
    assert Workload((b,), Solver("fft")).seconds() > Workload((a,), Solver("fft")).seconds()
    assert Workload((a,), Solver("fv")).seconds() > Workload((a,), Solver("fft")).seconds()


def test_side_by_side_processes_each_count_in_the_peak_and_the_plan_says_so():
    """Identifications side by side hold their own caches and fields: the peak is each
    process's as if alone, plus this process's base; the plan names the processes; a
    bad count is refused naming the argument."""
    from itr_identify.forward.model import ForwardSettings
    from itr_identify.forward.work_estimate import identification_workload
    from itr_surrogate.workload import PROCESS_BASE_BYTES, Workload

    g = Grid("g", 12.0, 0.25, rves=10, solves=20, fields=True, kept_fields=4)
    alone = Workload((g,), Solver("fft"))
    two = Workload((g,), Solver("fft"), processes=2)
    assert two.peak_bytes() == 2 * alone.peak_bytes() + PROCESS_BASE_BYTES
    assert "in this process and 2 side processes" in two.summary()
    with refuses(ValueError, "processes"):
        Workload((g,), Solver("fft"), processes=0)
    comps = {"Al2O3-60": {"Al2O3": 0.6}, "AlN-60": {"AlN": 0.6}}
    both = identification_workload(ForwardSettings(), comps, ["area", "gap"], validation=True)
    one = identification_workload(ForwardSettings(), comps, ["gap"], validation=True)
    workers = identification_workload(ForwardSettings(), comps, ["area", "gap"],
                                      validation=True, workers=2)
    assert one.processes == 1 and workers.processes == 1
    assert both.processes == (2 if (os.cpu_count() or 1) > 1 else 1)
