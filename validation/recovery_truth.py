"""The truth of issue 39's recovery study: a fidelity the shipped corrections never use.

Per filler system a box larger than the corrections' (Al2O3 40 um for 32, AlN and the hybrid
80 um for 64), packing seeds the corrections and the cheap replicas never use (701, 702), the
voxel bias extrapolated from 0.25 and 0.2 um on the same packing (the 0.2 um voxel's
fine-tail cut at both), at one point of
resistances that is not a design point of the corrections (:data:`TRUTH`). Each
(system, voxel) is one campaign of the campaign engine; the device script
(``validation/faithful_solves_on_device.py``) or a CPU run solves them, and
``validation/shipped_recovery_study.py`` reads them.
"""

from __future__ import annotations

from itr_surrogate.campaign import Campaign

#: The true resistances, m^2 K/W (between the corrections' design values 1e-8 and 5e-8).
TRUTH = {"R_Al2O3_silicone": 1.8e-8, "R_AlN_silicone": 2.6e-8}
#: Per system: box (um), packings, formulations (Table 2).
SYSTEMS = {
    "Al2O3": (40.0, 2, ("Al2O3-55", "Al2O3-58", "Al2O3-60", "Al2O3-65")),
    "AlN": (80.0, 1, ("AlN-55", "AlN-62", "AlN-60", "AlN-58")),
    "Al2O3-AlN": (80.0, 1, ("Al2O3-29-AlN-29", "Al2O3-32.5-AlN-32.5", "Al2O3-30-AlN-30",
                            "Al2O3-31-AlN-31")),
}
VOXELS_UM = (0.25, 0.2)
SEED = 701


def truth_campaign(system: str, voxel_um: float, *, solver: str = "mg") -> Campaign:
    """The truth campaign of one system at one voxel edge (um)."""
    box, packings, formulations = SYSTEMS[system]
    fillers = {"Al2O3": ("Al2O3",), "AlN": ("AlN",), "Al2O3-AlN": ("Al2O3", "AlN")}[system]
    values = {f"R_{f}_silicone": [TRUTH[f"R_{f}_silicone"]] for f in fillers}
    return Campaign.from_dict({
        "name": f"truth-{system}-{voxel_um:g}um", "box_um": box, "voxel_um": voxel_um,
        "replicas": packings, "seed": SEED, "contact": "gap", "solver": solver, "tol": 1e-6,
        **({} if voxel_um == VOXELS_UM[1] else {"cut_voxel_um": VOXELS_UM[1]}),
        "block_size": 1, "formulation": [{"name": f} for f in formulations],
        "design": {"kind": "grid", "values": values}})


def folder(system: str, voxel_um: float) -> str:
    return f"truth-{system}-{voxel_um:g}um"
