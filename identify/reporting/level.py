"""The fidelity level that actually ran, in one record: identified.json, the manifest and the
report say it from here, so that none of them says a solve ran that did not.

Per model (:meth:`~itr_identify.forward.model.ForwardModel.level_at` at the best values):
where its level came from (``shipped``: the corrections shipped with the package;
``runtime``: faithful solves of this run; ``none``), the factor on the cheap RVE's k and its
uncertainty. Then, only where a model used it, the shipped table's provenance (its boxes,
voxels, packings, date and commit) and the runtime correction's RVEs, rounds and
convergence.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..forward.fidelity import fidelity_name
from ..inference.pipeline import Identification

__all__ = ["level_record", "level_lines", "runs_record"]

#: Provenance entries of the shipped table that say what its corrections are.
_SHIPPED_KEYS = ("plan", "date", "commit", "contacts", "boxes_um", "voxels_um", "packings",
                 "seeds", "tol", "solver")


def _faithful_solves(ident: Identification) -> int:
    return sum(1 for m in ident.models.values() for r in m.solves
               if str(r.get("purpose", "")).startswith("faithful"))


def level_record(ident: Identification) -> dict:
    """What set the level of each model of ``ident`` at its best values (module notes)."""
    models = {f: m.level_at({p: ident.quoted[p] for p in m.parameters})
              for f, m in ident.models.items()}
    sources = {r["source"] for r in models.values()}
    rec: dict = {"level": fidelity_name(ident.settings.faithful),
                 "parametrisation": ident.parametrisation,
                 "faithful_solves_this_run": _faithful_solves(ident), "models": models}
    if "shipped" in sources:
        from ..forward.shipped import ShippedCorrections

        prov = ShippedCorrections.load().provenance
        rec["shipped"] = {"file": "identify/data/corrections.json (`itr corrections show`)",
                          **{k: prov[k] for k in _SHIPPED_KEYS if k in prov}}
    if "runtime" in sources:
        fa = ident.settings.faithful
        rounds = ident.fidelity_rounds
        rec["runtime"] = {
            "boxes_um": {f: r["box_um"] for f, r in models.items() if r["source"] == "runtime"},
            "voxels_um": [fa.coarse_voxel_um, fa.voxel_um], "packings": fa.packings,
            "seed": fa.seed, "rounds": len(rounds),
            "converged": bool(rounds and rounds[-1].get("converged")),
            "move_tolerance": fa.move_tolerance}
    return rec


def runs_record(idents: Mapping[str, Identification]) -> dict:
    """:func:`level_record` of every parametrisation (the manifest's ``fidelity``)."""
    return {p: level_record(i) for p, i in idents.items()}


def _factors(rec: dict, names: list[str]) -> str:
    """``Al2O3-55 x1.041 (+-0.5 %), ...``: the factors of the models ``names``."""
    return ", ".join(f"{f} x{rec['models'][f]['factor']:.3f} "
                     f"(+-{100 * rec['models'][f]['relative_sd']:.1f} %)" for f in names)


def level_lines(ident: Identification) -> list[str]:
    """The record as the report's sentences: what corrected which model, from what."""
    rec = level_record(ident)
    s = ident.settings
    by: dict[str, list[str]] = {}
    for f, r in rec["models"].items():
        by.setdefault(str(r["source"]), []).append(f)
    cheap = f"the cheap RVE ({s.box_um:g} um box, {s.voxel_um:g} um voxels)"
    lines = [f"Fidelity `{rec['level']}`, {ident.parametrisation} parametrisation; "
             f"{rec['faithful_solves_this_run']} faithful full solves ran in this run."]
    if "shipped" in by:
        sh = rec["shipped"]
        boxes = ", ".join(f"{k} {v:g} um" for k, v in sh.get("boxes_um", {}).items())
        voxels = ", ".join(f"{k} {v:g} um" for k, v in sh.get("voxels_um", {}).items())
        factors = _factors(rec, by["shipped"])
        lines.append(
            f"- shipped corrections ({len(by['shipped'])} models, {sh['file']}; plan "
            f"{sh.get('plan')}, {sh.get('date')}, commit {str(sh.get('commit'))[:10]}; "
            f"touching particles at the {sh.get('contacts')}): k of each system's table box "
            f"({boxes}; voxels {voxels}; {sh.get('packings')} packings, seeds "
            f"{sh.get('seeds')}) taken to the converged box of its box study and to no voxel "
            f"bias by its order study, over k of {cheap}, computed once and read here: no "
            f"solve of this run made them. Factors at the best values (own sd): {factors}; "
            "each system's box, voxel and tail terms shared by its formulations.")
    if "runtime" in by:
        rt = rec["runtime"]
        boxes = ", ".join(f"{f} {b:g} um" for f, b in rt["boxes_um"].items())
        factors = _factors(rec, by["runtime"])
        lines.append(
            f"- corrected in this run ({len(by['runtime'])} models): full solves of "
            f"{rt['packings']} faithful packings per formulation (boxes {boxes}; voxel bias "
            f"removed by Richardson over {rt['voxels_um'][0]:g} and {rt['voxels_um'][1]:g} "
            f"um) at the best point, {rt['rounds']} rounds, "
            + ("converged" if rt["converged"] else "not converged")
            + f" (the best point moved less than {rt['move_tolerance']:g} of its 90 % "
            f"interval). Factors: {factors}.")
    if "none" in by:
        why = {str(rec["models"][f].get("why", "")) for f in by["none"]} - {""}
        lines.append(f"- not corrected ({', '.join(by['none'])}): the numbers of {cheap}"
                     + (f" ({'; '.join(sorted(why))})" if why else "") + ".")
    return lines
