"""The README's figures of the main job and the tests, measured and written by script.

``python validation/readme_figures.py measure`` runs the README's main job (``itr reproduce``
at its defaults, in a new temporary folder, nothing reused) and the default test run
(``python -m pytest -q``), each in a child process of the installed package, and records
wall time, the child's peak resident memory, the output folder's size by part and the test
counts in ``validation/results/readme_figures.json``. ``python validation/readme_figures.py
write`` puts those numbers into README.md between the markers ``<!-- readme-figures -->``
and ``<!-- /readme-figures -->``, and the figures of the result files the documentation
quotes between markers in its pages: issue 47's (the shipped data's headline, the box study,
the contact films, the recovery) in docs/reproduce.md between ``<!-- result-figures -->``
and ``<!-- /result-figures -->``, issue 48's (the paper's system as a file, the second
system) in docs/own_system.md between ``<!-- system-figures -->`` and
``<!-- /system-figures -->``, and issue 49's (the discrepancy workflow's naming rule and
Table 3's verdict) in docs/discrepancy.md between ``<!-- discrepancy-figures -->`` and
``<!-- /discrepancy-figures -->``, and issue 63's (``itr solve`` on images; ``itr predict``'s
leave-one-formulation-out and ``itr design``) in docs/images.md and docs/predict_design.md
between ``<!-- image-figures -->`` and ``<!-- predict-figures -->`` markers; nothing there is
typed by hand (``BLOCKS`` lists each
file and its markers). ``all`` does both.
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
RESULTS_BEGIN, RESULTS_END = "<!-- result-figures -->", "<!-- /result-figures -->"
SYSTEM_BEGIN, SYSTEM_END = "<!-- system-figures -->", "<!-- /system-figures -->"
DISCREPANCY_BEGIN, DISCREPANCY_END = ("<!-- discrepancy-figures -->",
                                      "<!-- /discrepancy-figures -->")
IMAGES_BEGIN, IMAGES_END = "<!-- image-figures -->", "<!-- /image-figures -->"
PREDICT_BEGIN, PREDICT_END = "<!-- predict-figures -->", "<!-- /predict-figures -->"
DOCS = ROOT / "docs"
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


def reproduce_from_log(path: Path, out: Path | None) -> dict:
    """The main job's figures from a saved ``bash .ci/run`` log: the wall time of README
    command 1 (a fresh venv, ``pip install .`` and ``itr reproduce``: what a new user waits
    for), the sizes of its output folder ``out`` where given; no peak memory (CI does not
    measure it)."""
    text = Path(path).read_text(errors="replace")
    took = re.findall(r"== command 1 took (\d+) s", text)
    if not took:
        raise SystemExit(f"{path}: no '== command 1 took N s' line")
    sizes = _sizes(out) if out is not None and out.is_dir() else {}
    return {"wall_s": float(took[-1]), "peak_gb": None, "fresh_install": True, **sizes,
            "source": str(path)}


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
    run = (f"README command 1 (a fresh venv, `pip install .` and `itr reproduce`) "
           f"{r['wall_s'] / 60:.1f} min {r.get('where', 'in CI')} (peak memory not measured "
           "there)"
           if r.get("fresh_install") else
           f"`itr reproduce` {r['wall_s'] / 60:.1f} min and {r['peak_gb']:.2f} GB peak")
    return (f"On {r['machine']} (no GPU, {r['date']}): {run}; it writes "
            f"{r['files_mb']:.0f} MB in {r['files']} files plus its solve store "
            f"`itr-reproduce/solves/` ({r['solves_mb']:.0f} MB: one small Parquet row per "
            f"full solve; the reduced bases' temperature fields are kept there only while the "
            f"run lasts, or with `--keep-fields`, about 320 MB). The tests (README command 2, "
            "the fast tier; .ci/run then runs the rest, `pytest -m slow`): "
            + (f"{t['failed']} FAILED, " if t.get("failed") else "")
            + f"{t.get('passed', 0)} passed, {t.get('skipped', 0)} skipped in "
            f"{t['wall_s'] / 60:.1f} min{' ' + t['where'] if t.get('where') else ''} "
            f"({t['date']}). Written by "
            "`validation/readme_figures.py` from `validation/results/readme_figures.json`.")


def _json(name: str) -> dict | None:
    path = RESULTS.parent / name
    return json.loads(path.read_text()) if path.exists() else None


#: The truths of validation/input_recovery_study.py (ten noise seeds each).
RECOVERY_TRUTHS = 6


def _text(name: str) -> str | None:
    """The first line of a result file, without its full stop."""
    path = RESULTS.parent / name
    return path.read_text().splitlines()[0].rstrip(".") if path.exists() else None


def _interval_line(name: str, e: dict) -> str:
    lo, hi = e["interval_90"]
    out = f"{name} {e['best']:.2e} (90 % {lo:.2e} - {hi:.2e}; {e['flag']}"
    if "interval_90_nominal_inputs" in e:
        a, b = e["interval_90_nominal_inputs"]
        out += (f"; at the nominal inputs {e.get('best_nominal_inputs', float('nan')):.2e}, "
                f"{a:.2e} - {b:.2e}")
    if e.get("narrow_first"):
        nf = e["narrow_first"]
        out += (f"; measuring {nf['input']} would leave {nf['interval'][0]:.2e} - "
                f"{nf['interval'][1]:.2e}")
    return out + ")"


def results_block() -> str:
    """The README's figures of issue 47's studies, from their result files: the shipped
    data's headline (``reproduce_identified.json``), the box study, the contact-film table
    and the recovery against truths that do not share the model."""
    parts = []
    ident = _json("reproduce_identified.json")
    if ident:
        h = ident["headline"]
        fit = {**h.get("fit", {}).get("gap", {}), **ident.get("gap", {}).get("fit", {})}
        lofo = {p: ident[p].get("leave_one_out", []) for p in ("gap", "area") if p in ident}
        parts.append(
            "`itr reproduce` on Table 3 (`validation/results/reproduce.md`, "
            + (_text("reproduce_wall.txt") or "as CI last ran it") + "): "
            "gap " + "; ".join(_interval_line(n, e) for n, e in h["parameters"]["gap"].items())
            + (f". The gap fit's test with the inputs free within their priors (no model "
               f"form): chi-square {fit['chi2']:.1f} on {fit['dof']} dof (p {fit['p']:.2g}); "
               f"at the quoted values with the stated inputs {fit['stated']['chi2']:.1f} "
               f"without the model form, {fit['stated']['chi2_with']:.1f} with its prior "
               "variance"
               if fit and "stated" in fit else
               f". The gap fit: chi-square {fit['chi2']:.1f} on {fit['dof']} dof (p "
               f"{fit['p']:.2g}), model-form error {100 * fit['model_form_sd']:.1f} % of k"
               if fit else "")
            + ". Table 6 at the quoted values (full solves, the stated inputs), measured "
            "mean inside the 90 % posterior predictive interval: "
            + ", ".join(f"{p} {sum(bool(r.get('inside')) for r in ident[p]['validation'])} of "
                        f"{len(ident[p]['validation'])}" for p in ("gap", "area")
                        if ident.get(p, {}).get("validation"))
            + ". Leave-one-formulation-out, measured mean inside the 90 % predictive "
            "interval: " + ", ".join(f"{p} {sum(r['inside'] for r in rows)} of {len(rows)}"
                                     for p, rows in lofo.items() if rows) + ".")
    sbc = _json("sbc.json")
    if sbc and sbc.get("parameters"):
        parts.append(
            f"Simulation-based calibration (`sbc.md`, {sbc['draws']} draws from the priors, "
            "Table 3's replicate noise"
            + (f"; INTERIM, {sbc['draws']} of the {sbc['study_draws']} draws the targets are "
               "judged on, the study resumes where it stopped"
               if sbc["draws"] < sbc.get("study_draws", 0) else "")
            + "): " + "; ".join(
                f"{r} coverage of the 90 % interval {d['coverage']:.2f}, rank uniformity p "
                f"{d['rank_p']:.2f}, median ln(point / truth) {d['median_log_error']:+.3f}"
                for r, d in sbc["parameters"].items()) + ".")
    conv = _json("joint_convergence.json")
    if conv and conv.get("largest_move") is not None:
        parts.append(f"The sampler: doubling the chain moves an interval end by at most "
                     f"{100 * conv['largest_move']:.1f} % (`joint_convergence.md`).")
    shipped = _json("shipped_corrections.json")
    if shipped:
        rows = []
        for name, s in shipped["systems"].items():
            b = s["shared"]["box"]
            steps = ", ".join(f"{st['from_um']:g}->{st['to_um']:g} um {100 * st['rel']:+.2f} %"
                              for st in b["steps"])
            bias = ", ".join(f"{100 * q['bias']:+.1f} %" for q in s["shared"]["voxel"]["points"])
            orders = ", ".join(f"{q['order']:.2f} ({q['order_interval'][0]:.2f}-"
                               f"{q['order_interval'][1]:.2f})"
                               for q in s["shared"]["voxel"]["points"])
            rows.append(f"{name}: {steps}, converged at {b['converged_um']:g} um (table "
                        f"{b['table_box_um']:g} um, x{b['factor']:.4f}); voxel order {orders}, "
                        f"bias of 0.25 um {bias} over the design's resistances")
        parts.append("Shipped corrections (`shipped_corrections.md`; box studies with 6 "
                     "packings per box, the stated film): " + "; ".join(rows) + ".")
    film = _json("contact_film.json")
    if film:
        ratios = [sum(r["cheap_5nm"]) / sum(r["cheap_0nm"]) for r in film["rows"].values()
                  if r.get("cheap_5nm") and r.get("cheap_0nm")]
        if ratios:
            parts.append(f"A 5 nm contact film lowers k of the cheap RVE by "
                         f"{100 * (1 - max(ratios)):.1f}-{100 * (1 - min(ratios)):.1f} % "
                         f"across the {len(ratios)} formulations (`contact_film.md`).")
    rec, joint = _json("input_recovery_joint.json"), True
    if not rec:
        rec, joint = _json("input_recovery.json"), False
    if rec:
        rows = [f"{name}: {p} {d['covered']} of {d['seeds']}, best "
                f"{d['best_geomean'] / d['truth']:.2f} x the truth"
                + ("" if d["passes"] else " (MISSES acceptance)")
                for name, t in rec.items() for p, d in t["parameters"].items()]
        parts.append("Recovery against truths that do not share the model (`"
                     + ("input_recovery_joint.md`, the joint posterior" if joint else
                        "input_recovery.md`, the earlier marginalisation")
                     + "; 90 % intervals holding the truth over noise seeds, the geometric "
                     "mean of the best values"
                     + ("; INTERIM, the study resumes where it stopped" if joint and (
                         len(rec) < RECOVERY_TRUTHS or any(
                             d["seeds"] < 10 for t in rec.values()
                             for d in t["parameters"].values())) else "")
                     + "): " + "; ".join(rows) + ".")
    return " ".join(parts) + " Written by `validation/readme_figures.py` from those files."


def system_block() -> str:
    """The README's figures of issue 48: the paper's system as a file against the default
    (``paper_system_file.json``) and the second system end to end (``second_system.json``)."""
    parts = []
    same = _json("paper_system_file.json")
    if same:
        parts.append(
            "with `--system examples/paper/system.toml`, `itr identify --example` gives the "
            f"default's identified.json: {same['numbers_compared']} numbers, largest relative "
            f"difference {same['largest_relative_difference']:.2g}"
            + ("" if same["passes"] else f" ({len(same['differences'])} leaves DIFFER)")
            + " (`validation/results/paper_system_file.md`).")
    second = _json("second_system.json")
    if second:
        rows = []
        for name, r in second["runs"].items():
            e = r["parameters"].get("gap")
            if e:
                lo, hi = e["interval_90"]
                rows.append(f"{name}: {r['wall_s'] / 60:.1f} min, R_ZnO_epoxy 90 % "
                            f"{lo:.2e} - {hi:.2e} ({e['flag']}; "
                            f"{'holds' if e['holds_truth'] else 'MISSES'} the truth "
                            f"{second['truth_R_ZnO_epoxy']:.0e})")
        parts.append(f"ZnO in epoxy on {second['machine']} (`validation/results/"
                     f"second_system.md`, gap parametrisation): " + "; ".join(rows)
                     + f"; building the system's corrections table took "
                     f"{second['corrections_build_s'] / 60:.1f} min.")
    return " ".join(parts) + " Written by `validation/readme_figures.py` from those files."


def discrepancy_block() -> str:
    """The README's figures of issue 49: the naming rule's false-naming rate and power on
    truths the workflow does not share (``discrepancy_calibration.json``) and Table 3's
    verdict at the default settings (``discrepancy.json``)."""
    parts = []
    cal = _json("discrepancy_calibration.json")
    if cal:
        s = cal["summary"]
        study = {c: v for c, v in s["power"].items()}
        powers = "; ".join(f"{c} " + ", ".join(f"{size} {share:.0%}"
                                                for size, share in p.items())
                           for c, p in study.items())
        parts.append(
            f"On truths the workflow does not share (28 um / 0.2 um, other packings, effects "
            f"built with the public API; the base at the `standard` level the truths' box "
            f"matches), an effect was named on {s['false_named']} of {s['test_tables']} "
            f"noise-only tables ({s['false_naming_rate']:.0%}; target at most 5 %), the "
            f"base model's chi-square per degree of freedom there was "
            f"{s['null_chi_square_over_dof']:.2f}, and {s['effects_named_at_study_size']} of "
            f"7 library effects were named with the truth inside the 90 % interval at their "
            f"study size in at least half of 10 noise seeds (target 6). Share of seeds "
            f"naming it with the truth inside, by size: {powers} "
            "(`validation/results/discrepancy_calibration.md`).")
    t3 = _json("discrepancy.json")
    if t3 and t3.get("threshold"):
        base = t3["base"]["parameters"]
        rs = ", ".join(f"{k} {v:.2g}" for k, v in base.items() if k.startswith("R_"))
        head = (_json("reproduce_identified.json") or {}).get("headline", {}).get(
            "parameters", {}).get("gap", {})
        nominal = ", ".join(f"{k} {v['best_nominal_inputs']:.2g}" for k, v in head.items()
                            if "best_nominal_inputs" in v)
        parts.append(
            f"On Table 3 at the default (shipped) level: **{t3['verdict']}**"
            + (f" ({t3['winner_name']})" if t3.get("winner_name") else "")
            + f", base chi-square {t3['base']['chi_square']:.1f} on {t3['base']['dof']} "
            f"dof, base resistances {rs} m^2 K/W"
            + (f" (the headline's at nominal inputs: {nominal})" if nominal else "")
            + f", naming threshold {t3['threshold']['log_bayes_factor']:.2f} "
            f"(`validation/results/discrepancy.md`).")
    return " ".join(parts) + " Written by `validation/readme_figures.py` from those files."


def image_block() -> str:
    """docs/images.md's figures of issue 63 (``image_solve.json``)."""
    d = _json("image_solve.json")
    if not d:
        return "Not measured yet."
    api = d["api_vs_cli"]
    worst = max(v["max_abs_difference"] for v in api.values())
    arrays = "; ".join(f"{a['lattice'].upper()} {a['n']}^3 {a['k_image_W_per_mK']:.4f} against "
                       f"{a['k_multipole_W_per_mK']:.4f} ({a['difference_percent']:+.2f} %)"
                       for a in d["sphere_arrays"])
    trips = d["round_trips"]["formats"]
    same = all(v["labels_identical"] for v in trips.values())
    rt = max(v["max_abs_difference"] for v in trips.values())
    return (f"`validation/image_solve_study.py` (`validation/results/image_solve.json`): TIFFs "
            f"written by tifffile (ImageJ metadata) solved by `itr solve` against "
            f"`itr_fv.homogenize` on the same labels: largest difference {worst:.1g} W/(m K) "
            f"over {len(api)} cases, the same iterations. Sphere arrays as label images (f = "
            f"0.4, silicone and Al2O3, R = 2e-7 m^2 K/W) against the multipole reference: "
            f"{arrays} W/(m K). One volume written and read in each of "
            f"{', '.join(k.lstrip('.') for k in trips)}: labels "
            f"{'identical' if same else 'DIFFER'}, largest tensor difference {rt:.1g}. "
            "Written by `validation/readme_figures.py` from that file.")


