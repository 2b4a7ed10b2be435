"""The README's figures of the main job and the tests, measured and written by script.

``python validation/readme_figures.py measure`` runs the README's main job (``itr reproduce``
at its defaults, in a new temporary folder, nothing reused) and the default test run
(``python -m pytest -q``), each in a child process of the installed package, and records
wall time, the child's peak resident memory, the output folder's size by part and the test
counts in ``validation/results/readme_figures.json``. ``python validation/readme_figures.py
write`` puts those numbers into README.md between the markers ``<!-- readme-figures -->``
and ``<!-- /readme-figures -->``; nothing there is typed by hand. ``all`` does both.
Options: ``--skip-tests`` (keep the recorded test figures), ``--skip-reproduce``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from datetime import date
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "validation" / "results" / "readme_figures.json"
README = ROOT / "README.md"
BEGIN, END = "<!-- readme-figures -->", "<!-- /readme-figures -->"
ITR = [sys.executable, "-m", "itr_identify.cli"]


def _child(cmd: list[str], cwd: Path) -> tuple[float, float, subprocess.CompletedProcess]:
    """Run ``cmd``; (wall s, peak RSS of the largest child in GB, the process)."""
    t = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True,
                          env=dict(os.environ, MPLBACKEND="Agg", PYVISTA_OFF_SCREEN="true"))
    wall = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024 / 1e9
    return wall, peak, proc


def _sizes(folder: Path) -> dict[str, float]:
    """MB of the folder, of its solve store and of the rest."""
    def mb(paths) -> float:
        return sum(p.stat().st_size for p in paths if p.is_file()) / 1e6
    everything = list(folder.rglob("*"))
    store = [p for p in everything if "solves" in p.relative_to(folder).parts[:1]]
    return {"total_mb": round(mb(everything), 1), "solves_mb": round(mb(store), 1),
            "files_mb": round(mb(everything) - mb(store), 1),
            "files": sum(1 for p in folder.iterdir() if p.is_file())}


def measure_reproduce() -> dict:
    work = Path(tempfile.mkdtemp(prefix="itr-readme-"))
    try:
        wall, peak, proc = _child([*ITR, "reproduce", "--no-progress"], work)
        if proc.returncode != 0:
            raise SystemExit(f"itr reproduce failed ({proc.returncode}): {proc.stderr[-2000:]}")
        out = work / "itr-reproduce"
        plan = next((line for line in proc.stdout.splitlines() if line.startswith("plan: ")), "")
        return {"wall_s": round(wall, 1), "peak_gb": round(peak, 2), **_sizes(out),
                "plan": plan}
    finally:
        shutil.rmtree(work, ignore_errors=True)


def measure_tests() -> dict:
    wall, _, proc = _child([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                            "--durations=25"], ROOT)
    return test_figures(proc.stdout, wall)


def tests_from_log(path: Path) -> dict:
    """The test figures of a default test run's output saved elsewhere (e.g. the log of
    ``bash .ci/run``, whose second command is the README's test command): its last pytest
    summary line, the failures and slowest steps before it; the wall time is pytest's own."""
    lines = Path(path).read_text(errors="replace").splitlines()
    ends = [i for i, ln in enumerate(lines)
            if re.search(r"\b(passed|failed)\b.* in [\d.]+s", ln)]
    if not ends:
        raise SystemExit(f"{path}: no pytest summary line")
    end = ends[-1]
    heads = [i for i, ln in enumerate(lines[:end]) if "slowest" in ln and "durations" in ln]
    part = lines[heads[-1] if heads else max(0, end - 200):end + 1]
    secs = re.findall(r" in ([\d.]+)s", lines[end])
    return test_figures("\n".join(part), float(secs[-1]) if secs else math.nan)


def test_figures(stdout: str, wall: float) -> dict:
    lines = [ln.strip("= ") if ln.startswith("=") else ln
             for ln in stdout.strip().splitlines()]
    tail = lines[-1] if lines else ""
    counts = {k: int(v) for v, k in re.findall(r"(\d+) (passed|failed|skipped|errors?)", tail)}
    slowest = [ln for ln in lines if re.match(r"\d+\.\d+s (call|setup|teardown)", ln)]
    failures = [ln.split()[1] for ln in lines if ln.startswith(("FAILED ", "ERROR "))]
    return {"wall_s": round(wall, 1), "summary": tail, **counts, "slowest": slowest,
            "failures": failures}


def _machine() -> str:
    return f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}"


def measure(skip_reproduce: bool, skip_tests: bool) -> dict:
    data = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    if not skip_reproduce:
        data["reproduce"] = {**measure_reproduce(), "date": str(date.today()),
                             "machine": _machine()}
    if not skip_tests:
        data["tests"] = {**measure_tests(), "date": str(date.today()), "machine": _machine()}
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(data, indent=2) + "\n")
    return data


def block(data: dict) -> str:
    """The README's lines, from the recorded figures."""
    r, t = data["reproduce"], data["tests"]
    return (f"On {r['machine']} (no GPU, {r['date']}): `itr reproduce` "
            f"{r['wall_s'] / 60:.1f} min and {r['peak_gb']:.2f} GB peak; it writes "
            f"{r['files_mb']:.0f} MB in {r['files']} files plus its solve store "
            f"`itr-reproduce/solves/` ({r['solves_mb']:.0f} MB: one small Parquet row per "
            f"full solve; the reduced bases' temperature fields are kept there only while the "
            f"run lasts, or with `--keep-fields`, about 320 MB). The tests: "
            + (f"{t['failed']} FAILED, " if t.get("failed") else "")
            + f"{t.get('passed', 0)} passed, {t.get('skipped', 0)} skipped in "
            f"{t['wall_s'] / 60:.0f} min ({t['date']}). Written by "
            "`validation/readme_figures.py` from `validation/results/readme_figures.json`.")


def write(data: dict) -> None:
    text = README.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"README.md has no {BEGIN} ... {END} block")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    wrapped = "\n".join(textwrap.wrap(block(data), width=100, break_on_hyphens=False))
    README.write_text(f"{head}{BEGIN}\n{wrapped}\n{END}{tail}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("step", choices=["measure", "write", "all"])
    p.add_argument("--skip-tests", action="store_true")
    p.add_argument("--skip-reproduce", action="store_true")
    p.add_argument("--tests-from", default=None, metavar="LOG",
                   help="take the test figures from a saved default test run (the log of "
                        "bash .ci/run) instead of running the tests")
    a = p.parse_args()
    data = (measure(a.skip_reproduce, a.skip_tests or bool(a.tests_from))
            if a.step in ("measure", "all") else json.loads(RESULTS.read_text()))
    if a.tests_from:
        data["tests"] = {**tests_from_log(Path(a.tests_from)), "date": str(date.today()),
                         "machine": _machine(), "source": str(a.tests_from)}
        RESULTS.write_text(json.dumps(data, indent=2) + "\n")
    if a.step in ("write", "all"):
        write(data)
    print(block(data))


if __name__ == "__main__":
    main()
