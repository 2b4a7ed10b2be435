"""The solve engine: serial and Dask runs give the same numbers, the store keeps every
finished solve (a re-run solves nothing), and the geometry is built once per RVE."""

from __future__ import annotations

import os

import numpy as np
import pytest
from refusals import refuses

import itr_fft
from itr_fv import Materials, homogenize
from itr_fv.rve import FillerSpec, RVESpec, generate_rve
from itr_fv.solvers.choice import Solver
from itr_surrogate import cluster as eng
from itr_surrogate import requests as payloads
from itr_surrogate import worker
from itr_surrogate.engine import SolveEngine
from itr_surrogate.requests import RVEData, SolveRequest
from itr_surrogate.store import SolveStore

MAT = Materials({"silicone": 0.18, "Al2O3": 30.0}, {("Al2O3", "silicone"): 2e-8},
                matrix="silicone")


@pytest.fixture(scope="module")
def rves():
    out = []
    for seed in (1, 2):
        # a 5 um box on purpose (small solves): the box cut is expected and said
        with pytest.warns(UserWarning, match="under-represents its coarse particles"):
            ms = generate_rve(RVESpec(5.0, 0.25, max_diameter_box_ratio=0.45),
                              [FillerSpec("Al2O3", mu=1.02, sigma=0.35, volume_fraction=0.5)],
                              seed, matrix="silicone")
        out.append((ms, RVEData.of(ms)))
    return out


def _requests(rves, fields=False):
    return [SolveRequest.for_materials(rve, MAT.with_parameters({"R_Al2O3_silicone": r}),
                                       1e-9, fields=fields, replica=i)
            for i, (_, rve) in enumerate(rves) for r in (1e-8, 1e-7)]


def test_rve_data_rebuilds_the_same_voxels_and_has_a_stable_id(rves):
    ms, rve = rves[0]
    again = rve.microstructure()
    assert np.array_equal(again.material_ids, ms.material_ids)
    assert np.array_equal(again.particle_ids, ms.particle_ids)
    assert RVEData.from_payload(rve.to_payload()).rve_id == rve.rve_id
    assert rve.rve_id != rves[1][1].rve_id


def test_request_keys_follow_parameters_tolerance_and_solver(rves):
    rve = rves[0][1]
    a = SolveRequest.for_materials(rve, MAT, 1e-8)
    assert a.key == SolveRequest.for_materials(rve, MAT, 1e-8, purpose="other").key
    assert a.key != SolveRequest.for_materials(rve, MAT, 1e-9).key
    assert a.key != SolveRequest.for_materials(rve, MAT, 1e-8, solver="fv").key
    assert a.key != SolveRequest.for_materials(
        rve, MAT.with_parameters({"R_Al2O3_silicone": 2.1e-8}), 1e-8).key
    with refuses(ValueError, "solver"):
        SolveRequest.for_materials(rve, MAT, 1e-8, solver="quantum")


def test_serial_results_are_the_solver_and_a_rerun_reuses_every_solve(rves, tmp_path):
    reqs = _requests(rves, fields=True)
    builds = worker.geometry_builds()
    with SolveEngine(tmp_path / "store") as first:
        got = first.solve(reqs)
    assert first.solved == 4 and first.reused == 0
    # one geometry per RVE, not one per solve
    assert first.geometry_builds == 2 and worker.geometry_builds() - builds == 2
    direct = homogenize(rves[1][0], reqs[3].materials, solver="fft", tol=1e-9)
    assert np.allclose(got[3].k_eff, direct.k_eff, rtol=1e-12, atol=0)
    assert np.allclose(got[3].theta, np.stack(direct.theta), rtol=0, atol=1e-12)
    assert SolveStore(tmp_path / "store").count() == 4
    with SolveEngine(tmp_path / "store") as again:
        back = again.solve(reqs)
    assert again.solved == 0 and again.reused == 4
    for a, b in zip(got, back):
        assert np.array_equal(a.k_eff, b.k_eff) and np.array_equal(a.theta, b.theta)
        assert np.array_equal(a.k_eff_energy, b.k_eff_energy) and b.cached
    table = SolveStore(tmp_path / "store").table()
    assert table.num_rows == 4 and set(table.column("replica").to_pylist()) == {0, 1}
    assert "R_Al2O3_silicone" in table.column_names and "k_iso" in table.column_names


def test_duplicate_requests_are_solved_once(rves):
    req = _requests(rves)[0]
    e = SolveEngine()
    out = e.solve([req, req])
    assert e.solved == 1 and np.array_equal(out[0].k_eff, out[1].k_eff)
    assert (e.repeated, e.earlier, e.reused) == (1, 0, 1)