def predict_block() -> str:
    """docs/predict_design.md's figures of issue 63 (``predict_loo.json``,
    ``design_study.json``)."""
    parts = []
    loo = _json("predict_loo.json")
    if loo:
        outside = ", ".join(f"{r['formulation']} ({r['measured_mean']:.3f} against "
                            f"{r['interval_90'][0]:.3f} - {r['interval_90'][1]:.3f})"
                            for r in loo["rows"] if not r["inside"])
        err = [abs(r["error_pct"]) for r in loo["rows"]]
        parts.append(f"Leave-one-formulation-out on Table 3 (`itr identify` of the gap "
                     f"parametrisation on eleven formulations at the shipped level, `itr "
                     f"predict` of the twelfth): **{loo['inside']} of {loo['of']}** measured "
                     f"means inside their 90 % predictive intervals (acceptance: "
                     f"{loo['required_inside']})" + (f"; outside: {outside}" if outside else "")
                     + f"; median error {sorted(err)[len(err) // 2]:.1f} %, largest "
                     f"{max(err):.1f} % (`validation/results/predict_loo.md`).")
    st = _json("design_study.json")
    if st:
        runs = [("the paper's system", st["paper"])]
        if "reachable" in st["paper"]:
            runs.append(("the paper's system (a second target, chosen after the first run)",
                         {"identify_s": st["paper"]["identify_s"],
                          **st["paper"]["reachable"]}))
        for name, run in runs + [("the ZnO example", st["zno"])]:
            d, ch = run["design"], run["design"]["choice"]
            if ch is None:
                parts.append(f"Design on {name} ({', '.join(d['space']['fillers'])}, "
                             f"{d['space']['total_vol_pct'][0]:g}-"
                             f"{d['space']['total_vol_pct'][1]:g} vol%, target "
                             f"{d['target']:g} W/(m K) with probability {d['probability']:g}): "
                             f"no formulation reaches it; the most probable point reaches it "
                             f"with {d['max_probability']:.2f}.")
                continue
            checks = "; ".join(f"{c['formulation']} full solves {c['full_solve_k']:.3f} "
                               f"{'inside' if c['full_solve_inside'] else 'OUTSIDE'} "
                               f"{c['surrogate_interval_90'][0]:.3f} - "
                               f"{c['surrogate_interval_90'][1]:.3f}, own model "
                               f"P = {c['direct_probability']:.2f}" for c in d["checks"])
            parts.append(f"Design on {name} ({', '.join(d['space']['fillers'])}, "
                         f"{d['space']['total_vol_pct'][0]:g}-{d['space']['total_vol_pct'][1]:g}"
                         f" vol%, target {d['target']:g} W/(m K) with probability "
                         f"{d['probability']:g}): **{ch['formulation']}**, k {ch['median']:.3f} "
                         f"(90 % {ch['interval_90'][0]:.3f} - {ch['interval_90'][1]:.3f}), "
                         f"P = {ch['probability']:.3f}; checks: {checks}"
                         + (f"; design {run['design_s'] / 60:.1f} min on 2 cores"
                            if run.get("design_s") else "") + ".")
        h = st["zno"]["held_out"]
        parts.append(f"ZnO-80wt held out of the ZnO example (identified on ZnO-35 and "
                     f"ZnO-55): measured mean {h['measured_mean']:.3f}, predicted "
                     f"{h['median']:.3f} (90 % {h['interval_90'][0]:.3f} - "
                     f"{h['interval_90'][1]:.3f}): {'inside' if h['inside'] else 'OUTSIDE'} "
                     "(`validation/results/design_study.md`).")
    if not parts:
        return "Not measured yet."
    return " ".join(parts) + " Written by `validation/readme_figures.py` from those files."


