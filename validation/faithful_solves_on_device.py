"""Issue 39's faithful solves on one lent GPU, in priority order within a time budget.

The device machine has no Dask, so every task runs in this process
(:func:`itr_surrogate.runner.run_tasks_here`), into campaign stores (one Parquet part per
task, atomic; a run with the same solver resumes them). In order:

1. the AlN shipped corrections (``examples/corrections.toml``), coarse and fine voxel of each
   packing one after the other, the extreme fractions first;
2. the AlN and the hybrid truth of the recovery study (``validation/recovery_truth.py``);
3. the hybrid shipped corrections;
4. the voxel-bias order for AlN-60 (40 um box at 0.25, 0.2, 0.16 and 0.125 um, 2 packings);
5. four more packings per box of the box study at 0.25 um (64, 80, 56 um).

First it times the array-API backend's variants on one AlN-60 problem (160^3) and uses the
fastest one that agrees with the FFT-preconditioned portable path (the one verified on an
H200 before) to 1e-5.

Usage (on the device, the package and its wheels installed)::

    python validation/faithful_solves_on_device.py --out $OUT --budget-s 540 [--queue hybrid]
    python validation/faithful_solves_on_device.py --out $OUT --budget-s 500 --queue film \
        --backend fft/portable       # issue 47: box study, contact films, tail cut

Each store is ``$OUT/<kind>__<folder>`` and every task's rows are also dumped as
``$OUT/<kind>__<folder>.rows.json`` (the device returns two folder levels at most).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from types import MappingProxyType

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "validation"))

T0 = time.perf_counter()


def log(msg: str, out: Path) -> None:
    line = f"[{time.perf_counter() - T0:7.1f} s] {msg}"
    print(line, flush=True)
    with open(out / "log.txt", "a") as fh:
        fh.write(line + "\n")


def pick_backend(out: Path) -> dict:
    """Time the variants on one AlN-60 problem; patch the ``gpu`` choice to the fastest
    agreeing one; returns the table."""
    import numpy as np

    from itr_fft.array_api_backend import ArrayAPIBackend
    from itr_fv.discrete.problem import DiscreteProblem
    from itr_fv.solvers.driver import homogenize
    from itr_surrogate.campaign import Campaign
    from itr_surrogate.runner import campaign_rve

    camp = Campaign.from_dict({"box_um": 40.0, "voxel_um": 0.25, "seed": 1, "contact": "gap",
                               "formulation": [{"name": "AlN-60"}],
                               "design": {"kind": "grid", "values": {"R_AlN_silicone": [3e-8]}}})
    ms, _ = campaign_rve(camp, "AlN-60", 0)
    problem = DiscreteProblem(ms, contact="gap")
    mat = camp.materials(camp.parameter_sets(camp.formulations[0])[0])
    rows = {}
    variants = [("fft", "portable"), ("fft", "auto"), ("multigrid", "auto"),
                ("multigrid", "portable")]
    for pre, kern in variants:
        try:
            be = ArrayAPIBackend(device="cuda", preconditioner=pre, kernels=kern)
            homogenize(problem, mat, backend=be, tol=1e-6, directions=(0,))  # warm
            t = time.perf_counter()
            res = homogenize(problem, mat, backend=be, tol=1e-6)
            wall = time.perf_counter() - t
            k = float(np.trace(res.k_eff) / 3)
            rows[f"{pre}/{kern}"] = {"k_iso": k, "wall_s": wall,
                                     "iterations": list(map(int, res.iterations))}
            log(f"backend {pre}/{kern}: k_iso {k:.6f}, {wall:.2f} s, iterations "
                f"{list(res.iterations)}", out)
        except Exception as exc:  # noqa: BLE001 - a variant that fails is reported, not used
            rows[f"{pre}/{kern}"] = {"error": f"{type(exc).__name__}: {exc}"}
            log(f"backend {pre}/{kern}: FAILED {type(exc).__name__}: {exc}", out)
    ref = rows.get("fft/portable", {}).get("k_iso")
    ok = {name: r for name, r in rows.items() if "k_iso" in r and (
        ref is None or abs(r["k_iso"] / ref - 1) < 1e-5)}
    best = min(ok, key=lambda n: ok[n]["wall_s"])
    use_backend(best, out)
    return {"variants": rows, "chosen": best}


def use_backend(name: str, out: Path) -> None:
    """Patch the ``gpu`` solver choice to ``PRECONDITIONER/KERNELS`` (this run only)."""
    from itr_fv.solvers import choice

    pre, kern = name.split("/")
    gpu = dataclasses.replace(choice.SOLVERS["gpu"],
                              options={"device": "cuda", "preconditioner": pre, "kernels": kern})
    choice.SOLVERS = MappingProxyType({**choice.SOLVERS, "gpu": gpu})
    log(f"using {name}", out)


def hybrid_queue(solver: str) -> list[tuple[str, object, object]]:
    """The second device run: the hybrid corrections of the fraction range's two ends
    (Al2O3-29-AlN-29, Al2O3-32.5-AlN-32.5), packing by packing, both voxels."""
    from itr_identify.forward.correction_plan import CorrectionPlan

    plan = CorrectionPlan.from_toml(ROOT / "examples" / "corrections.toml")
    f = plan.folders("Al2O3-AlN")
    pairs = [(f"corrections/{f[key]}", plan.faithful_campaign("Al2O3-AlN", v, solver=solver))
             for key, v in zip(("coarse", "fine"), plan.voxels_um)]
    items = []
    for form in ("Al2O3-29-AlN-29", "Al2O3-32.5-AlN-32.5"):
        for replica in range(plan.packings):
            for fold, camp in pairs:
                (task,) = [t for t in camp.tasks()
                           if t.formulation == form and t.replica == replica]
                items.append((fold, camp, task))
    return items


#: Issue 47's box study: boxes (um), packings per box, the packings' first seed.
FILM_BOXES_UM = (64, 80, 96)
FILM_PACKINGS = 6
FILM_SEED = 201
#: Issue 47's contact-film table at the converged box (nm).
FILMS_NM = (0.0, 1.0, 2.0, 5.0)


def film_queue(solver: str) -> list[tuple[str, object, object]]:
    """Issue 47, with touching pairs at the stated film (0 nm unless said), 0.25 um voxels,
    R = 3e-8 m^2 K/W at every filler-matrix interface, in priority order:

    1. AlN-60 at 64, 80 and 96 um, 6 packings each (seeds 201..), packing by packing across
       the boxes, so that a budget cut leaves whole packings at every box;
    2. the contact-film table at the converged box: AlN-60 and Al2O3-30-AlN-30 at 64 um, the
       first packing, films 0, 1, 2 and 5 nm (the same particles and voxels at every film);
    3. the tail cut at a fixed box: AlN-60 at 80 um with the size distribution cut at number
       quantiles 1e-3 and 1e-5 (the box study's 1e-4 between them), 3 packings each;
    4. Al2O3-30-AlN-30 at 64, 80 and 96 um, 6 packings each.
    """
    from box_convergence_study import GROUPS

    from itr_surrogate.campaign import Campaign

    def campaign(group: str, box: int, name: str, **rve) -> Campaign:
        g = GROUPS[group]
        return Campaign.from_dict({
            "name": name, "box_um": float(box), "voxel_um": 0.25, "seed": FILM_SEED,
            "replicas": FILM_PACKINGS, "contact": "gap", "solver": solver, "tol": 1e-6,
            "block_size": 1, "formulation": [{"name": g["formulation"]}],
            "design": {"kind": "grid", "values": g["values"]}, **rve})

    items: list[tuple[str, object, object]] = []

    def boxes(group: str) -> None:
        camps = [(f"box47/{group}-{b}um", campaign(group, b, f"box47-{group}-{b}"))
                 for b in FILM_BOXES_UM]
        for r in range(FILM_PACKINGS):
            for fold, camp in camps:
                items.append((fold, camp, camp.tasks()[r]))

    boxes("AlN")
    for group in ("AlN", "hybrid"):
        for f in FILMS_NM:
            camp = campaign(group, 64, f"film47-{group}-{f:g}nm", film_um=f / 1000)
            items.append((f"film47/{group}-64um-{f:g}nm", camp, camp.tasks()[0]))
    for q in (1e-3, 1e-5):
        camp = campaign("AlN", 80, f"tail47-AlN-80-q{q:g}", tail_quantile=q)
        items += [(f"tail47/AlN-80um-q{q:g}", camp, t) for t in camp.tasks()[:3]]
    boxes("hybrid")
    return items


def film2_queue(solver: str) -> list[tuple[str, object, object]]:
    """Issue 47's second device run: the voxel order per system on the same particles
    (AlN-60, then Al2O3-30-AlN-30, 40 um at 0.25, 0.2 and 0.16 um with the fine tail cut at
    0.25 um's two voxels, 2 packings), packing by packing, with the tail cut of
    :func:`film_queue` (AlN-60 at 80 um, quantiles 1e-3 and 1e-5) between the systems."""
    from box_convergence_study import GROUPS

    from itr_surrogate.campaign import Campaign

    items: list[tuple[str, object, object]] = []

    def order(group: str) -> None:
        g = GROUPS[group]
        camps = [(f"order47/{group}-40um-{v:g}um", Campaign.from_dict({
            "name": f"order47-{group}-{v:g}", "box_um": 40.0, "voxel_um": v,
            "cut_voxel_um": 0.25, "seed": FILM_SEED, "replicas": 2, "contact": "gap",
            "solver": solver, "tol": 1e-6, "block_size": 1,
            "formulation": [{"name": g["formulation"]}],
            "design": {"kind": "grid", "values": g["values"]}}))
            for v in (0.25, 0.2, 0.16)]
        for r in range(2):
            for fold, camp in camps:
                items.append((fold, camp, camp.tasks()[r]))

    order("AlN")
    for fold, camp, task in film_queue(solver):
        if fold.startswith("tail47/"):
            items.append((fold, camp, task))
    order("hybrid")
    return items


def queue(solver: str) -> list[tuple[str, object, list]]:
    """(store folder, campaign, tasks) in priority order, tasks interleaved across voxels."""
    from box_convergence_study import campaign_dict
    from recovery_truth import VOXELS_UM, truth_campaign
    from recovery_truth import folder as truth_folder

    from itr_identify.forward.correction_plan import CorrectionPlan
    from itr_surrogate.campaign import Campaign

    plan = CorrectionPlan.from_toml(ROOT / "examples" / "corrections.toml")
    items: list[tuple[str, object, object]] = []

    def interleave(pairs):
        """pairs: [(folder, campaign)] of the same tasks at several voxels."""
        tasks = [c.tasks() for _, c in pairs]
        for i in range(len(tasks[0])):
            for (fold, camp), ts in zip(pairs, tasks):
                items.append((fold, camp, ts[i]))

    def corrections(system):
        f = plan.folders(system)
        interleave([(f"corrections/{f['coarse']}",
                     plan.faithful_campaign(system, plan.voxels_um[0], solver=solver)),
                    (f"corrections/{f['fine']}",
                     plan.faithful_campaign(system, plan.voxels_um[1], solver=solver))])

    def truth(system):
        interleave([(f"truth/{truth_folder(system, v)}", truth_campaign(system, v, solver=solver))
                    for v in VOXELS_UM])

    corrections("AlN")
    truth("AlN")
    truth("Al2O3-AlN")
    corrections("Al2O3-AlN")
    order = []
    for v in (0.25, 0.2, 0.16, 0.125):
        order.append((f"voxel_order/AlN-60-40um-{v:g}um", Campaign.from_dict({
            "name": f"voxel-order-AlN-{v:g}", "box_um": 40.0, "voxel_um": v, "replicas": 2,
            "seed": 1, "contact": "gap", "solver": solver, "tol": 1e-6, "block_size": 1,
            "formulation": [{"name": "AlN-60"}],
            "design": {"kind": "grid", "values": {"R_AlN_silicone": [3e-8]}}})))
    interleave(order)
    for box in (64, 80, 56):
        pairs = []
        for g in ("AlN", "hybrid"):
            d = campaign_dict(g, box, 0.25, 1) | {"seed": 3, "replicas": 4, "solver": solver,
                                                  "name": f"boxconv-{g}-{box}-0.25-s3"}
            pairs.append((f"box/{g}-{box}um-0.25um-s3", Campaign.from_dict(d)))
        interleave(pairs)
    return items


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--budget-s", type=float, default=540.0,
                    help="start no task after this many seconds")
    ap.add_argument("--solver", default="gpu")
    ap.add_argument("--skip-pick", action="store_true")
    ap.add_argument("--queue", choices=("main", "hybrid", "film", "film2"), default="main")
    ap.add_argument("--stores", default=None,
                    help="where the campaign stores go (default --out); every task's rows "
                         "also go to OUT/rows.json, one file (a device returns few files)")
    ap.add_argument("--backend", default=None,
                    help="PRECONDITIONER/KERNELS of the gpu choice without timing the "
                         "variants (e.g. fft/portable, the one verified on an H200)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from itr_surrogate.runner import run_tasks_here
    from itr_surrogate.store import CampaignStore

    if args.backend:
        use_backend(args.backend, out)
    elif args.solver == "gpu" and not args.skip_pick:
        (out / "backend_choice.json").write_text(json.dumps(pick_backend(out), indent=1))
    items = {"main": queue, "hybrid": hybrid_queue, "film": film_queue,
             "film2": film2_queue}[args.queue](args.solver)
    stores = Path(args.stores) if args.stores else out
    all_rows: dict[str, list] = {}
    log(f"{len(items)} tasks queued", out)
    opened: dict[str, CampaignStore] = {}
    done = 0
    for fold, camp, task in items:
        if time.perf_counter() - T0 > args.budget_s:
            log(f"budget reached: {done} tasks run, {len(items) - done} left", out)
            break
        store = opened.get(fold)
        flat = fold.replace("/", "__")   # the device returns two folder levels at most
        if store is None:
            store = CampaignStore(stores / flat)
            store.check_for(camp)
            store.open_for(camp)
            opened[fold] = store
        if task.task_id in store.done_tasks():
            done += 1
            continue
        t = time.perf_counter()
        solves, failed, _ = run_tasks_here(camp, store, [task])
        done += 1
        rows = store.results().to_pylist() if not failed else []
        if args.stores:
            all_rows[flat] = rows
            (out / "rows.json").write_text(json.dumps(all_rows, default=str))
        else:
            (out / f"{flat}.rows.json").write_text(json.dumps(rows, default=str))
        ks = [f"{r['k_iso']:.4f}" for r in rows if r["task_id"] == task.task_id]
        log(f"{fold} {task.task_id}: {solves} solves in {time.perf_counter() - t:.1f} s"
            f"{' FAILED' if failed else ''} k_iso {ks}", out)
    log("end", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
