"""Faithful solves on one lent GPU, in priority order within a time budget.

The device machine has no Dask, so every task runs in this process
(:func:`itr_surrogate.runner.run_task`), into campaign stores (one Parquet part per task,
atomic; a run with the same solver resumes them). Queues:

- ``corrections58`` (the default): issue 58's rebuild of the shipped corrections
  (``examples/corrections.toml``), the work the 2-core CPU takes longest over first
  (:func:`corrections58_queue`); the CPU takes the rest with ``itr corrections build ...
  --solved-in validation/results/corrections_v2/device``;
- ``film`` and ``film2``: issue 47's box study, contact films, tail cut and voxel order.

``--backend quick`` uses the fused CUDA kernels where they equal the portable ones on one
AlN-60 problem (aliasing ``numpy.row_stack``, which numba-cuda 0.30 calls and NumPy 2.5
removed, for this run only), else the portable kernels. ``--pack-ahead N`` packs the next N
tasks' RVEs in a pool of N processes while the GPU solves (packing a 96 um hybrid box takes
45 s on one core).

Usage (on the device, the package and its wheels installed; the recipe in
``../shared/gpu/README.md``)::

    python validation/faithful_solves_on_device.py --out $OUT --stores /tmp/c58 \
        --backend quick --pack-ahead 12 --tar-stores --budget-s 500

With ``--stores`` every task's rows go to ``$OUT/rows.json`` and, with ``--tar-stores``,
the stores (campaign.json and Parquet parts) to ``$OUT/stores.tar``: a device returns 8
files at most. Unpack it into ``validation/results/corrections_v2/device``.
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
    from itr_fv import homogenize
    from itr_fv.discrete.problem import DiscreteProblem
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
            homogenize(problem, mat, solver=be, tol=1e-6, directions=(0,))  # warm
            t = time.perf_counter()
            res = homogenize(problem, mat, solver=be, tol=1e-6)
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


def corrections58_queue(solver: str) -> list[tuple[str, object, object]]:
    """Issue 58's rebuild of the shipped corrections (``examples/corrections.toml``,
    corrections-v2), the work the 2-core CPU takes longest over first, packing by packing:

    1. the hybrid box study (Al2O3-30-AlN-30 at 64, 80 and 96 um, 6 packings), across the
       boxes packing by packing;
    2. the hybrid table (4 formulations x 3 packings x 8 resistance pairs, 64 um);
    3. the AlN table (4 formulations x 3 packings x 4 resistances, 64 um);
    4. the hybrid tail cut (64 um, quantiles 1e-3 and 1e-5, 3 packings);
    5. the voxel order of AlN-60 and of the hybrid (32 um at 0.25, 0.2, 0.16 um);
    6. the rest of the plan (Al2O3, the cheap RVEs), which the CPU does in minutes.

    A store folder is the campaign's name (``device__<name>`` flattened)."""
    from itr_identify.forward.correction_plan import CorrectionPlan

    plan = CorrectionPlan.from_toml(ROOT / "examples" / "corrections.toml")
    items: list[tuple[str, object, object]] = []
    seen: set[tuple[str, str]] = set()

    def add(camps) -> None:
        """Every task of ``camps``, replica by replica across the campaigns."""
        tasks = [c.tasks() for c in camps]
        for i in range(max(len(t) for t in tasks)):
            for camp, ts in zip(camps, tasks):
                if i < len(ts) and (camp.name, ts[i].task_id) not in seen:
                    seen.add((camp.name, ts[i].task_id))
                    items.append((camp.name, camp, ts[i]))

    hyb = "Al2O3-AlN"
    add(plan.study_campaigns(hyb, "boxes", solver=solver))
    add([plan.table_campaign(hyb, solver=solver)])
    add([plan.table_campaign("AlN", solver=solver)])
    add(plan.study_campaigns(hyb, "tail", solver=solver))
    add(plan.study_campaigns("AlN", "order", solver=solver))
    add(plan.study_campaigns(hyb, "order", solver=solver))
    for _, camp in plan.campaigns(solver=solver):
        if not camp.name.endswith("-cheap") and not camp.name.startswith(("box47", "tail47")):
            add([camp])
    return items