def _replace(path: Path, begin: str, end: str, text: str) -> None:
    doc = path.read_text()
    if begin not in doc or end not in doc:
        raise SystemExit(f"{path.name} has no {begin} ... {end} block")
    head, rest = doc.split(begin, 1)
    _, tail = rest.split(end, 1)
    wrapped = "\n".join(textwrap.wrap(text, width=100, break_on_hyphens=False))
    path.write_text(f"{head}{begin}\n{wrapped}\n{end}{tail}")


#: Each written block: the file that holds it, its markers, and what writes its text (the
#: README keeps the main job's and the tests' figures; the studies' figures are in the pages
#: of docs/ that explain them).
BLOCKS = [
    (README, BEGIN, END, block),
    (DOCS / "reproduce.md", RESULTS_BEGIN, RESULTS_END, lambda data: results_block()),
    (DOCS / "own_system.md", SYSTEM_BEGIN, SYSTEM_END, lambda data: system_block()),
    (DOCS / "discrepancy.md", DISCREPANCY_BEGIN, DISCREPANCY_END,
     lambda data: discrepancy_block()),
    (DOCS / "images.md", IMAGES_BEGIN, IMAGES_END, lambda data: image_block()),
    (DOCS / "predict_design.md", PREDICT_BEGIN, PREDICT_END, lambda data: predict_block()),
]


