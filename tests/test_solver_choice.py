"""The one place a solver is chosen (itr_fv.solvers.choice): names, devices, refusals, and
that every command that solves takes --solver and --device and refuses a GPU it lacks in one
line before any work."""

import numpy as np
import pytest

import itr_fv.solvers.choice as choice
from itr_fv.solvers.choice import (
    DEFAULT_SOLVER,
    SOLVERS,
    needs_gpu,
    resolve_solver,
    solver_backend,
    worker_resources,
)
from itr_identify.cli import main


@pytest.fixture
def gpus(monkeypatch):
    """Set how many CUDA devices the choice sees (a stand-in for the device check)."""
    def set_count(n: int) -> None:
        monkeypatch.setattr(choice, "cuda_device_count", lambda: n)
        monkeypatch.setattr("itr_fv.solvers.devices.cuda_device_count", lambda: n)
    return set_count


@pytest.mark.parametrize("solver, device, expected", [
    ("fft", None, "fft"), ("fft", "cpu", "fft"), ("mg", "cpu", "mg"), ("fv", None, "fv"),
    ("auto", "cpu", "fft"), ("auto", "auto", "fft"), ("fft", "auto", "fft"),
    ("scipy_fft", "cpu", "scipy_fft"), ("mg", "auto", "mg")])
def test_choices_without_a_gpu(gpus, solver, device, expected):
    gpus(0)
    assert resolve_solver(solver, device) == expected


@pytest.mark.parametrize("solver, device, expected", [
    ("fft", "cuda", "gpu"), ("auto", "cuda", "gpu"), ("auto", "auto", "gpu"),
    ("fft", "auto", "gpu"), ("gpu", None, "gpu"), ("gpu", "auto", "gpu"), ("mg", "auto", "mg"),
    ("fft", None, "fft")])
def test_choices_with_a_gpu(gpus, solver, device, expected):
    gpus(1)
    assert resolve_solver(solver, device) == expected


def test_refusals_name_the_argument(gpus):
    gpus(0)
    with pytest.raises(ValueError, match=r"^--device: solver 'gpu' solves on a GPU, but this "
                       r"machine has no CUDA device"):
        resolve_solver("fft", "cuda", device_argument="--device")
    with pytest.raises(ValueError, match=r"^--solver: solver 'gpu' solves on a GPU"):
        resolve_solver("gpu", solver_argument="--solver")
    assert resolve_solver("gpu", "cuda", local=False) == "gpu"  # the workers' business
    gpus(1)
    with pytest.raises(ValueError, match=r"^device: the solver 'fv' runs on the CPU, not on "
                       r"'cuda'; use --device cpu, or a solver for 'cuda' \('gpu'\)"):
        resolve_solver("fv", "cuda")
    with pytest.raises(ValueError, match=r"^device: the solver 'gpu' runs on the CUDA"):
        resolve_solver("gpu", "cpu")
    with pytest.raises(ValueError, match=r"^solver: expected one of 'fft', 'mg', 'fv', 'gpu'"):
        resolve_solver("quantum")
    with pytest.raises(ValueError, match=r"^device: expected one of 'cpu', 'cuda', 'auto'"):
        resolve_solver("fft", "tpu")


def test_each_choice_declares_its_backend_device_and_worker_resources():
    assert DEFAULT_SOLVER in SOLVERS
    assert {n: c.backend for n, c in SOLVERS.items()} == {
        "fft": "itr_fft", "mg": "itr_fft", "fv": "itr_fv", "gpu": "array_api"}
    assert worker_resources("gpu") == {"GPU": 1} and needs_gpu("gpu")
    assert all(worker_resources(n) is None and not needs_gpu(n) for n in ("fft", "mg", "fv"))
    backend = solver_backend("mg", threads=1)
    assert backend.name == "itr_fft" and backend.options()["preconditioner"] == "multigrid"
    assert backend.device_bytes_per_voxel() == 0  # a host backend: nothing on a device


def test_the_memory_guard_checks_device_memory_for_a_device_backend():
    from itr_fv.solvers.backends import Backend
    from itr_fv.solvers.resources import InsufficientMemoryError, check_device_memory

    class OnDevice(Backend):
        name = "on_device"

        def bytes_per_voxel(self):
            return 40

        def device_bytes_per_voxel(self):
            return 100

        def prepare(self, system, voxel_m):  # pragma: no cover - never solved here
            raise NotImplementedError

    # 100^3 voxels x 100 B = 1e8 B on the device: fits 1 GB free, not 50 MB
    assert check_device_memory((100, 100, 100), OnDevice(), free=10**9) == 10**8
    with pytest.raises(InsufficientMemoryError, match=r"of GPU memory but 0\.1 GB is free"):
        check_device_memory((100, 100, 100), OnDevice(), free=10**8)
    assert check_device_memory((100, 100, 100), solver_backend("fft"), free=0) == 0


@pytest.mark.parametrize("command", [
    ["demo", "--n", "12", "--box-um", "3"],
    ["reproduce"], ["identify", "MEAS"], ["discrepancy"],
    ["campaign", "run", "examples/campaign-tiny.toml"]])
def test_every_command_that_solves_refuses_cuda_without_a_gpu_in_one_line(
        command, gpus, tmp_path, capsys, monkeypatch):
    gpus(0)
    root = __import__("pathlib").Path(__file__).resolve().parents[1]
    command = [str(root / c) if c.startswith("examples/") else c for c in command]
    if "MEAS" in command:
        meas = tmp_path / "m.csv"
        meas.write_text("formulation,replicate,k_W_per_mK\nAl2O3-30,1,0.5\n")
        command[command.index("MEAS")] = str(meas)
    monkeypatch.chdir(tmp_path)
    code = main([*command, "--out", "out", "--device", "cuda"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("itr: error: --device: solver 'gpu' solves on a GPU, but this "
                          "machine has no CUDA device")
    assert not (tmp_path / "out").exists()  # refused before any work, no folder
    code = main([*command, "--out", "out2", "--solver", "fv", "--device", "cuda"])
    err = capsys.readouterr().err
    assert code == 2 and "--device: the solver 'fv' runs on the CPU" in err


def test_demo_solves_with_the_chosen_solver(tmp_path, capsys):
    """The demo's --solver reaches the solve: fv (pyamg) and mg (numba multigrid) give the
    same k_eff as the default fft on the same RVE to solver tolerance."""
    k = {}
    for name in ("fft", "fv", "mg"):
        out = tmp_path / name
        assert main(["demo", "--n", "16", "--box-um", "4", "--fraction", "0.3",
                     "--solver", name, "--device", "cpu", "--out", str(out)]) == 0
        text = capsys.readouterr().out
        line = next(s for s in text.splitlines() if s.startswith("k_iso = "))
        k[name] = float(line.split()[2])
        assert f"solver {choice.SOLVERS[name].backend}" in line
    assert np.allclose(k["fv"], k["fft"], rtol=1e-6) and np.allclose(k["mg"], k["fft"],
                                                                      rtol=1e-6)
