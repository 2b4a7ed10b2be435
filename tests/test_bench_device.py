"""The device script of issue 61 (validation/bench_device.py) runs as it is where no CUDA
device is seen: every solver row measured on the CPU and marked "GPU unverified", the
command rows said skipped, the report written (a lent device runs the same script)."""

import json

import pytest

from validation.bench_device import GOALS, main


@pytest.mark.slow
def test_the_device_script_runs_without_a_device_and_says_what_is_unverified(tmp_path, capsys):
    assert main(["--n", "32", "--budget-s", "300", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "bench_device.json").read_text())
    rows = {r["row"]: r for r in res["rows"]}
    assert {"al2o3_60 32^3 CG (auto)", "al2o3_60 32^3 wall (auto)",
            "AlN-60 4 um / 0.125 um: problem build", "AlN-60 4 um solve wall (auto)"} <= set(rows)
    assert all(r["holds"] == "GPU unverified" for r in rows.values())
    assert rows["al2o3_60 32^3 CG (auto)"]["goal_s"] == GOALS["al2o3_cg"] == 3.0
    # the same kernels on the CPU: auto and portable take the same iterations
    auto = rows["AlN-60 4 um solve wall (auto)"]["detail"].split("iterations ")[1]
    portable = rows["AlN-60 4 um solve wall (portable)"]["detail"].split("iterations ")[1]
    assert auto == portable
    assert "the command rows need one" in capsys.readouterr().out
    assert "| row | goal | measured | holds | detail |" in (
        tmp_path / "bench_device.md").read_text()
