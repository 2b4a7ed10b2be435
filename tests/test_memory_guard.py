"""The memory guard: estimate before a solve, refuse what cannot fit (issue 8, point 5)."""

import numpy as np
import pytest
from conftest import sc_sphere
from refusals import refuses

import itr_fft
from itr_fft.multigrid import MG_BYTES_PER_VOXEL
from itr_fft.numba_backend import FFT_BYTES_PER_VOXEL
from itr_fv import Materials, homogenize
from itr_fv.solvers import resources
from itr_fv.solvers.amg import AMG_BYTES_PER_VOXEL
from itr_fv.solvers.resources import InsufficientMemoryError, check_memory, estimate_peak_memory

MAT = Materials({"matrix": 1.0, "filler": 10.0}, {("filler", "matrix"): 0.05}, "matrix")


def test_estimates_scale_with_voxels_and_rank_the_solvers():
    fv = estimate_peak_memory((400, 400, 400), "itr_fv", store_fields=False)
    f64 = estimate_peak_memory((400, 400, 400), itr_fft.NumbaFFTBackend(preconditioner="fft"),
                               store_fields=False)
    f32 = estimate_peak_memory((400, 400, 400), "itr_fft", dtype="float32", store_fields=False)
    assert fv == 400**3 * AMG_BYTES_PER_VOXEL
    assert fv > 10 * f64 and f32 <= estimate_peak_memory((400, 400, 400), "itr_fft",
                                                         store_fields=False)
    # the multigrid (which "auto" may take) holds its hierarchy on top
    mg = estimate_peak_memory((400, 400, 400), "itr_fft", store_fields=False)
    assert mg == 400**3 * (FFT_BYTES_PER_VOXEL + MG_BYTES_PER_VOXEL) > f64
    # the 400^3 FV solve that died at 7.6 GB in assemble_operator is estimated far above that
    assert fv > 60e9
    fields = estimate_peak_memory((400, 400, 400), "itr_fft", store_fields=True, load_cases=3)
    assert fields - mg == 400**3 * 3 * resources.FIELD_BYTES_PER_VOXEL_CASE
    with refuses(ValueError, "solver"):
        estimate_peak_memory((8, 8, 8), "itr_gpu")
    # a configured backend object gives its own cost
    assert estimate_peak_memory((10, 10, 10), itr_fft.NumbaFFTBackend(
        dtype=np.float32, preconditioner="fft"), store_fields=False) == 1000 * FFT_BYTES_PER_VOXEL


def test_refusal_names_estimate_available_and_what_would_fit():
    with pytest.raises(InsufficientMemoryError) as info:
        check_memory((400, 400, 400), "itr_fv", store_fields=False, available=24 * 10**9)
    msg = str(info.value)
    assert "400x400x400" in msg and "80.0 GB" in msg and "24.0 GB" in msg
    # the cheapest backend that fits is named: plain numpy/scipy FFT-PCG, 136 B per voxel
    assert "would fit: scipy_fft" in msg and "8.7 GB" in msg and "check_memory=False" in msg
    assert msg.startswith("memory: itr_fv on a 400x400x400 grid")
    assert info.value.estimate > info.value.available
    # nothing fits: say so
    with pytest.raises(InsufficientMemoryError, match="no solver fits"):
        check_memory((2000, 2000, 2000), "itr_fft", available=10**9)
    # enough memory: the estimate is returned
    assert check_memory((64, 64, 64), "itr_fv", available=10**10) == \
        estimate_peak_memory((64, 64, 64), "itr_fv")


@pytest.mark.parametrize("solver", ["fv", "fft"])
def test_solvers_refuse_before_any_work_and_can_be_told_to_go_ahead(solver, monkeypatch):
    ms = sc_sphere(12, 0.2)
    calls = []
    monkeypatch.setattr(resources, "available_memory", lambda: 1000)  # 1 kB left
    import itr_fv.discrete.problem
    real = itr_fv.discrete.problem.face_geometry

    def spy(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(itr_fv.discrete.problem, "face_geometry", spy)
    with pytest.raises(InsufficientMemoryError, match="12x12x12"):
        homogenize(ms, MAT, solver=solver, tol=1e-8)
    assert calls == []  # refused before the geometry was built
    res = homogenize(ms, MAT, solver=solver, tol=1e-8, check_memory=False)
    assert calls == [1] and res.converged and np.isfinite(res.k_eff).all()


def test_available_memory_reads_this_machine():
    avail = resources.available_memory()
    assert avail is None or 10**8 < avail < 10**14


@pytest.mark.slow
@pytest.mark.parametrize("solver,n", [("itr_fv", 64), ("itr_fft", 128)])
def test_estimate_bounds_the_measured_peak(solver, n):
    """The guard must not underestimate: peak RSS growth of a real solve (fresh process,
    dense 60 % Al2O3 RVE at 0.125 um voxels, three load cases, fields kept) stays below the
    estimate, and the estimate is not wildly pessimistic (< 2.5x). The peak is the child's
    own VmHWM: getrusage's ru_maxrss is kept across fork and exec, so a child of a big pytest
    process starts with its parent's peak and would measure no growth at all."""
    import json
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent(f"""
        import json
        import numpy as np
        from itr_fv import Materials, homogenize
        from itr_fv.rve import FillerSpec, RVESpec, generate_rve
        ms = generate_rve(RVESpec({n} * 0.125, 0.125, max_diameter_box_ratio=0.45),
                          [FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.6)], 1)
        mat = Materials({{"silicone": 0.18, "Al2O3": 30.0}},
                        {{("Al2O3", "silicone"): 1e-7, ("Al2O3", "Al2O3"): 1e-7}}, "silicone")
        def peak():  # this process's own high-water mark of resident memory, bytes
            with open("/proc/self/status") as f:
                return next(int(ln.split()[1]) * 1024 for ln in f if ln.startswith("VmHWM:"))
        before = peak()
        homogenize(ms, mat, solver={solver!r}, tol=1e-6, store_fields=True)
        after = peak()
        print(json.dumps([before, after]))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600, check=True)
    before, after = json.loads(out.stdout.strip().splitlines()[-1])
    estimate = estimate_peak_memory((n, n, n), solver, store_fields=True, load_cases=3)
    assert after - before < estimate < 2.5 * max(after - before, 1)