def test_the_summary_tells_repeats_of_this_run_from_an_earlier_run(rves, tmp_path):
    reqs = _requests(rves)
    with SolveEngine(tmp_path / "store") as fresh:
        fresh.solve(reqs)
        assert fresh.summary().startswith("4 full solves in this process, none from an "
                                          "earlier run, ")
        fresh.solve(reqs[:3])   # the store answers, with rows this engine wrote
        assert (fresh.solved, fresh.repeated, fresh.earlier) == (4, 3, 0)
        assert fresh.summary() == (
            "4 full solves in this process (3 requests repeated a solve of this run), none "
            f"from an earlier run, {_builds(fresh.geometry_builds)}")
    with SolveEngine(tmp_path / "store") as resumed:
        resumed.solve(reqs[:1] + [SolveRequest.for_materials(
            rves[0][1], MAT.with_parameters({"R_Al2O3_silicone": 3e-8}), 1e-9)])
        resumed.solve(reqs[:1])   # an earlier run's row again: still not this run's solve
        assert (resumed.solved, resumed.repeated, resumed.earlier, resumed.reused) == \
            (1, 0, 2, 2)
        assert resumed.summary() == (
            "1 full solve in this process, 2 requests from the store of an earlier run, "
            f"{_builds(resumed.geometry_builds)}")


def _builds(n: int) -> str:
    return f"{n} geometry build{'' if n == 1 else 's'}"


def test_a_local_cluster_gives_the_serial_numbers(rves, tmp_path):
    reqs = _requests(rves)
    serial = SolveEngine().solve(reqs)
    with SolveEngine(tmp_path / "s", workers=2) as par:
        dist = par.solve(reqs)
        assert par.solved == 4
        # each worker builds an RVE's geometry at most once
        assert 2 <= par.geometry_builds <= 4
    for a, b in zip(serial, dist):
        assert np.array_equal(a.k_eff, b.k_eff)


def test_bad_engine_arguments():
    with refuses(ValueError, "workers"):
        SolveEngine(workers=0)
    with refuses(ValueError, "--scheduler"):
        eng.open_client(None, "tcp://127.0.0.1:9", memory_per_worker=10**9)


def test_worker_limit_keeps_a_measured_250_cubed_worker_below_the_pause_mark():
    """A box-study worker on 250^3 AlN-60 (gap model, 2 parameter sets per task) was measured
    at 5.9 GiB resident while its limit was 6.6 GB: above dask's 95 % restart mark, so the
    nanny killed it task after task. The limit must put that resident size below the pause
    mark (80 %)."""
    from itr_surrogate.campaign import Campaign
    from itr_surrogate.runner import worker_memory

    camp = Campaign.from_dict({
        "name": "box-AlN-40", "box_um": 40.0, "voxel_um": 0.16, "replicas": 2, "seed": 1,
        "contact": "gap", "solver": "fft", "tol": 1e-7, "block_size": 4,
        "formulation": [{"name": "AlN-60"}],
        "design": {"kind": "grid", "values": {"R_AlN_silicone": [7.7e-9, 3e-8]}}})
    assert camp.shape == (250, 250, 250)
    measured = 5.9 * 2**30
    assert 0.8 * worker_memory(camp) > measured
    # and not absurdly above it: two such workers still fit in 24 GiB
    assert 2 * worker_memory(camp) < 24 * 2**30
    # a small task keeps the base of the interpreter and libraries
    assert eng.worker_memory_limit(0) >= eng.WORKER_BASE_BYTES / 0.8