def _pack(camp, formulation: str, replica: int):
    """One task's RVE, in a pool process (one numba thread each)."""
    from itr_surrogate.runner import campaign_rve

    return campaign_rve(camp, formulation, replica)


def _pool_init() -> None:
    import numba

    numba.set_num_threads(1)


def quick_kernels(out: Path) -> None:
    """Where the fused CUDA kernels fail with the installed numba-cuda and NumPy (numba-cuda
    0.30 calls ``numpy.row_stack``, gone in NumPy 2.5), alias it for this run only, check the
    fused path against the portable one on one AlN-60 problem (96^3) and use it if equal to
    1e-6; else the portable kernels."""
    import numpy as np

    if not hasattr(np, "row_stack"):
        np.row_stack = np.vstack
        log("numpy.row_stack aliased to numpy.vstack for this run (numba-cuda 0.30 calls it)",
            out)
    from itr_fft.array_api_backend import ArrayAPIBackend
    from itr_fv import homogenize
    from itr_fv.discrete.problem import DiscreteProblem
    from itr_surrogate.campaign import Campaign
    from itr_surrogate.runner import campaign_rve

    camp = Campaign.from_dict({"box_um": 24.0, "voxel_um": 0.25, "seed": 1, "contact": "gap",
                               "formulation": [{"name": "AlN-60"}],
                               "design": {"kind": "grid", "values": {"R_AlN_silicone": [3e-8]}}})
    ms, _ = campaign_rve(camp, "AlN-60", 0)
    problem = DiscreteProblem(ms, contact="gap")
    mat = camp.materials(camp.parameter_sets(camp.formulations[0])[0])
    k = {}
    for kern in ("portable", "auto"):
        try:
            be = ArrayAPIBackend(device="cuda", preconditioner="fft", kernels=kern)
            t = time.perf_counter()
            res = homogenize(problem, mat, solver=be, tol=1e-8)
            k[kern] = float(np.trace(res.k_eff) / 3)
            log(f"fft/{kern}: k_iso {k[kern]:.8f} in {time.perf_counter() - t:.1f} s (first, "
                f"with compiling)", out)
        except Exception as exc:  # noqa: BLE001 - a failing variant is reported, not used
            log(f"fft/{kern}: FAILED {type(exc).__name__}: {exc}", out)
    fused = "auto" in k and "portable" in k and abs(k["auto"] / k["portable"] - 1) < 1e-6
    use_backend("fft/auto" if fused else "fft/portable", out)


