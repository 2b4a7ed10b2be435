"""Simulation-based calibration of the joint posterior (issue 59, acceptance 1).

Truths come from the model itself, the one place where they may (Talts et al. 2018): the
gap parametrisation's forward models of ``itr reproduce`` (Table 3's twelve formulations at
the default fidelity, shipped corrections) are built once; then per draw ``i``

1. every parameter of the joint space (the resistances, the conductivities, the film, the
   per-system offsets and slopes) is drawn from its prior (seed ``SEED + i``);
2. a table is simulated from the likelihood's own generative model: per formulation one
   model error ``k (1 + eta)``, ``eta`` normal with the RVE scatter, the level's own sd and
   the pooled packing sd in quadrature, shared by its replicates, and four replicates about
   it with Table 3's replicate noise (the root-mean-square relative replicate sd of the
   formulation's filler system);
3. the joint posterior is sampled at the defaults (:func:`itr_identify.inference.joint.
   sample`, seed ``i``), and per resistance the rank of the truth among 99 draws thinned
   by the longest autocorrelation time, whether the 90 % interval holds it and
   ln(point / truth) are kept (point and interval as the package quotes them: from the
   resistance's Rao-Blackwell marginal; the quantiles counted from the draws are kept
   beside them).

The ranks of a calibrated machine are uniform on 0..99 (tested by a chi-square over 10
bins); the 90 % intervals hold the truth in 90 % of draws; the point's median log error is
0. Targets (acceptance 1 of issue 59, fixed before the run): coverage 0.85-0.95 for every
resistance, rank uniformity p > 0.01, median ln(point / truth) within +-0.1.

Each draw is written to ``validation/results/sbc_runs/draw_<i>.json`` as it finishes (a
killed run redoes only the missing ones). Writes ``validation/results/sbc.md`` and
``sbc.json``.

Usage::

    python validation/sbc_study.py [--draws 200] [--shard K/N] [--report-only]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "validation" / "results"
RUNS = RESULTS / "sbc_runs"
OUT, OUT_JSON = RESULTS / "sbc.md", RESULTS / "sbc.json"
SEED = 5900
REPLICATES = 4
RANK_DRAWS = 99
TARGET_COVERAGE = (0.85, 0.95)
TARGET_P = 0.01
TARGET_BIAS = 0.1
#: Draws the targets are judged on (acceptance 1 of issue 59).
STUDY_DRAWS = 200
#: The report's title.
TITLE = "Simulation-based calibration of the joint posterior (issue 59)"


#: The tabulated forward models, their priors and the replicate noise, kept after the first
#: build (the build is one identification, minutes; a resumed study reads them; no pickle).
CACHE = RUNS / "likelihood.npz"


def build():
    """The gap identification of Table 3 at the reproduce defaults: its likelihood (tables,
    space, scatter) and the replicate noise per filler system (from :data:`CACHE` where an
    earlier build left it)."""
    from itr_identify.inference.measurements import read_measurements

    meas = read_measurements()
    if not CACHE.exists():
        _build_cache(meas)
    return _from_cache(meas)


def _priors():
    """The reproduce defaults' input priors over the phases of Table 3."""
    from itr_identify.inference.formulations import fractions_of
    from itr_identify.inference.measurements import read_measurements
    from itr_identify.workflows.reproduce import ReproduceSettings

    settings = ReproduceSettings()
    meas = read_measurements()
    system = settings.forward.system
    phases = {system.matrix, *(f for n in meas.formulations for f in fractions_of(n, system))}
    return settings, settings.input_priors(phases)