def write(data: dict) -> None:
    for path, begin, end, text in BLOCKS:
        _replace(path, begin, end, text(data))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("step", choices=["measure", "write", "all"])
    p.add_argument("--skip-tests", action="store_true")
    p.add_argument("--skip-reproduce", action="store_true")
    p.add_argument("--tests-from", default=None, metavar="LOG",
                   help="take the test figures from a saved default test run (the log of "
                        "bash .ci/run) instead of running the tests")
    p.add_argument("--tests-where", default=None,
                   help="with --tests-from: where that run ran, in words")
    p.add_argument("--reproduce-from", default=None, metavar="LOG",
                   help="take the main job's wall time from a saved log of bash .ci/run "
                        "(README command 1) instead of running it")
    p.add_argument("--reproduce-out", default=None, metavar="DIR",
                   help="with --reproduce-from: that run's itr-reproduce folder (its sizes)")
    p.add_argument("--reproduce-where", default="in CI",
                   help="with --reproduce-from: where that run ran, in words")
    a = p.parse_args()
    data = (measure(a.skip_reproduce or bool(a.reproduce_from),
                    a.skip_tests or bool(a.tests_from))
            if a.step in ("measure", "all") else json.loads(RESULTS.read_text()))
    if a.reproduce_from:
        data["reproduce"] = {**reproduce_from_log(
            Path(a.reproduce_from), Path(a.reproduce_out) if a.reproduce_out else None),
            "date": str(date.today()), "machine": _machine(), "where": a.reproduce_where}
        RESULTS.write_text(json.dumps(data, indent=2) + "\n")
    if a.tests_from:
        data["tests"] = {**tests_from_log(Path(a.tests_from)), "date": str(date.today()),
                         "machine": _machine(), "source": str(a.tests_from),
                         **({"where": a.tests_where} if a.tests_where else {})}
        RESULTS.write_text(json.dumps(data, indent=2) + "\n")
    if a.step in ("write", "all"):
        write(data)
    print(block(data))


if __name__ == "__main__":
    main()
