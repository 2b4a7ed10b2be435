"""``itr design`` on the paper's system and on the ZnO example, and ``itr predict`` of a
ZnO formulation held out (issue 63).

1. The paper's system: ``itr identify --example --parametrisation gap`` (all of Table 3, the
   default fidelity ``shipped``), then ``itr design ... --fillers Al2O3,AlN --total 50-65
   --target 2.0``: the cheapest formulation whose measured mean (four samples) reaches 2.0
   W/(m K) with probability 0.95, and its neighbours checked by their own models and full
   solves; and, since nothing in that space reaches 2.0 with 0.95, the same with target 1.8.
2. The ZnO-in-epoxy example (``examples/zno_epoxy``, synthetic measurements from a higher
   fidelity with inputs off their nominal values): identified on ZnO-35 and ZnO-55 only,
   ``itr predict`` of the held-out ZnO-80wt (45.05 vol%) against its two measured samples;
   then the design ``--fillers ZnO --total 35-55 --target 1.2`` on the identification of all
   three.

Resumable: every command's folder is under ``--work`` (default
``validation/results/design_study_runs``, not committed); a finished one is not run again.
Writes ``validation/results/design_study.json``, ``design_study.md`` and the two design
figures (``design_paper.png``, ``design_zno.png``).

    python validation/design_study.py [--work DIR]
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "validation" / "results"
ZNO = ROOT / "examples" / "zno_epoxy"


def _itr(folder: Path, *args: str) -> float | None:
    """Run ``itr ARGS --out folder`` unless ``folder`` holds a finished run; its seconds
    (kept in ``seconds.json`` beside the folders; None for a run finished before that
    file was kept)."""
    times_file = folder.parent / "seconds.json"
    times = json.loads(times_file.read_text()) if times_file.is_file() else {}
    if (folder / "manifest.json").is_file():
        return times.get(folder.name)
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "itr_identify.cli", *args, "--out", str(folder),
                    "--no-progress"], check=True)
    times[folder.name] = time.perf_counter() - t
    times_file.write_text(json.dumps(times, indent=1) + "\n")
    return times[folder.name]


def _minutes(seconds: float | None) -> str:
    return "not timed (an earlier run's)" if seconds is None else f"{seconds / 60:.1f} min"


def _design(folder: Path) -> dict:
    return json.loads((folder / "design.json").read_text())


def paper(work: Path) -> dict:
    store = str(work / "store")
    t_id = _itr(work / "paper_ident", "identify", "--example", "--parametrisation", "gap",
                "--store", store)
    ident = str(work / "paper_ident" / "identified.json")
    t_de = _itr(work / "paper_design", "design", ident, "--fillers", "Al2O3,AlN",
                "--total", "50-65", "--target", "2.0", "--store", store)
    # the command reaches 2.0 nowhere with 0.95 (its best point 0.93): a target the
    # space reaches, chosen after that run, to show a choice and its checks
    t_lo = _itr(work / "paper_design_1.8", "design", ident, "--fillers", "Al2O3,AlN",
                "--total", "50-65", "--target", "1.8", "--store", store)
    shutil.copyfile(work / "paper_design" / "design.png", RESULTS / "design_paper.png")
    shutil.copyfile(work / "paper_design_1.8" / "design.png", RESULTS / "design_paper_1.8.png")
    return {"identify_s": t_id, "design_s": t_de, "design": _design(work / "paper_design"),
            "reachable": {"design_s": t_lo, "design": _design(work / "paper_design_1.8")}}


def zno(work: Path) -> dict:
    store = str(work / "store")
    system = str(ZNO / "system.toml")
    with open(ZNO / "measurements.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    table = work / "zno_without_80wt.csv"
    with open(table, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(r for r in rows if r["formulation"] != "ZnO-80wt")
    t_h = _itr(work / "zno_held_ident", "identify", str(table), "--system", system,
               "--parametrisation", "gap", "--store", store)
    t_p = _itr(work / "zno_held_predict", "predict",
               str(work / "zno_held_ident" / "identified.json"), "ZnO-80wt",
               "--replicates", "2", "--store", store)
    pred = json.loads((work / "zno_held_predict" / "predicted.json").read_text())[
        "predictions"][0]
    measured = float(np.mean([float(r["k_W_per_mK"]) for r in rows
                              if r["formulation"] == "ZnO-80wt"]))
    t_id = _itr(work / "zno_ident", "identify", str(ZNO / "measurements.csv"), "--system",
                system, "--parametrisation", "gap", "--store", store)
    t_de = _itr(work / "zno_design", "design", str(work / "zno_ident" / "identified.json"),
                "--fillers", "ZnO", "--total", "35-55", "--target", "1.2", "--store", store)
    shutil.copyfile(work / "zno_design" / "design.png", RESULTS / "design_zno.png")
    lo, hi = pred["interval"]
    return {"held_out": {"formulation": "ZnO-80wt", "measured_mean": measured,
                         "median": pred["median"], "interval_90": [lo, hi],
                         "inside": bool(lo <= measured <= hi),
                         "identify_s": t_h, "predict_s": t_p},
            "identify_s": t_id, "design_s": t_de, "design": _design(work / "zno_design")}


def _lines(name: str, run: dict) -> list[str]:
    d = run["design"]
    ch = d["choice"]
    out = [f"## {name}", "",
           f"Identification {_minutes(run['identify_s'])}, design {_minutes(run['design_s'])}"
           f" on this machine. Space {d['space']['fillers']} at "
           f"{d['space']['total_vol_pct'][0]:g}-{d['space']['total_vol_pct'][1]:g} vol%, "
           f"anchors {', '.join(d['space']['anchors'])}; target {d['target']:g} W/(m K) "
           f"with probability {d['probability']:g}.", ""]
    if ch is None:
        return out + [f"Nothing in the space reaches the target with probability "
                      f"{d['probability']:g}; the most probable point reaches it with "
                      f"{d['max_probability']:.3f}.", ""]
    out += [f"Chosen: **{ch['formulation']}**, k {ch['median']:.3f} W/(m K) (90 % "
            f"{ch['interval_90'][0]:.3f} - {ch['interval_90'][1]:.3f}), probability "
            f"{ch['probability']:.3f}.", "",
            "| candidate | surrogate k (90 %) | P | own model k (90 %) | its P | full solves k "
            "| inside |", "|---|---|---|---|---|---|---|"]
    for r in d["checks"]:
        out.append(f"| {r['formulation']} | {r['surrogate_median']:.3f} "
                   f"({r['surrogate_interval_90'][0]:.3f} - {r['surrogate_interval_90'][1]:.3f})"
                   f" | {r['surrogate_probability']:.3f} | {r['direct_median']:.3f} "
                   f"({r['direct_interval_90'][0]:.3f} - {r['direct_interval_90'][1]:.3f}) | "
                   f"{r['direct_probability']:.3f} | {r['full_solve_k']:.3f} | "
                   f"{'yes' if r['full_solve_inside'] else '**no**'} |")
    return out + [""]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", default=str(RESULTS / "design_study_runs"))
    args = ap.parse_args(argv)
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    data = {"paper": paper(work), "zno": zno(work)}
    (RESULTS / "design_study.json").write_text(json.dumps(data, indent=2) + "\n")
    h = data["zno"]["held_out"]
    md = ["# `itr design` and `itr predict` studies", "",
          "Times on 2 cores, with the shared store holding the solves of earlier runs of "
          "this study (a first run of the paper's identification and design took about 7 "
          "and 8 min with another job on the same cores).", ""]
    md += _lines("The paper's system (Table 3, gap, fidelity shipped)", data["paper"])
    md += _lines("The paper's system, target 1.8 W/(m K) (chosen after the 2.0 run)",
                 {"identify_s": data["paper"]["identify_s"], **data["paper"]["reachable"]})
    md += _lines("ZnO in epoxy (examples/zno_epoxy)", data["zno"])
    md += [f"ZnO-80wt held out (identified on ZnO-35 and ZnO-55): measured mean "
           f"{h['measured_mean']:.3f}, predicted {h['median']:.3f} (90 % "
           f"{h['interval_90'][0]:.3f} - {h['interval_90'][1]:.3f}): "
           f"{'inside' if h['inside'] else 'OUTSIDE'}.", ""]
    (RESULTS / "design_study.md").write_text("\n".join(md))
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