def _build_cache(meas) -> None:
    from itr_identify.inference.calibrate import pooled_scatter
    from itr_identify.inference.joint import Tabulated
    from itr_identify.inference.pipeline import identify

    settings, inputs = _priors()
    ident = identify(meas, "gap", settings=settings.forward, seed=settings.seed,
                     inputs=inputs, echo=print, floor_check=False)
    tables = {f: Tabulated.of(f, m, ident.inputs["elasticity"].get(f, {}))
              for f, m in ident.models.items()}
    groups: dict[str, list] = {}
    for f, t in tables.items():
        groups.setdefault(t.group, []).append(ident.models[f])
    noise = {}
    for g in groups:
        rel = [np.std(meas.values[f], ddof=1) / np.mean(meas.values[f])
               for f, t in tables.items() if t.group == g]
        noise[g] = float(math.sqrt(np.mean(np.square(rel))))
    arrays, meta = {}, {"priors": sorted(ident.priors), "matrix": settings.forward.system.matrix,
                        "resistance": list(ident.posterior.prior), "noise": noise,
                        "scatter": {g: pooled_scatter(ms) for g, ms in groups.items()},
                        "tables": {}}
    for i, (f, t) in enumerate(tables.items()):
        meta["tables"][f] = {"index": i, "parameters": list(t.parameters),
                             "fractions": t.fractions, "system": t.system,
                             "model_sd": t.model_sd, "rve_scatter": t.rve_scatter,
                             "packing": list(t.packing) if t.packing else None,
                             "elasticity": t.elasticity, "axes": len(t.axes)}
        for j, ax in enumerate(t.axes):
            arrays[f"t{i}_axis{j}"] = ax
        for key in ("log_k", "rel_err", "shared"):
            arrays[f"t{i}_{key}"] = np.asarray(getattr(t, key))
    RUNS.mkdir(parents=True, exist_ok=True)
    tmp = RUNS / ".likelihood.tmp.npz"
    np.savez_compressed(tmp, meta=np.array(json.dumps(meta)), **arrays)
    tmp.replace(CACHE)


