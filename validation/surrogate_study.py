"""Surrogate study (issue 11): every model against held-out full solves, the precision check,
the cost of each model in full solves.

Data: two campaigns on the same two RVE replicas of Al2O3-60 (16 um box, 0.2 um voxels,
gap contact model), run on a Dask LocalCluster by ``itr campaign run``:

- ``validation/campaigns/surrogate-train.toml``: the paper's Table 4 grid (k_Al2O3 x
  R_Al2O3_silicone, 40 sets per RVE, 80 full solves): the training set of the prototype
  model and of the baselines;
- ``validation/campaigns/surrogate-test.toml``: 30 sets per RVE drawn log-uniformly in R and
  uniformly in k over the same box (60 full solves): held out from every model.

Models: the prototypical-function model (:mod:`itr_surrogate.prototype`), XGBoost, SVR and an
MLP (:mod:`itr_surrogate.baselines`), all on k_iso (the mean of the diagonal) per row; and the
reduced basis (:mod:`itr_surrogate.reduced_basis`) of replica 0's RVE, which makes its own full
solves (at most 40) and is compared entry by entry with the held-out solves of that RVE.

    python validation/surrogate_study.py                       # runs both campaigns first
    python validation/surrogate_study.py --train DIR --test DIR  # reuse finished campaigns

Writes validation/results/surrogate.md, surrogate.json, surrogate_parity.png and
surrogate_precision.png.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from itr_fv import homogenize
from itr_fv.discrete.problem import DiscreteProblem
from itr_fv.io import write_text
from itr_surrogate.baselines import (
    BASELINES,
    make_baseline,
    max_relative_error,
    precision_check,
    r2_score,
)
from itr_surrogate.campaign import Campaign
from itr_surrogate.prototype import PrototypeRegressor
from itr_surrogate.reduced_basis import ReducedBasis
from itr_surrogate.runner import build_rve, run_campaign
from itr_surrogate.store import CampaignStore

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
FEATURES = ["k_Al2O3", "R_Al2O3_silicone"]
BOUNDS = {"k_Al2O3": (20.0, 40.0), "R_Al2O3_silicone": (1e-8, 5e-5)}
PRECISION_VALUES = np.linspace(2.0e-8, 2.9e-8, 10)  # the paper's check, inside [1e-8, 5e-8]
PRECISION_BASE = {"k_Al2O3": 30.0}
LABELS = {"prototype": "prototypical functions", "xgboost": "XGBoost", "svr": "SVR",
          "mlp": "MLP (ANN)", "reduced_basis": "reduced basis (replica 0's RVE)"}


def campaign_rows(folder: Path) -> dict[str, np.ndarray]:
    table = CampaignStore(folder).results()
    cols = {name: np.asarray(table.column(name).to_numpy()) for name in
            ["replica", "k_Al2O3", "R_Al2O3_silicone", "k_xx", "k_yy", "k_zz", "k_iso"]}
    cols["X"] = np.column_stack([cols["k_Al2O3"], cols["R_Al2O3_silicone"]])
    return cols


def ensure_campaign(toml: Path, folder: Path | None, work: Path) -> Path:
    if folder is not None:
        return folder
    out = work / toml.stem
    run_campaign(Campaign.from_toml(toml), out, workers=2)
    return out


def fit_regressors(train: dict, test: dict) -> dict[str, dict]:
    out = {}
    models = {"prototype": PrototypeRegressor(feature_names=FEATURES)}
    models.update({n: make_baseline(n, feature_names=FEATURES, seed=0) for n in BASELINES})
    big = np.column_stack([np.random.default_rng(0).uniform(20, 40, 100_000),
                           10 ** np.random.default_rng(1).uniform(-8, np.log10(5e-5), 100_000)])
    for name, model in models.items():
        t0 = time.perf_counter()
        model.fit(train["X"], train["k_iso"])
        fit_s = time.perf_counter() - t0
        pred = model.predict(test["X"])
        t0 = time.perf_counter()
        model.predict(big)
        rate = big.shape[0] / (time.perf_counter() - t0)
        check = precision_check(model.predict, feature_names=FEATURES, base=PRECISION_BASE,
                                feature="R_Al2O3_silicone", values=PRECISION_VALUES)
        out[name] = {"model": model, "pred": np.asarray(pred, dtype=np.float64),
                     "r2": r2_score(test["k_iso"], pred),
                     "max_rel": max_relative_error(test["k_iso"], pred),
                     "r2_train": r2_score(train["k_iso"], model.predict(train["X"])),
                     "fit_s": fit_s, "rows_per_s": rate, "precision": check,
                     "full_solves": int(train["X"].shape[0])}
    out["prototype"]["expression"] = models["prototype"].to_expression()
    return out


def fit_reduced_basis(train_folder: Path, test: dict, *, tol: float, max_solves: int) -> dict:
    camp = CampaignStore(train_folder).campaign()
    ms = build_rve(camp, "Al2O3-60", 0)
    problem = DiscreteProblem(ms, contact=camp.contact)
    mat = camp.materials({"k_Al2O3": 30.0, "R_Al2O3_silicone": 1e-7})
    rb = ReducedBasis(problem, mat, BOUNDS, tol=tol, max_solves=max_solves, solver="fft",
                      solver_tol=1e-9, progress=True).fit()
    rows = test["replica"] == 0
    sets = {"k_Al2O3": test["k_Al2O3"][rows], "R_Al2O3_silicone": test["R_Al2O3_silicone"][rows]}
    K = rb.predict(sets)
    diag = np.diagonal(K, axis1=1, axis2=2)
    truth = np.column_stack([test["k_xx"][rows], test["k_yy"][rows], test["k_zz"][rows]])
    err = np.abs(diag - truth)
    est = rb.error_estimate(sets)
    rng = np.random.default_rng(2)
    n = 100_000
    many = {"k_Al2O3": rng.uniform(20, 40, n),
            "R_Al2O3_silicone": 10 ** rng.uniform(-8, np.log10(5e-5), n)}
    rb.predict({k: v[:1000] for k, v in many.items()})  # compile once
    t0 = time.perf_counter()
    rb.predict(many)
    rate = n / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    rb.error_estimate(many)
    est_rate = n / (time.perf_counter() - t0)
    all_sets = {"k_Al2O3": test["k_Al2O3"], "R_Al2O3_silicone": test["R_Al2O3_silicone"]}
    k_iso_all = np.trace(rb.predict(all_sets), axis1=1, axis2=2) / 3.0

    def rb_k_iso(X):
        return np.trace(rb.predict({"k_Al2O3": X[:, 0], "R_Al2O3_silicone": X[:, 1]}),
                        axis1=1, axis2=2) / 3.0

    check = precision_check(rb_k_iso, feature_names=FEATURES, base=PRECISION_BASE,
                            feature="R_Al2O3_silicone", values=PRECISION_VALUES)
    ends = []
    for r in (PRECISION_VALUES[0], PRECISION_VALUES[-1]):
        res = homogenize(problem, mat.with_parameters({"k_Al2O3": 30.0,
                                                       "R_Al2O3_silicone": float(r)}),
                         solver="fft", tol=1e-9)
        ends.append(float(np.trace(res.k_eff_energy) / 3.0))
    rb.save(RESULTS / "surrogate_reduced_basis.npz")
    return {"rb": rb, "rel_err": err / truth, "bounded": float(np.mean(err <= est)),
            "est_over_err": est / np.maximum(err, 1e-300), "rate": rate, "est_rate": est_rate,
            "pred_same_rve": np.trace(K, axis1=1, axis2=2) / 3.0, "rows": rows,
            "pred": k_iso_all, "r2": r2_score(test["k_iso"], k_iso_all),
            "max_rel": max_relative_error(test["k_iso"], k_iso_all),
            "r2_same_rve": r2_score(test["k_iso"][rows], np.trace(K, axis1=1, axis2=2) / 3.0),
            "max_rel_same_rve": float((err / truth).max()),
            "precision": check, "precision_truth": (ends[1] - ends[0]) / ends[0],
            "full_solves": rb.n_solves_}


def parity_figure(test: dict, reg: dict, rb: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ["prototype", *BASELINES, "reduced_basis"]
    fig, axes = plt.subplots(1, len(names), figsize=(3.3 * len(names), 3.4))
    lo, hi = test["k_iso"].min() * 0.9, test["k_iso"].max() * 1.1
    for ax, name in zip(axes, names):
        entry = rb if name == "reduced_basis" else reg[name]
        for rep, marker in ((0, "o"), (1, "s")):
            sel = test["replica"] == rep
            ax.loglog(test["k_iso"][sel], entry["pred"][sel], marker, ms=4, mfc="none",
                      label=f"RVE replica {rep}")
        ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
        ax.set_title(f"{LABELS[name]}\nR2 = {entry['r2']:.4f}", fontsize=9)
        ax.set_xlabel("full solve k_iso, W/(m K)")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
    axes[0].set_ylabel("model, W/(m K)")
    axes[0].legend(fontsize=7)
    fig.suptitle("Held-out full solves, Al2O3-60 (analogues of the paper's Figs. 6, 10, 11)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def precision_figure(reg: dict, rb: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for name in ["prototype", *BASELINES, "reduced_basis"]:
        entry = rb if name == "reduced_basis" else reg[name]
        p = entry["precision"]
        y = np.array(p["predictions"])
        ax.plot(np.array(p["values"]) * 1e8, y / y[0], "o-", ms=3, label=LABELS[name])
    ax.set_xlabel("R_Al2O3_silicone, 1e-8 m^2 K/W (k_Al2O3 = 30)")
    ax.set_ylabel("k_iso / k_iso(2.0e-8)")
    ax.legend(fontsize=7)
    ax.set_title("Precision check inside one grid step", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(reg: dict, rb: dict, train: dict, test: dict, settings: dict) -> str:
    r = rb["rb"]
    lines = [
        "# Surrogate study (issue 11)",
        "",
        "Generated by `validation/surrogate_study.py`. Al2O3-60 (Table 2), 16 um box at 0.2 um "
        "voxels (80^3), gap contact model, two RVE replicas; training: the paper's Table 4 grid "
        f"(k_Al2O3 x R_Al2O3_silicone, {train['X'].shape[0]} full solves); held out: "
        f"{test['X'].shape[0]} full solves drawn log-uniformly in R and uniformly in k over "
        "the same box (Latin hypercube, seed 7). Target: k_iso, the mean of the diagonal, per "
        "row. Both campaigns ran on a Dask LocalCluster (`itr campaign run`).",
        "",
        "## Accuracy on held-out full solves",
        "",
        "| model | full solves it costs | R^2 train | R^2 held out | max rel. error held out "
        "| fit (s) | predictions / s |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in ["prototype", *BASELINES]:
        e = reg[name]
        lines.append(f"| {LABELS[name]} | {e['full_solves']} | {e['r2_train']:.5f} | "
                     f"{e['r2']:.5f} | {100 * e['max_rel']:.2f} % | {e['fit_s']:.2f} | "
                     f"{e['rows_per_s']:.3g} |")
    lines += [
        f"| {LABELS['reduced_basis']}, both replicas | {rb['full_solves']} | - | {rb['r2']:.5f} "
        f"| {100 * rb['max_rel']:.2f} % | {r.fit_time_:.0f} | {rb['rate']:.3g} |",
        f"| {LABELS['reduced_basis']}, its own RVE | {rb['full_solves']} | - | "
        f"{rb['r2_same_rve']:.7f} | {100 * rb['max_rel_same_rve']:.4f} % (every diagonal entry) "
        f"| {r.fit_time_:.0f} | {rb['rate']:.3g} |",
        "",
        "The prototype model and the baselines see two RVE replicas whose k_iso differ at the "
        "same parameters (RVE-to-RVE scatter), which no function of (k, R) can follow; the "
        "reduced basis is exact per RVE, so against its own RVE its error is the certified "
        "model error only, and against the other replica it shows the RVE scatter.",
        "",
        f"Prototype expression: `{reg['prototype']['expression']}`",
        "",
        "## Reduced basis of one RVE (acceptance 2)",
        "",
        f"- Built from {r.n_solves_} full solves (itr_fft, relative residual 1e-9; at most "
        f"{settings['max_solves']}), greedy on a training set of {r.n_train} + 4 corner "
        f"parameter sets, tol {r.tol:g}; converged: {r.converged_}; final training gap "
        f"(upper - lower) / lower = {r.training_gap_:.2e}. Fit time {r.fit_time_:.0f} s.",
        f"- Conductance interpolation: {r.n_interpolation_terms_} terms over "
        f"{r.microstructure_info_['nonaffine_faces']} non-affine faces; eps (twice the largest "
        f"relative error measured on training and check sets) = {r.interpolation_error_:.2e}.",
        f"- Held-out full solves of its RVE: {int(rb['rows'].sum())} parameter sets x 3 "
        f"diagonal entries; relative error max {rb['rel_err'].max():.2e}, median "
        f"{np.median(rb['rel_err']):.2e}.",
        f"- The error estimate bounds the true error on {100 * rb['bounded']:.1f} % of the "
        f"{rb['rel_err'].size} entries (effectivity estimate / error: median "
        f"{np.median(rb['est_over_err']):.3g}, min {rb['est_over_err'].min():.3g}). The full "
        "solves' own error (campaign tolerance 1e-7) sits below the model error here.",
        f"- Evaluations: {rb['rate']:.3g} parameter sets per second (predict, 1e5 sets); "
        f"{rb['est_rate']:.3g} per second with the error estimate.",
        "",
        "Greedy history (parameter set solved, training gap after adding it):",
        "",
        "| solve | k_Al2O3 | R_Al2O3_silicone | training gap |",
        "|---|---|---|---|",
    ]
    for i, h in enumerate(r.history_):
        p = h["parameters"]
        lines.append(f"| {i + 1} | {p['k_Al2O3']:.2f} | {p['R_Al2O3_silicone']:.3g} | "
                     f"{h['training_gap']:.2e} |")
    lines += [
        "",
        "## Precision check (the paper's Section 3.3)",
        "",
        "k_Al2O3 = 30 W/(m K) fixed, R_Al2O3_silicone from 2.0e-8 to 2.9e-8 m^2 K/W in 10 "
        "steps (inside one step of the Table 4 grid). Truth: two full solves at the ends on "
        f"replica 0's RVE give a relative change of {100 * rb['precision_truth']:.3f} %.",
        "",
        "| model | distinct predictions of 10 | relative change 2.0e-8 -> 2.9e-8 |",
        "|---|---|---|",
    ]
    for name in ["prototype", *BASELINES, "reduced_basis"]:
        p = (rb if name == "reduced_basis" else reg[name])["precision"]
        lines.append(f"| {LABELS[name]} | {p['distinct']} | {100 * p['relative_change']:.3f} % |")
    lines += [
        "",
        "Figures: `surrogate_parity.png` (held-out parity of every model), "
        "`surrogate_precision.png` (the precision check). The reduced basis is stored as "
        "`surrogate_reduced_basis.npz` (`ReducedBasis.load`).",
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", type=Path, help="finished surrogate-train campaign folder")
    ap.add_argument("--test", type=Path, help="finished surrogate-test campaign folder")
    ap.add_argument("--work", type=Path, default=Path("surrogate-study-runs"))
    ap.add_argument("--rb-tol", type=float, default=1e-3)
    ap.add_argument("--max-solves", type=int, default=40)
    args = ap.parse_args(argv)
    RESULTS.mkdir(exist_ok=True)
    train_dir = ensure_campaign(HERE / "campaigns" / "surrogate-train.toml", args.train, args.work)
    test_dir = ensure_campaign(HERE / "campaigns" / "surrogate-test.toml", args.test, args.work)
    train, test = campaign_rows(train_dir), campaign_rows(test_dir)
    reg = fit_regressors(train, test)
    rb = fit_reduced_basis(train_dir, test, tol=args.rb_tol, max_solves=args.max_solves)
    parity_figure(test, reg, rb, RESULTS / "surrogate_parity.png")
    precision_figure(reg, rb, RESULTS / "surrogate_precision.png")
    text = report(reg, rb, train, test, {"max_solves": args.max_solves})
    write_text(RESULTS / "surrogate.md", text)
    summary = {name: {k: v for k, v in e.items() if k not in ("model", "pred")}
               for name, e in reg.items()}
    summary["reduced_basis"] = {
        "full_solves": rb["full_solves"], "r2": rb["r2"], "max_rel": rb["max_rel"],
        "r2_same_rve": rb["r2_same_rve"], "max_rel_same_rve": rb["max_rel_same_rve"],
        "bounded_fraction": rb["bounded"], "evaluations_per_s": rb["rate"],
        "estimates_per_s": rb["est_rate"], "precision": rb["precision"],
        "precision_truth": rb["precision_truth"], "training_gap": rb["rb"].training_gap_,
        "interpolation_error": rb["rb"].interpolation_error_}
    write_text(RESULTS / "surrogate.json", json.dumps(summary, indent=1, default=float) + "\n")
    print(text)


if __name__ == "__main__":
    main()
