"""Truths of issue 47's recovery study whose inputs are off the model's nominal values.

The identification's forward model holds the paper's conductivities (silicone 0.18, Al2O3 30,
AlN 200 W/(m K)), touching particles at a film of 0 and Table 1 read as number-weighted
lognormals, and corrects a 12 um RVE to a converged box. These truths change one of those
inputs and are solved at a fidelity the model never uses: the Al2O3 formulations of Table 2 in
a 40 um box (the corrections' Al2O3 box is 32 um), on a packing seed neither the corrections
(9001, 9002), the cheap replicas (1, 2, 3) nor issue 39's truth (701, 702) use (801), at 0.25
and 0.2 um on the same particles (the 0.2 um voxel's fine-tail cut at both), its voxel bias
extrapolated away in ``validation/input_recovery_study.py``. One resistance
R_Al2O3_silicone = 1.8e-8 m^2 K/W (not a design point of the corrections).

- ``km+8``: the matrix conductivity 8 % above nominal (0.1944 W/(m K)), the fillers nominal;
- ``film3``: touching particles meet at a 3 nm silicone film (``film_um``, same packing);
- ``volume``: Table 1 read as a volume-weighted lognormal (what a laser diffractometer
  reports): the number median exp(mu - 3 sigma^2), 1.92 um instead of 2.77 um;
- ``nominal``: the nominal inputs with the stated-film contacts (the other truths' reference).

Each (truth, voxel) is one campaign of the campaign engine under
``validation/results/input_truth_runs/`` (a re-run resumes; a killed one loses at most the
task in flight).

Usage::

    python validation/input_truths.py [--truth km+8 film3 ...] [--workers 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "validation" / "results" / "input_truth_runs"
BOX_UM = 40.0
SEED = 801
VOXELS_UM = (0.25, 0.2)
#: The true resistance, m^2 K/W.
TRUTH = {"R_Al2O3_silicone": 1.8e-8}
FORMULATIONS = ("Al2O3-55", "Al2O3-58", "Al2O3-60", "Al2O3-65")
#: Per truth: what it changes (campaign keys) and a one-line description.
TRUTHS = {
    "km+8": ({"base": {"k_silicone": 0.18 * 1.08}}, "k_silicone 0.1944 W/(m K) (+8 %)"),
    "film3": ({"film_um": 0.003}, "touching particles at a 3 nm film"),
    "volume": ({"volume_basis": True}, "Table 1 read as volume-weighted lognormals"),
    "nominal": ({}, "nominal inputs, stated-film (0 nm) contacts"),
}


def number_psd_of_volume(mu: float, sigma: float) -> tuple[float, float]:
    """(mu, sigma) of the number-weighted lognormal whose volume-weighted one has ``mu``,
    ``sigma`` (of ln(D / 1 um)): the volume median is the number median times
    exp(3 sigma^2)."""
    return mu - 3.0 * sigma ** 2, sigma


def truth_campaign(truth: str, voxel_um: float):
    """The campaign of one truth at one voxel edge (um)."""
    from itr_fv.materials.paper_data import TABLE1
    from itr_surrogate.campaign import Campaign

    change, _ = TRUTHS[truth]
    change = dict(change)
    forms = [{"name": f} for f in FORMULATIONS]
    if change.pop("volume_basis", False):
        psd = list(number_psd_of_volume(TABLE1["Al2O3"].mu, TABLE1["Al2O3"].sigma))
        forms = [{"name": f, "fractions": {"Al2O3": int(f.split("-")[1]) / 100},
                  "psd": {"Al2O3": psd}} for f in FORMULATIONS]
    return Campaign.from_dict({
        "name": f"input-truth-{truth}-{voxel_um:g}um", "box_um": BOX_UM, "voxel_um": voxel_um,
        "replicas": 1, "seed": SEED, "contact": "gap", "solver": "mg", "tol": 1e-6,
        "threads_per_worker": 2, "block_size": 1,
        **({} if voxel_um == VOXELS_UM[1] else {"cut_voxel_um": VOXELS_UM[1]}),
        **change, "formulation": forms,
        "design": {"kind": "grid", "values": {k: [v] for k, v in TRUTH.items()}}})


def folder(truth: str, voxel_um: float) -> Path:
    return RUNS / f"{truth}-{voxel_um:g}um"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--truth", nargs="+", default=list(TRUTHS), choices=list(TRUTHS))
    ap.add_argument("--workers", type=int, default=0,
                    help="0: solve in this process (default); N: a local Dask cluster")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from itr_surrogate.runner import run_campaign

    for truth in args.truth:
        for v in VOXELS_UM:
            run_campaign(truth_campaign(truth, v), folder(truth, v), workers=args.workers,
                         progress=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