def _from_cache(meas):
    from itr_identify.inference.joint import JointLikelihood, JointSpace, Tabulated
    from itr_identify.inference.priors import DEFAULT_MODEL_FORM, ResistancePrior

    with np.load(CACHE, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        tables = {}
        for f, m in meta["tables"].items():
            i = m["index"]
            tables[f] = Tabulated(
                f, tuple(m["parameters"]), m["fractions"],
                tuple(z[f"t{i}_axis{j}"] for j in range(m["axes"])), z[f"t{i}_log_k"],
                z[f"t{i}_rel_err"], z[f"t{i}_shared"], m["system"], m["model_sd"],
                m["rve_scatter"], tuple(m["packing"]) if m["packing"] else None,
                m["elasticity"])
    _, inputs = _priors()
    space = JointSpace.build(tables, matrix=meta["matrix"],
                             resistance=ResistancePrior(*meta["resistance"]),
                             inputs={n: inputs[n] for n in meta["priors"]},
                             model_form=DEFAULT_MODEL_FORM)
    lik = JointLikelihood(tables, meas, space, scatter=meta["scatter"])
    return lik, meta["noise"]


def simulate(lik, noise: dict[str, float], rng: np.random.Generator):
    """A truth drawn from the prior and its table (module notes)."""
    from itr_identify.inference.measurements import Measurements

    space = lik.space
    theta = space.draw(rng, 1)
    cols = space.columns(theta)
    values = {}
    for f, tab in lik.tables.items():
        k = float(lik.conductivities(cols, f)[0][0])
        pack = tab.packing[0] if tab.packing else 0.0
        sd = math.sqrt(lik.scatter[tab.group] ** 2 + tab.model_sd ** 2 + pack ** 2)
        level = k * (1 + sd * rng.standard_normal())
        values[f] = level * (1 + noise[tab.group] * rng.standard_normal(REPLICATES))
    return theta[0], Measurements(values, "simulated")


def one_draw(lik, noise, i: int) -> dict:
    from itr_identify.inference.joint import JointLikelihood, sample, weighted_quantile

    rng = np.random.default_rng(SEED + i)
    truth, meas = simulate(lik, noise, rng)
    lik_i = JointLikelihood(lik.tables, meas, lik.space, scatter=lik.scatter)
    t = time.perf_counter()
    post = sample(lik_i, seed=i)
    out = {"draw": i, "seconds": time.perf_counter() - t, "converged": post.converged,
           "truth": dict(zip(lik.space.names, map(float, truth))), "parameters": {}}
    # independent draws: the importance draws by weight (the chain's, thinned by its
    # longest autocorrelation, where the refinement's weights degenerated)
    rows = post.resample(RANK_DRAWS, seed=i)
    if math.isnan(post.log_evidence):
        thin = max(1, int(math.ceil(max(post.autocorr.values()))))
        idx = np.arange(post.samples.shape[0]).reshape(-1, post.walkers)[::thin].ravel()
        rows = idx[np.linspace(0, idx.size - 1, RANK_DRAWS).astype(int)]
    out["effective_draws"] = post.effective_draws
    for r in post.resistances:
        name = f"log10 {r}"
        pick = post.column(name)[rows]
        x = truth[lik.space.names.index(name)]
        lo, hi = post.interval(r)
        counted = 10 ** weighted_quantile(post.column(name), [0.05, 0.5, 0.95], post.weights)
        out["parameters"][r] = {"rank": int(np.sum(pick < x)), "truth": 10 ** x,
                                "point": post.point(r), "interval_90": [lo, hi],
                                "counted_from_draws": counted.tolist(),
                                "covered": bool(lo <= 10 ** x <= hi),
                                "log_error": math.log(post.point(r) / 10 ** x)}
    return out


def report() -> dict:
    from scipy import stats

    rows = [json.loads(p.read_text()) for p in sorted(RUNS.glob("draw_*.json"))]
    if not rows:
        return {}
    summary = {"draws": len(rows), "study_draws": STUDY_DRAWS,
               "converged": sum(r["converged"] for r in rows),
               "seconds_per_draw": float(np.mean([r["seconds"] for r in rows])),
               "parameters": {}}
    lines = [f"# {TITLE}", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             f"{len(rows)} draws ({summary['converged']} converged by the sampler's rule; "
             f"{summary['seconds_per_draw']:.0f} s of sampling per draw on 2 cores)"
             + (f"; INTERIM: {len(rows)} of the {STUDY_DRAWS} draws the targets are judged on "
                "(the study resumes where it stopped)" if len(rows) < STUDY_DRAWS else "")
             + ".", "",
             "| resistance | coverage of the 90 % interval | rank uniformity (chi-square, 10 "
             "bins) | median ln(point / truth) | targets |", "|---|---|---|---|---|"]
    for r in rows[0]["parameters"]:
        ranks = np.array([x["parameters"][r]["rank"] for x in rows])
        counts, _ = np.histogram(ranks, bins=10, range=(0, RANK_DRAWS + 1))
        chi2 = float(np.sum((counts - counts.mean()) ** 2 / counts.mean()))
        p = float(stats.chi2.sf(chi2, 9))
        cov = float(np.mean([x["parameters"][r]["covered"] for x in rows]))
        bias = float(np.median([x["parameters"][r]["log_error"] for x in rows]))
        ok = (TARGET_COVERAGE[0] <= cov <= TARGET_COVERAGE[1] and p > TARGET_P
              and abs(bias) <= TARGET_BIAS)
        summary["parameters"][r] = {"coverage": cov, "rank_chi2": chi2, "rank_p": p,
                                    "rank_counts": counts.tolist(), "median_log_error": bias,
                                    "meets_targets": ok}
        lines.append(f"| {r} | {cov:.3f} | chi-square {chi2:.1f} on 9, p {p:.3f} (counts "
                     f"{', '.join(map(str, counts))}) | {bias:+.3f} | "
                     f"{'met' if ok else 'MISSED'} |")
    OUT.write_text("\n".join(lines) + "\n")
    OUT_JSON.write_text(json.dumps(summary, indent=1) + "\n")
    print(f"wrote {OUT}")
    return summary


def _name_study(name: str) -> None:
    """Point the study's folders and report at ``name`` (module notes), its likelihood the
    first study's cached one (the model is the same; only the sampler is under test)."""
    import shutil

    global RUNS, OUT, OUT_JSON, CACHE, TITLE
    first = CACHE
    RUNS = RESULTS / f"sbc_runs_{name}"
    OUT, OUT_JSON = RESULTS / f"sbc_{name}.md", RESULTS / f"sbc_{name}.json"
    CACHE = RUNS / "likelihood.npz"
    TITLE = f"{TITLE}, study {name}"
    if first.exists() and not CACHE.exists():
        RUNS.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(first, CACHE)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=200)
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--shard", default="0/1",
                    help="K/N: only the draws i with i %% N == K (one process per core)")
    ap.add_argument("--name", default="",
                    help="a study of its own beside the first: its draws in sbc_runs_NAME/, "
                         "its report sbc_NAME.md (the tables of the first study's cache); "
                         "e.g. issue61 for the sampler that stops at its importance draws")
    args = ap.parse_args()
    if args.name:
        _name_study(args.name)
    k, n = (int(x) for x in args.shard.split("/"))
    if not args.report_only:
        RUNS.mkdir(parents=True, exist_ok=True)
        todo = [i for i in range(args.draws) if i % n == k
                and not (RUNS / f"draw_{i:03d}.json").exists()]
        if todo:
            lik, noise = build()
            for i in todo:
                row = one_draw(lik, noise, i)
                tmp = RUNS / f".draw_{i:03d}.json.tmp"
                tmp.write_text(json.dumps(row) + "\n")
                tmp.replace(RUNS / f"draw_{i:03d}.json")
                print(f"draw {i}: " + ", ".join(
                    f"{r} rank {v['rank']} covered {v['covered']}"
                    for r, v in row["parameters"].items()), flush=True)
    report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
