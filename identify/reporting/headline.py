"""The headline of an identification: per parameter the best value, the 90 % interval and
what kind of answer it is, and which parametrisation to quote and why.

Printed at the end of ``itr reproduce`` / ``itr identify``, at the top of ``report.md``
and under ``"headline"`` in ``identified.json``.

Flags (one per parameter, the first that applies):

- ``at the prior's edge``: the best value lies within :data:`EDGE_FACTOR` of an end of the
  prior: the data pull it out of the range searched;
- ``undetermined``: the 90 % interval reaches both ends of the prior (within
  :data:`EDGE_FACTOR`), or spans more than :data:`UNDETERMINED_DECADES` decades;
- ``bounded on one side``: the interval reaches one end of the prior;
- ``voxel-specific``: a per-area contact resistance (``Rff``): determined, but a property
  of the voxel it was identified at (``validation/results/resolution_area.md``);
- ``determined``: none of these.

Beside the flag, the combined factor of the error budget's effects that this fidelity
leaves uncorrected (voxel bias, box beyond the box solved) and a caveat where it is larger
than the interval: a value can be determined at its fidelity and still move by more than its
interval at a faithful one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from itr_fv.parameters import parse_parameter

from ..forward.fidelity import fidelity_name
from ..inference.pipeline import Identification
from .error_budget import error_budget

__all__ = ["parameter_flag", "prior_ends", "choose_parametrisation", "headline", "headline_lines",
           "headline_markdown", "EDGE_FACTOR",
           "UNDETERMINED_DECADES", "FLAGS"]

#: An interval end or best value within this factor of a prior end counts as at that end.
EDGE_FACTOR = 1.5
#: A 90 % interval wider than this many decades determines nothing worth quoting.
UNDETERMINED_DECADES = 2.0
#: The error budget's effects that the RVE leaves out of the likelihood and that a higher
#: fidelity removes: their combined factor on a resistance is set against its interval.
UNCORRECTED = ("voxel bias (not corrected)", "box effect beyond the box solved")
FLAGS = ("at the prior's edge", "undetermined", "bounded on one side", "voxel-specific",
         "determined")


def prior_ends(post, name: str) -> tuple[bool, bool]:
    """Whether the 90 % interval of ``name`` reaches the prior's lower and upper end
    (within :data:`EDGE_FACTOR`); ``post`` a :class:`~itr_identify.inference.calibrate.
    Posterior`."""
    p_lo, p_hi = post.prior
    lo, hi = post.interval(name)
    return lo <= p_lo * EDGE_FACTOR, hi >= p_hi / EDGE_FACTOR


def parameter_flag(ident: Identification, name: str) -> str:
    """The flag of parameter ``name`` of ``ident`` (one of :data:`FLAGS`)."""
    post = ident.posterior
    p_lo, p_hi = post.prior
    lo, hi = post.interval(name)
    best = post.best[name]
    if best <= p_lo * EDGE_FACTOR or best >= p_hi / EDGE_FACTOR:
        return FLAGS[0]
    low_end, high_end = prior_ends(post, name)
    if (low_end and high_end) or math.log10(hi / lo) > UNDETERMINED_DECADES:
        return FLAGS[1]
    if low_end or high_end:
        return FLAGS[2]
    if parse_parameter(name)[0] == "Rff" and ident.parametrisation == "area":
        return FLAGS[3]
    return FLAGS[4]


def _filler_matrix(name: str) -> bool:
    return parse_parameter(name)[0] == "R"


def choose_parametrisation(bics: Mapping[str, float], flags: Mapping[str, Mapping[str, str]]
                           ) -> tuple[str, str]:
    """The parametrisation to quote and why: the lower BIC where its filler-matrix
    resistances (``R_*``) are all determined, else the other one if its are.

    Parameters
    ----------
    bics : mapping of str to float
        BIC per parametrisation.
    flags : mapping of str to mapping of str to str
        Per parametrisation, the flag (:func:`parameter_flag`) of each parameter.
    """
    order = sorted(bics, key=bics.get)

    def usable(p: str) -> bool:
        return all(f == "determined" for n, f in flags[p].items() if _filler_matrix(n))

    if len(order) == 1:
        p = order[0]
        return p, ("the only parametrisation run" + ("" if usable(p) else
                   "; its filler-matrix resistances are not all determined (flags)"))
    best, other = order[0], order[1]
    margin = bics[other] - bics[best]
    if usable(best):
        return best, (f"the data support it (BIC lower by {margin:.1f} than {other}) and its "
                      "filler-matrix resistances are determined")
    if usable(other):
        bad = ", ".join(f"{n} {f}" for n, f in flags[best].items()
                        if _filler_matrix(n) and f != "determined")
        return other, (f"its filler-matrix resistances are determined; {best} fits better "
                       f"(BIC lower by {margin:.1f}) but leaves {bad}")
    return best, (f"the lower BIC (by {margin:.1f}); no parametrisation determines every "
                  "filler-matrix resistance: quote the intervals, not the best values")


def _caveat(budget_entry: dict) -> dict:
    """``numerical_factor`` (the combined factor of the :data:`UNCORRECTED` effects on the
    resistance, > 1 means the resistance would be higher) and a ``caveat`` when it exceeds
    the 90 % interval's half-width factor."""
    factors = [budget_entry["factors"].get(k) for k in UNCORRECTED]
    factors = [f for f in factors if f is not None and f > 0]
    if not factors:
        return {}
    c = math.prod(factors)
    width = budget_entry["interval_half_width_factor"]
    out = {"numerical_factor": c}
    if max(c, 1 / c) > width:
        out["caveat"] = (f"the RVE's uncorrected voxel and box effects move it by x{c:.2f}, "
                         f"more than its interval (x/{width:.2f}): quote it from a higher "
                         "--fidelity")
    return out


