"""Issue 48, acceptance 2: the paper's system written as a file gives what the default gives.

Runs ``itr identify --example`` twice in child processes of the installed package, once at
the default system and once with ``--system examples/paper/system.toml``, each in its own
fresh folder and store (nothing shared), and compares the two ``identified.json`` leaf by
leaf: every number to 1e-6 relative (or 1e-12 absolute), every other value equal; the only
leaves allowed to differ are the wall times of the stages (``seconds``) and where each run
says its system came from (``settings.system.source``, a size's ``stated_as``) and the
named formulations the package's tables carry (Table 2 names, which the file does not
repeat: they name the same compositions). Writes
``validation/results/paper_system_file.json`` and ``.md``.

Usage::

    python validation/paper_system_file_check.py [--reuse DEFAULT_DIR FILE_DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "validation" / "results"
RUNS = RESULTS / "paper_system_file_runs"
ITR = [sys.executable, "-m", "itr_identify.cli"]
#: Leaves that say where the system came from, not what it is, and the stages' wall times.
ALLOWED = ("settings.system.source", "settings.system.named_formulations", "size.stated_as",
           "seconds.")
REL, ABS = 1e-6, 1e-12


def leaves(data, prefix=""):
    if isinstance(data, dict):
        for k, v in data.items():
            yield from leaves(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            yield from leaves(v, f"{prefix}[{i}]")
    else:
        yield prefix, data


def differences(a: dict, b: dict) -> tuple[list[str], int, float]:
    """(paths that differ beyond the tolerance, numbers compared, largest relative
    difference)."""
    la, lb = dict(leaves(a)), dict(leaves(b))
    bad, n, worst = [], 0, 0.0
    for path in sorted(set(la) | set(lb)):
        if any(f".{allowed}" in f".{path}." for allowed in ALLOWED):
            continue
        x, y = la.get(path, "<missing>"), lb.get(path, "<missing>")
        if isinstance(x, (int, float)) and isinstance(y, (int, float)) \
                and not isinstance(x, bool):
            n += 1
            if math.isnan(x) and math.isnan(y):
                continue
            rel = abs(x - y) / max(abs(x), abs(y), 1e-300)
            if abs(x - y) > ABS:
                worst = max(worst, rel)
            if rel > REL and abs(x - y) > ABS:
                bad.append(f"{path}: {x!r} vs {y!r}")
        elif x != y:
            bad.append(f"{path}: {x!r} vs {y!r}")
    return bad, n, worst


def run(label: str, extra: list[str]) -> tuple[Path, float]:
    out = RUNS / label
    if out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    proc = subprocess.run([*ITR, "identify", "--example", "--out", str(out), "--no-progress",
                           *extra], cwd=ROOT, capture_output=True, text=True)
    (RUNS / f"{label}.log").write_text(proc.stdout + proc.stderr)
    if proc.returncode:
        raise SystemExit(f"{label}: itr identify failed; see {RUNS / (label + '.log')}")
    return out, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reuse", nargs=2, metavar=("DEFAULT_DIR", "FILE_DIR"), default=None,
                    help="compare two finished output folders instead of running")
    args = ap.parse_args()
    RUNS.mkdir(parents=True, exist_ok=True)
    if args.reuse:
        dirs, walls = [Path(d) for d in args.reuse], [math.nan, math.nan]
    else:
        (d0, w0), (d1, w1) = run("default", []), run(
            "file", ["--system", str(ROOT / "examples" / "paper" / "system.toml")])
        dirs, walls = [d0, d1], [w0, w1]
    a, b = (json.loads((d / "identified.json").read_text()) for d in dirs)
    bad, n, worst = differences(a, b)
    data = {"numbers_compared": n, "largest_relative_difference": worst,
            "differences": bad, "passes": not bad, "wall_s": walls,
            "tolerance": {"relative": REL, "absolute": ABS}, "allowed": list(ALLOWED)}
    (RESULTS / "paper_system_file.json").write_text(json.dumps(data, indent=1) + "\n")
    text = ("# The paper's system as a file (issue 48, acceptance 2)\n\n"
            "`itr identify --example` at the default system and with `--system "
            "examples/paper/system.toml`, each in a fresh folder and store "
            "(`validation/paper_system_file_check.py`): "
            f"{n} numbers of identified.json compared, largest relative difference "
            f"{worst:.2g} (tolerance {REL:g}); "
            + ("every leaf the same but where the system came from." if not bad else
               f"{len(bad)} leaves differ:\n\n" + "\n".join(f"- {x}" for x in bad[:40]))
            + "\n")
    (RESULTS / "paper_system_file.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