def tar_stores(stores: Path, path: Path) -> None:
    """Every store's campaign.json and parts under ``stores`` into the tar ``path``
    (written beside and renamed: atomic)."""
    import os
    import tarfile

    tmp = path.with_name(path.name + ".tmp")
    with tarfile.open(tmp, "w") as tar:
        for camp in sorted(stores.glob("*/campaign.json")):
            tar.add(camp, arcname=str(camp.relative_to(stores)))
            for part in sorted((camp.parent / "parts").glob("*.parquet")):
                tar.add(part, arcname=str(part.relative_to(stores)))
    os.replace(tmp, path)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--budget-s", type=float, default=540.0,
                    help="start no task after this many seconds")
    ap.add_argument("--solver", default="gpu")
    ap.add_argument("--skip-pick", action="store_true")
    ap.add_argument("--queue", choices=("film", "film2", "corrections58"),
                    default="corrections58")
    ap.add_argument("--stores", default=None,
                    help="where the campaign stores go (default --out); every task's rows "
                         "also go to OUT/rows.json, one file (a device returns few files)")
    ap.add_argument("--backend", default=None,
                    help="PRECONDITIONER/KERNELS of the gpu choice without timing the "
                         "variants (e.g. fft/portable, the one verified on an H200); 'quick': "
                         "the fused FFT path where it equals the portable one")
    ap.add_argument("--pack-ahead", type=int, default=0,
                    help="pack this many tasks' RVEs ahead in a pool of processes")
    ap.add_argument("--tar-stores", action="store_true",
                    help="keep OUT/stores.tar (every store's campaign.json and Parquet parts, "
                         "one file: a device returns 8 files at most) as tasks finish")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from concurrent.futures import ProcessPoolExecutor

    from itr_surrogate.runner import run_task, write_task_result
    from itr_surrogate.store import CampaignStore

    pool = None
    if args.pack_ahead > 0:   # before any CUDA context: the pool forks
        import multiprocessing as mp

        pool = ProcessPoolExecutor(args.pack_ahead, mp_context=mp.get_context("fork"),
                                   initializer=_pool_init)
        for f in [pool.submit(time.sleep, 0.3) for _ in range(args.pack_ahead)]:
            f.result()   # every process forked now, before any CUDA context
    if args.backend == "quick":
        quick_kernels(out)
    elif args.backend:
        use_backend(args.backend, out)
    elif args.solver == "gpu" and not args.skip_pick:
        (out / "backend_choice.json").write_text(json.dumps(pick_backend(out), indent=1))
    items = {"film": film_queue, "film2": film2_queue,
             "corrections58": corrections58_queue}[args.queue](args.solver)
    stores = Path(args.stores) if args.stores else out
    all_rows: dict[str, list] = {}
    log(f"{len(items)} tasks queued", out)
    opened: dict[str, CampaignStore] = {}

    def store_of(fold: str, camp) -> CampaignStore:
        if fold not in opened:
            st = CampaignStore(stores / fold.replace("/", "__"))  # two folder levels at most
            st.open_for(camp)
            opened[fold] = st
        return opened[fold]

    todo = [(f, c, t) for f, c, t in items if t.task_id not in store_of(f, c).done_tasks()]
    log(f"{len(items) - len(todo)} already done, {len(todo)} to run", out)
    ahead: dict[int, object] = {}
    done = 0
    for i, (fold, camp, task) in enumerate(todo):
        if time.perf_counter() - T0 > args.budget_s:
            log(f"budget reached: {done} tasks run, {len(todo) - done} left", out)
            break
        if pool is not None:
            for j in range(i, min(i + args.pack_ahead, len(todo))):
                if j not in ahead:
                    _, c, t = todo[j]
                    ahead[j] = pool.submit(_pack, c, t.formulation, t.replica)
        store = store_of(fold, camp)
        flat = fold.replace("/", "__")
        t = time.perf_counter()
        try:
            packed = ahead.pop(i).result() if pool is not None else None
            tp = time.perf_counter() - t
            result = run_task(camp, task, packed)
        except Exception as exc:  # noqa: BLE001 - a task's failure is recorded, not fatal
            store.record_failure(task.task_id, f"{type(exc).__name__}: {exc}")
            log(f"{fold} {task.task_id}: FAILED {type(exc).__name__}: {exc}", out)
            continue
        write_task_result(store, result)
        done += 1
        rows = store.results().to_pylist()
        if args.stores:
            all_rows[flat] = rows
            (out / "rows.json").write_text(json.dumps(all_rows, default=str))
        else:
            (out / f"{flat}.rows.json").write_text(json.dumps(rows, default=str))
        if args.tar_stores and args.stores:
            tar_stores(stores, out / "stores.tar")
        ks = [f"{r['k_iso']:.4f}" for r in result["rows"]]
        log(f"{fold} {task.task_id}: {result['solves']} solves in {time.perf_counter() - t:.1f}"
            f" s (waited {tp:.1f} s for its packing) k_iso {ks}", out)
    if pool is not None:
        pool.shutdown(wait=False, cancel_futures=True)
    log("end", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