def headline(idents: Mapping[str, Identification]) -> dict:
    """The headline as plain JSON: ``quote`` (parametrisation), ``why``, ``fidelity`` and
    per parametrisation and parameter ``best``, ``interval_90`` (m^2 K/W) and ``flag``."""
    flags = {p: {n: parameter_flag(i, n) for n in i.posterior.names}
             for p, i in idents.items()}
    quote, why = choose_parametrisation({p: i.bic() for p, i in idents.items()}, flags)
    params = {p: {n: {"best": i.posterior.best[n], "interval_90": list(i.posterior.interval(n)),
                      "flag": flags[p][n], "unit": "m^2 K/W"}
                  for n in i.posterior.names} for p, i in idents.items()}
    for p, ident in idents.items():
        for n, entry in error_budget(ident)["parameters"].items():
            if n in params[p]:
                params[p][n].update(_caveat(entry))
    s = next(iter(idents.values())).settings
    fidelity = fidelity_name(s.faithful)
    return {"quote": quote, "why": why, "fidelity": fidelity,
            "holds_at": f"{s.box_um:g} um box, {s.voxel_um:g} um voxels"
                        + ("" if s.faithful is None else
                           f", corrected on faithful RVEs ({fidelity})"),
            "parameters": params}


def headline_lines(head: dict) -> list[str]:
    """:func:`headline` as plain-text lines (the terminal and the top of ``report.md``)."""
    lines = []
    for par, params in head["parameters"].items():
        mark = "  <- quote" if par == head["quote"] else ""
        lines.append(f"{par}:{mark}")
        for n, e in params.items():
            lo, hi = e["interval_90"]
            lines.append(f"  {n} = {e['best']:.2e} m^2 K/W (90 % interval {lo:.2e} - "
                         f"{hi:.2e}; {e['flag']})")
            if "caveat" in e:
                lines.append(f"    caveat: {e['caveat']}")
    lines.append(f"quote {head['quote']}: {head['why']}.")
    lines.append(f"These hold at fidelity {head['fidelity']} ({head['holds_at']}); the "
                 "report's error budget gives what the RVE leaves out.")
    return lines


def headline_markdown(head: dict) -> list[str]:
    """:func:`headline` as the first section of ``report.md``."""
    lines = ["## Headline", "",
             "| parametrisation | parameter | best (m^2 K/W) | 90 % interval | flag | "
             "uncorrected voxel and box effects |",
             "|---|---|---|---|---|---|"]
    for par, params in head["parameters"].items():
        name = f"**{par}** (quote)" if par == head["quote"] else par
        for n, e in params.items():
            lo, hi = e["interval_90"]
            c = e.get("numerical_factor")
            effect = "-" if c is None else f"x{c:.2f}" + (
                ", beyond the interval: quote it from a higher --fidelity" if "caveat" in e
                else "")
            lines.append(f"| {name} | {n} | {e['best']:.2e} | {lo:.2e} - {hi:.2e} | "
                         f"{e['flag']} | {effect} |")
    lines += ["", f"Quote **{head['quote']}**: {head['why']}. These values hold at fidelity "
              f"`{head['fidelity']}` ({head['holds_at']}); the error budget below gives what "
              "the RVE leaves out. Flags: determined; bounded on one side (the interval "
              "reaches one end of the prior); undetermined (both ends, or wider than "
              f"{UNDETERMINED_DECADES:g} decades); at the prior's edge (the best value is); "
              "voxel-specific (a per-area contact value, a property of the voxel)."]
    return lines