def test_gpu_solves_go_only_to_workers_that_declare_a_gpu(rves, monkeypatch):
    """A ``solver="gpu"`` request asks the scheduler for the worker resource GPU: a cluster
    whose worker declares none holds it back; a worker that declares one runs it: a grid the
    cost model sends to the CPU is solved there (the CPU's tensor), a grid it keeps on the
    GPU reaches (here, with no GPU in the machine) the array-API backend's own clear
    error."""
    from dataclasses import replace

    from dask.distributed import Client, LocalCluster

    import itr_fv.solvers.choice as choice
    req = SolveRequest.for_materials(rves[0][1], MAT, 1e-8, solver="gpu")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as plain:
        # the engine refuses at once, before submitting anything (never a silent wait)
        with SolveEngine(scheduler=plain.scheduler_address, echo=lambda s: None) as engine:
            with pytest.raises(ValueError, match=r"no worker of --scheduler .* \(1 worker "
                               r"connected\) declares the resource GPU; start GPU workers "
                               r"with 'dask worker .* --resources GPU=1'"):
                engine.solve([req])
            assert engine.solved == 0 and not plain.scheduler.tasks
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as plain, Client(plain) as client:
        fut = client.submit(worker.run_payload, payloads.request_payload(req), pure=False,
                            resources=Solver("gpu").resources)
        with pytest.raises(TimeoutError):
            fut.result(timeout=3)  # no worker may take it
        assert fut.status == "pending"
        fut.cancel()
    if itr_fft.array_api_backend._cuda_available() is not None:
        pytest.skip("this machine has a GPU: the worker would solve, not fail")
    cpu = SolveEngine(echo=lambda s: None).solve_one(
        SolveRequest.for_materials(rves[0][1], MAT, 1e-8))
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None, resources={"GPU": 1}) as gpu:
        with SolveEngine(scheduler=gpu.scheduler_address, echo=lambda s: None) as engine:
            (res,) = engine.solve([req])          # a small grid: sooner on the CPU
            np.testing.assert_allclose(res.k_diagonal, cpu.k_diagonal, rtol=1e-12)
            on_gpu = replace(choice.SOLVERS["gpu"], seconds_per_solve=0.0,
                             seconds_per_voxel=0.0)  # the model keeps every grid there
            monkeypatch.setattr(choice, "SOLVERS", {**choice.SOLVERS, "gpu": on_gpu})
            with refuses(ValueError, "device"):
                engine.solve([SolveRequest.for_materials(rves[0][1], MAT, 1e-9,
                                                         solver="gpu")])


def test_a_local_cluster_for_gpu_solves_is_refused_where_there_is_no_gpu(rves, tmp_path):
    """The real device count (no CuPy, no GPU here): a one-line refusal naming the solver,
    from the one place that makes clusters, before any cluster starts or task is submitted
    -- for the engine and for a campaign alike."""
    from itr_surrogate.campaign import Campaign, CampaignError
    from itr_surrogate.runner import run_campaign

    if eng.cuda_device_count() > 0:
        pytest.skip("this machine has a GPU: the local cluster would get GPU workers")
    with pytest.raises(ValueError, match=r"^solver 'gpu' solves on a GPU, but this machine "
                       r"has no CUDA device .* choose another solver") as info:
        eng.open_client(None, None, memory_per_worker=10**9, solver=Solver("gpu"))
    assert "\n" not in str(info.value)
    req = SolveRequest.for_materials(rves[0][1], MAT, 1e-8, solver="gpu")
    with SolveEngine(tmp_path / "s", workers=1, echo=lambda s: None) as engine:
        with pytest.raises(ValueError, match="no CUDA device"):
            engine.solve([req])
        assert engine._client is None and engine.solved == 0  # no cluster was started
    camp = Campaign.from_dict({
        "name": "g", "box_um": 4.0, "voxel_um": 0.25, "replicas": 1, "seed": 1,
        "solver": "gpu", "formulation": [{"name": "Al2O3-30", "fractions": {"Al2O3": 0.3}}],
        "design": {"kind": "grid", "values": {"R_Al2O3_silicone": [1e-8]}}})
    with pytest.raises(CampaignError, match="solver 'gpu' solves on a GPU"):
        run_campaign(camp, tmp_path / "c", progress=False, echo=lambda s: None)
    assert not (tmp_path / "c").exists()


def test_a_local_cluster_for_gpu_solves_declares_one_gpu_worker_per_device(monkeypatch):
    """With two CUDA devices (the count faked: CI has none), the local cluster for solver
    "gpu" has two workers, however many were asked for, each declaring GPU=1 and seeing its
    own device only; a CPU solver's cluster declares none."""
    monkeypatch.setattr(eng, "cuda_device_count", lambda: 2)
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES", raising=False)
    client, cluster = eng.open_client(3, None, memory_per_worker=10**9, solver=Solver("gpu"),
                                      echo=lambda s: None)
    try:
        workers = client.scheduler_info()["workers"]
        assert [w["resources"] for w in workers.values()] == [{"GPU": 1}, {"GPU": 1}]
        seen = client.run(lambda: os.environ.get("CUDA_VISIBLE_DEVICES"))
        assert sorted(seen.values()) == ["0", "1"]
        assert eng.ready_workers(client, None, Solver("gpu")) == 2
        assert eng.ready_workers(client, None, Solver("fft")) == 2
    finally:
        client.close()
        cluster.close()
    assert Solver("gpu").needs_gpu and not Solver("fft").needs_gpu and not Solver("mg").needs_gpu
