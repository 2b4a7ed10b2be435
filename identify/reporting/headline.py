"""The headline of an identification: per parameter the best value, the 90 % interval and
what kind of answer it is, which parametrisation to quote and why, and how far the fidelity
the values were computed at lets one quote them.

Printed at the end of ``itr reproduce`` / ``itr identify``, at the top of ``report.md``
and under ``"headline"`` in ``identified.json``.

Flags (one per parameter, the first that applies): the calibration's
:meth:`~itr_identify.inference.calibrate.Posterior.determination` (the same rule writes the
report's identifiability statements),

- ``at the prior's edge``: the best value lies within :data:`EDGE_FACTOR` of an end of the
  prior: the data pull it out of the range searched;
- ``undetermined``: the 90 % interval reaches both ends of the prior (within
  :data:`EDGE_FACTOR`), or spans more than :data:`UNDETERMINED_DECADES` decades;
- ``bounded on one side``: the interval reaches one end of the prior;

then ``model misfit``: the data would determine it, but the fit fails its chi-square test
(p below :data:`~itr_identify.inference.misfit.MISFIT_P`): its interval carries a
model-form error (:mod:`itr_identify.inference.misfit`); ``voxel-specific``: a per-area
contact resistance (``Rff``): determined, but a property of the voxel it was identified at
(``validation/results/resolution_area.md``); ``determined``: none of these.

Which parametrisation to quote: :func:`parametrisation_choice`, the one rule that the
headline and the report's model-selection section (:func:`itr_identify.reporting.report.
selection_lines`) both print.

Beside the flag, the combined factor of the error budget's effects that this fidelity
leaves uncorrected (voxel bias, box beyond the box solved) and a mark where it is larger
than the interval: a value can be determined at its fidelity and still move by more than its
interval at a faithful one. What that means for quoting is said once, in
:func:`fidelity_note`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from itr_fv.materials.parameters import parse_parameter

from ..forward.fidelity import fidelity_name
from ..inference.calibrate import EDGE_FACTOR, UNDETERMINED_DECADES
from ..inference.misfit import MISFIT_P, is_misfit, misfit_note
from ..inference.nuisance import narrowing
from ..inference.pipeline import Identification
from .error_budget import error_budget
from .level import level_record
from .naming_words import headline_entry_lines

__all__ = ["parameter_flag", "prior_ends", "choose_parametrisation", "parametrisation_choice",
           "chi_square_per_dof", "fidelity_note", "headline", "headline_lines",
           "headline_markdown", "EDGE_FACTOR", "UNDETERMINED_DECADES", "FLAGS", "BIC_MARGIN",
           "INTERVAL_FACTOR_NOTE", "QUICK_TO_STANDARD", "DETERMINED_FACTOR"]

#: The error budget's effects that the RVE leaves out of the likelihood and that a higher
#: fidelity removes: their combined factor on a resistance is set against its interval.
UNCORRECTED = ("voxel bias (not corrected)", "box effect beyond the box solved")
FLAGS = ("at the prior's edge", "undetermined", "bounded on one side", "voxel-specific",
         "model misfit", "bounded", "determined")
#: The widest 90 % interval, as its half-width factor ``F = sqrt(upper / lower)``, that is
#: called ``determined`` (on a fit that passes its test): the value within x/3.
DETERMINED_FACTOR = 3.0
#: BIC difference from which one parametrisation is called better supported (Kass and
#: Raftery's "positive evidence").
BIC_MARGIN = 2.0
#: What ``x/F`` after an interval means (the error budget's ``interval_half_width_factor``,
#: ``F = sqrt(upper / lower)``).
INTERVAL_FACTOR_NOTE = ("x/F is the 90 % interval's half-width as a factor: the interval "
                        "runs from its geometric middle divided by F to its middle times F "
                        "(F = sqrt(upper end / lower end))")
#: The gap parametrisation's resistances at ``--fidelity standard`` over those at ``quick``
#: on the shipped Table 3 (``validation/results/reproduce_fidelity.md``: R_Al2O3_silicone
#: 2.84e-8 against 1.67e-8, R_AlN_silicone 1.56e-8 against 7.7e-9): the measured bias of the
#: default level, stated in :func:`fidelity_note`.
QUICK_TO_STANDARD = {"R_Al2O3_silicone": 2.84e-8 / 1.67e-8,
                     "R_AlN_silicone": 1.56e-8 / 7.7e-9}


def prior_ends(post, name: str) -> tuple[bool, bool]:
    """Whether the 90 % interval of ``name`` reaches the prior's lower and upper end
    (within :data:`EDGE_FACTOR`); ``post`` a :class:`~itr_identify.inference.calibrate.
    Posterior` (:meth:`~itr_identify.inference.calibrate.Posterior.prior_ends`)."""
    return post.prior_ends(name)


def parameter_flag(ident: Identification, name: str) -> str:
    """The flag of parameter ``name`` of ``ident`` (one of :data:`FLAGS`): a value the data
    would determine is ``model misfit`` where its model fails its chi-square test
    (:mod:`itr_identify.inference.misfit`), never ``determined``; ``determined`` only
    where its 90 % interval is within x/:data:`DETERMINED_FACTOR`, else ``bounded (x/F)``."""
    flag = ident.posterior.determination(name)
    if flag != "determined":
        return flag
    if is_misfit(ident.fit):
        return FLAGS[4]
    if parse_parameter(name)[0] == "Rff" and ident.parametrisation == "area":
        return FLAGS[3]
    lo, hi = ident.posterior.interval(name)
    factor = math.sqrt(hi / lo)
    if factor > DETERMINED_FACTOR:
        return f"{FLAGS[5]} (x/{factor:.1f})"
    return flag


def _filler_matrix(name: str) -> bool:
    return parse_parameter(name)[0] == "R"


def chi_square_per_dof(ident: Identification) -> float:
    """Chi-square at the best values over (formulations - parameters), at least 1."""
    return ident.chi_square() / max(len(ident.models) - ident.n_parameters, 1)


def choose_parametrisation(bics: Mapping[str, float], flags: Mapping[str, Mapping[str, str]],
                           *, chi2_dof: Mapping[str, float] | None = None,
                           voxel_um: float | None = None,
                           levels: Mapping[str, str] | None = None) -> dict:
    """Which parametrisation the data support and which one to quote, and why: the one rule
    of the headline and of the report's model-selection section.

    Supported: the lower BIC, when lower by :data:`BIC_MARGIN` or more (else none).
    Quoted: the supported one where its filler-matrix resistances (``R_*``) are all
    ``determined``; else one whose are (the lower BIC among them); else the supported one
    (or the lower BIC) with the warning to quote intervals, not best values. Where the
    quoted one is not the supported one, ``why`` says so and why: what the better fit leaves
    undetermined, that its per-area contact resistances (flag ``voxel-specific``) belong to
    the voxel (``voxel_um``) and do not transfer to another resolution, and that the quoted
    one's poorer fit (``chi2_dof``) is model error its intervals do not carry.

    Parameters
    ----------
    bics : mapping of str to float
        BIC per parametrisation.
    flags : mapping of str to mapping of str to str
        Per parametrisation, the flag (:func:`parameter_flag`) of each parameter.
    chi2_dof : mapping of str to float, optional
        Chi-square per degree of freedom at the best values, per parametrisation.
    voxel_um : float, optional
        The voxel the values were identified at.
    levels : mapping of str to str, optional
        The fidelity level of each parametrisation's models: models at different levels are
        not compared by their BIC (none is supported).

    Returns
    -------
    dict
        ``bic``, ``margin`` (BIC difference, None for one parametrisation), ``supported``
        (or None), ``quote``, ``why`` (text, no final full stop) and ``agrees`` (whether the
        quoted one is the supported one, or none is supported).
    """
    order = sorted(bics, key=bics.get)
    rule = _Determined(flags)
    out = {"bic": dict(bics), "margin": None, "supported": None}
    if len(order) == 1:
        p = order[0]
        why = "the only parametrisation run" + (
            "" if rule.usable(p) else f"; it leaves {rule.left(p)}: quote the intervals, "
                                      "not the best values")
        return {**out, "quote": p, "why": why, "agrees": True}
    lowest, other = order[0], order[1]
    margin = bics[other] - bics[lowest]
    supported = lowest if margin >= BIC_MARGIN else None
    compared = levels is None or len({levels[p] for p in order}) == 1
    if not compared:
        supported = None
    out.update(margin=margin if compared else None, supported=supported)
    if not compared:
        return {**out, **_not_compared(order, rule, levels)}
    if supported is not None and rule.usable(supported):
        return {**out, "quote": supported, "agrees": True,
                "why": f"the data support it (BIC lower by {margin:.1f} than {other}) and its "
                       "filler-matrix resistances are determined"}
    ok = [p for p in order if rule.usable(p)]
    if ok and supported is None:
        return {**out, **_neither_supported(order, rule, q=ok[0], margin=margin)}
    if ok:
        return {**out, **_other_quoted(rule, supported=supported, quoted=ok[0], margin=margin,
                                       fit=dict(chi2_dof or {}), voxel_um=voxel_um)}
    q = supported or lowest
    what = ("the data support it" if supported else
            f"the lower BIC, though not supported over {other} (difference {margin:.1f})")
    if supported:
        what += f" (BIC lower by {margin:.1f} than {other})"
    return {**out, "quote": q, "agrees": True,
            "why": f"{what}; no parametrisation determines every filler-matrix resistance "
                   f"({q} leaves {rule.left(q)}): quote the intervals, not the best values"}


class _Determined:
    """Whether a parametrisation determines its filler-matrix resistances, by their
    ``flags`` (per parametrisation, per parameter), and which it leaves."""

    def __init__(self, flags: Mapping[str, Mapping[str, str]]):
        self.flags = flags

    def usable(self, p: str) -> bool:
        """Whether every filler-matrix resistance of ``p`` is ``determined``."""
        return all(f == "determined" for n, f in self.flags[p].items() if _filler_matrix(n))

    def left(self, p: str) -> str:
        """The filler-matrix resistances of ``p`` not determined, each with its flag."""
        return ", ".join(f"{n} {f}" for n, f in self.flags[p].items()
                         if _filler_matrix(n) and f != "determined")


def _not_compared(order: Sequence[str], rule: _Determined,
                  levels: Mapping[str, str]) -> dict:
    """The choice (``quote``, ``agrees``, ``why``) where the models sit at different
    fidelity levels and are not compared by their BIC: the first of ``order`` (lowest BIC
    first) that determines its filler-matrix resistances, else gap (or the lowest BIC) with
    the warning to quote intervals."""
    at = ", ".join(f"{p} at {levels[p]}" for p in order)
    ok = [p for p in order if rule.usable(p)]
    if ok:
        q = ok[0]
        rest = [p for p in order if p != q]
        return {"quote": q, "agrees": True,
                "why": f"not compared by their BIC: their models sit at different "
                       f"fidelity ({at}); {q} determines its filler-matrix resistances"
                       + "".join(f"; {p} leaves {rule.left(p)}" for p in rest
                                 if rule.left(p))}
    q = "gap" if "gap" in order else order[0]
    return {"quote": q, "agrees": True,
            "why": f"not compared by their BIC: their models sit at different fidelity "
                   f"({at}); no parametrisation determines every filler-matrix "
                   f"resistance ({q} leaves {rule.left(q)}): quote the intervals, not the "
                   "best values"}


def _neither_supported(order: Sequence[str], rule: _Determined, *, q: str,
                       margin: float) -> dict:
    """The choice where neither parametrisation is supported over the other (BIC
    difference ``margin`` below :data:`BIC_MARGIN`): ``q``, which determines its
    filler-matrix resistances, with what the others leave."""
    why = (f"neither parametrisation is supported over the other (BIC difference "
           f"{margin:.1f}); {q} determines its filler-matrix resistances")
    rest = [p for p in order if p != q and not rule.usable(p)]
    if rest:
        why += "; " + "; ".join(f"{p} leaves {rule.left(p)}" for p in rest)
    return {"quote": q, "why": why, "agrees": True}


def _other_quoted(rule: _Determined, *, supported: str, quoted: str, margin: float,
                  fit: Mapping[str, float], voxel_um: float | None) -> dict:
    """The choice where the data support ``supported`` but it leaves a filler-matrix
    resistance undetermined, and ``quoted`` determines them: why the better fit is not
    quoted (its voxel-specific contact resistances, the quoted one's poorer fit ``fit``,
    chi-square per degree of freedom)."""
    s, q = supported, quoted
    fits = f"BIC lower by {margin:.1f}"
    if s in fit and q in fit:
        fits += f"; chi-square/dof {fit[s]:.2f} against {fit[q]:.2f}"
    why = (f"the data support {s} ({fits}), but it does not determine its "
           f"filler-matrix resistances ({rule.left(s)})")
    voxel = [n for n, f in rule.flags[s].items() if f == "voxel-specific"]
    if voxel:
        at = f"the {voxel_um:g} um voxel" if voxel_um else "the voxel"
        why += (f", and its fit rests on per-area contact resistances ({', '.join(voxel)}) "
                f"that are properties of {at}, not of the materials, and do not transfer "
                "to another resolution")
    why += f"; {q} determines them"
    if q in fit and fit[q] > 2.0:
        why += (f", but its poorer fit (chi-square/dof {fit[q]:.2f}) is model error that "
                "its 90 % intervals do not carry")
    return {"quote": q, "why": why, "agrees": False}


def parametrisation_choice(idents: Mapping[str, Identification],
                           flags: Mapping[str, Mapping[str, str]] | None = None) -> dict:
    """:func:`choose_parametrisation` of identifications (their BIC, flags, chi-square per
    degree of freedom and voxel): the dict that the headline and the report's
    model-selection section both print, plus ``chi2_dof``."""
    if flags is None:
        flags = {p: {n: parameter_flag(i, n) for n in i.posterior.names}
                 for p, i in idents.items()}
    chi2 = {p: chi_square_per_dof(i) for p, i in idents.items()}
    voxel = next(iter(idents.values())).settings.voxel_um
    levels = {p: level_name(i) for p, i in idents.items()}
    return {**choose_parametrisation({p: i.bic() for p, i in idents.items()}, flags,
                                     chi2_dof=chi2, voxel_um=voxel, levels=levels),
            "chi2_dof": chi2, "levels": levels}


def level_name(ident: Identification) -> str:
    """The fidelity level of an identification's models: that of its settings for the gap
    parametrisation (the one the faithful corrections apply to), ``cheap RVE`` otherwise
    and at ``quick``."""
    if ident.parametrisation != "gap" or ident.settings.faithful is None:
        return "the cheap RVE"
    return f"fidelity {fidelity_name(ident.settings.faithful)}"


def _caveat(budget_entry: dict) -> dict:
    """``numerical_factor`` (the combined factor of the :data:`UNCORRECTED` effects on the
    resistance, > 1 means the resistance would be higher), ``interval_factor`` (the 90 %
    interval's half-width as a factor, ``x/F``: :data:`INTERVAL_FACTOR_NOTE`) and a
    ``caveat`` when the first exceeds the second. What that means for quoting is said once,
    by :func:`fidelity_note`, not per value."""
    width = budget_entry["interval_half_width_factor"]
    beyond = [k for k in UNCORRECTED if k in budget_entry.get("beyond_prior", [])]
    if beyond:
        return {"caveat": f"the uncorrected {' and '.join(beyond)} would move it across the "
                          "whole prior: k hardly moves with it there"}
    factors = [budget_entry["factors"].get(k) for k in UNCORRECTED]
    factors = [f for f in factors if f is not None and f > 0]
    if not factors:
        return {}
    c = math.prod(factors)
    out = {"numerical_factor": c, "interval_factor": width}
    if max(c, 1 / c) > width:
        out["caveat"] = (f"the uncorrected voxel and box effects (x{c:.2f}) exceed its "
                         f"interval (x/{width:.2f})")
    return out


def fidelity_note(settings, parameters: Mapping[str, object] | None = None,
                  marked: bool = False, gap: Identification | None = None) -> str:
    """Once, at the top of the headline: what the values of this fidelity are good for. At
    ``quick`` (no faithful correction) they are indicative, with the bias measured against
    ``standard`` on the shipped data (:data:`QUICK_TO_STANDARD`, for the gap parameters of
    ``parameters``) and what to run for values to quote; at a corrected level, what it still
    leaves out. ``parameters``: per parametrisation its parameter names (default both
    parametrisations, every parameter); ``marked``: whether some values carry a caveat
    (marked ``*``); ``gap``: the gap parametrisation's identification, where there is one
    (at the shipped level, :func:`~itr_identify.reporting.level.level_record` says what
    corrected its models)."""
    s = settings
    name = fidelity_name(s.faithful)
    if parameters is None:
        parameters = {"area": (), "gap": tuple(QUICK_TO_STANDARD)}
    star = (" Values marked * would move by more than their 90 % interval under the voxel "
            "and box effects this level leaves uncorrected (the factor is given; the error "
            "budget has each effect)." if marked else "")
    area = (f" The area parametrisation is corrected at no level: its values belong to its "
            f"{s.voxel_um:g} um voxel and {s.box_um:g} um box." if "area" in parameters
            else "")
    if s.faithful is None:
        known = [(n, r) for n, r in QUICK_TO_STANDARD.items() if n in parameters.get("gap", ())]
        bias = ""
        if known:
            bias = (" The gap parametrisation's resistances read low: on the shipped Table 3, "
                    "`--fidelity standard` gave " + " and ".join(
                        f"{n} {r:.1f} times" for n, r in known)
                    + " the `quick` value (validation/results/reproduce_fidelity.md).")
        return (f"Fidelity `{name}`: indicative values, not for quoting. The "
                f"{s.box_um:g} um RVEs at {s.voxel_um:g} um voxels are not corrected for "
                "their voxel bias or their box." + bias + star + area
                + " For values to quote, run again at the default `--fidelity shipped` (the "
                "corrections shipped with the package, same cost) or `--fidelity standard`.")
    if s.faithful.shipped:
        from ..forward.shipped import ShippedCorrections

        table = ShippedCorrections.load()
        prov = table.provenance
        boxes = ", ".join(f"{n} {s_['box_um']:g} um -> {s_['shared']['box']['converged_um']:g}"
                          " um" for n, s_ in table.systems.items())
        voxels = ", ".join(f"{n} {min(s_['shared']['voxel']['voxels_um']):g}-"
                           f"{max(s_['shared']['voxel']['voxels_um']):g} um"
                           for n, s_ in table.systems.items())
        ran = level_record(gap) if gap is not None else None
        models = dict(ran["models"]) if ran else {}
        runtime = [f for f, r in models.items() if r["source"] == "runtime"]
        if not models:
            rest = ("; a formulation they do not hold is corrected at runtime on "
                    f"{', '.join(sorted({f'{b:g} um' for _, b in s.faithful.boxes_um}))} "
                    "boxes.")
        elif runtime:
            rest = (f"; {', '.join(runtime)}, which they do not hold, were corrected in this "
                    f"run on {', '.join(sorted({f'{b:g} um' for _, b in s.faithful.boxes_um}))}"
                    f" boxes ({ran['faithful_solves_this_run']} faithful solves).")
        else:
            rest = ("; every gap model took its shipped factor: no faithful solve ran in "
                    "this run.")
        return (f"Fidelity `{name}` (the default): the gap parametrisation's level is "
                f"corrected by the corrections shipped with the package (touching particles "
                f"at the {prov['contacts']}; table box to converged box: {boxes}; voxel "
                f"bias from the same particles at {voxels}; {prov['packings']} packings; "
                f"{prov['date']}, `itr corrections show`), their uncertainty in the "
                "intervals, the box, voxel and tail terms shared by each system's "
                "formulations" + rest + star + area)
    boxes = ", ".join(f"{f} {b:g} um" for f, b in s.faithful.boxes_um)
    return (f"Fidelity `{name}`: the gap parametrisation's level is corrected on faithful "
            f"RVEs (boxes {boxes}; voxel bias removed by Richardson over "
            f"{s.faithful.voxel_um:g} and {s.faithful.coarse_voxel_um:g} um)." + star + area)


def headline(idents: Mapping[str, Identification], *,
             discrepancy: dict | None = None) -> dict:
    """The headline as plain JSON: ``quote`` (parametrisation), ``why``, ``supported`` (by
    the BIC, or None), ``fidelity``, ``fidelity_note`` and per parametrisation and parameter
    ``best``, ``interval_90`` (m^2 K/W) and ``flag``; ``quote`` and ``why`` are those of
    the report's model-selection section (:func:`parametrisation_choice`); ``discrepancy``
    (where the run asked for it): the naming rule's verdict and the identification with
    the effect (:func:`~itr_identify.reporting.naming_words.headline_entry`)."""
    flags = {p: {n: parameter_flag(i, n) for n in i.posterior.names}
             for p, i in idents.items()}
    choice = parametrisation_choice(idents, flags)
    params = {p: {n: {"best": i.posterior.best[n], "interval_90": list(i.posterior.interval(n)),
                      "flag": flags[p][n], "unit": "m^2 K/W",
                      "half_width_factor": math.sqrt(i.posterior.interval(n)[1]
                                                     / i.posterior.interval(n)[0]),
                      "best_is": ("the posterior median of ln R (Rao-Blackwell marginal)"
                                  if i.joint is not None
                                  else "the marginal posterior's central point")}
                  for n in i.posterior.names} for p, i in idents.items()}
    for p, i in idents.items():
        for n, without in i.fit.get("intervals_without", {}).items():
            params[p][n]["interval_90_without_model_form"] = list(without)
        for n, rec in i.inputs.get("parameters", {}).items():
            shares = {k: v for k, v in sorted(rec["shares"].items(), key=lambda kv: -kv[1])}
            params[p][n].update(
                best_nominal_inputs=i.at_nominal.best[n],
                interval_90_nominal_inputs=list(rec["interval_nominal"]),
                variance_shares=shares,
                narrow_first=narrowing(i.inputs, n)[0] if rec.get("if_known") else None)
    for p, ident in idents.items():
        for n, entry in error_budget(ident)["parameters"].items():
            if n in params[p]:
                params[p][n].update(_caveat(entry))
    s = next(iter(idents.values())).settings
    fidelity = fidelity_name(s.faithful)
    marked = any("caveat" in e for ps in params.values() for e in ps.values())
    return {"quote": choice["quote"], "why": choice["why"], "supported": choice["supported"],
            "fidelity": fidelity,
            "fidelity_note": fidelity_note(
                s, {p: tuple(i.posterior.names) for p, i in idents.items()}, marked,
                idents.get("gap")),
            "holds_at": f"{s.box_um:g} um box, {s.voxel_um:g} um voxels"
                        + _corrected_by(idents.get("gap")),
            "parameters": params,
            "fit": {p: {k: i.fit[k] for k in ("chi2", "dof", "p", "misfit", "model_form_sd")
                        if k in i.fit} | ({"note": misfit_note(i.fit)} if i.fit else {})
                    for p, i in idents.items()}} | (
        {"discrepancy": dict(discrepancy)} if discrepancy else {})


def _corrected_by(gap: Identification | None) -> str:
    """How the gap models' level was corrected, from the per-model record: by the shipped
    corrections, at runtime, both (naming which), or not at all."""
    if gap is None or not all(hasattr(m, "level_at") for m in gap.models.values()):
        fa = None if gap is None else gap.settings.faithful
        return ("" if fa is None else ", corrected to converged boxes by the shipped "
                "corrections" if fa.shipped else ", corrected on faithful RVEs")
    sources: dict[str, list[str]] = {}
    for f, r in level_record(gap)["models"].items():
        sources.setdefault(str(r["source"]), []).append(f)
    parts = []
    if "shipped" in sources:
        parts.append("corrected to converged boxes by the shipped corrections"
                     + ("" if len(sources) == 1 else f" ({', '.join(sources['shipped'])})"))
    if "runtime" in sources:
        parts.append("corrected on faithful RVEs in this run"
                     + ("" if len(sources) == 1 else f" ({', '.join(sources['runtime'])})"))
    if "none" in sources:
        parts.append("not corrected" + ("" if len(sources) == 1 else
                                        f" ({', '.join(sources['none'])})"))
    return ", " + "; ".join(parts) if parts else ""


def _legend(head: dict) -> str:
    marked = any("caveat" in e for ps in head["parameters"].values() for e in ps.values())
    return (f"Flags: determined (a fit that passes its test and a 90 % interval within "
            f"x/{DETERMINED_FACTOR:g}); bounded (x/F) (wider than that: F = sqrt(upper end / "
            f"lower end)); bounded on one side (the 90 % interval reaches one end of "
            f"the prior: the data bound the value from one side only); undetermined (both "
            f"ends, or wider than {UNDETERMINED_DECADES:g} decades); at the prior's edge (the "
            "best value is, and the interval reaches it); model misfit (the fit fails its "
            f"chi-square test, p < {MISFIT_P:g}: the interval carries a model-form error and "
            "the value is not a determination); voxel-specific (a per-area contact value, a "
            "property of the voxel)." + (f" {INTERVAL_FACTOR_NOTE}." if marked else ""))


def headline_lines(head: dict, width: int = 100) -> list[str]:
    """:func:`headline` as plain-text lines (the terminal): the fidelity note once, the
    values, which parametrisation to quote and why, the legend."""
    import textwrap
    from functools import partial

    wrap = partial(textwrap.wrap, width=width, break_on_hyphens=False)
    lines = wrap(head["fidelity_note"])
    for par, params in head["parameters"].items():
        mark = "  <- quote" if par == head["quote"] else ""
        lines.append(f"{par}:{mark}")
        for n, e in params.items():
            lo, hi = e["interval_90"]
            lines.append(f"  {n} = {e['best']:.2e} m^2 K/W (90 % interval {lo:.2e} - "
                         f"{hi:.2e}; {e['flag']})")
            if "interval_90_nominal_inputs" in e:
                a, b = e["interval_90_nominal_inputs"]
                lines.append(f"    at the nominal inputs: {e['best_nominal_inputs']:.2e}"
                             f" ({a:.2e} - {b:.2e})")
            if "interval_90_without_model_form" in e:
                a, b = e["interval_90_without_model_form"]
                lines.append(f"    without the model-form error: {a:.2e} - {b:.2e}")
            if e.get("variance_shares"):
                lines.append("    variance shares: " + ", ".join(
                    f"{k} {100 * v:.0f} %" for k, v in e["variance_shares"].items()))
            if e.get("narrow_first"):
                nf = e["narrow_first"]
                lines.append(f"    narrows most: measuring {nf['input']} (expected interval "
                             f"{nf['interval'][0]:.2e} - {nf['interval'][1]:.2e})")
            if "caveat" in e:
                lines.append(f"    * {e['caveat']}")
        if head.get("fit", {}).get(par, {}).get("note"):
            lines += wrap("  " + head["fit"][par]["note"], subsequent_indent="    ")
    for line in headline_entry_lines(head.get("discrepancy", {})):
        lines += wrap(line, subsequent_indent="    ")
    lines += wrap(f"quote {head['quote']}: {head['why']}.")
    lines += wrap(f"These hold at fidelity {head['fidelity']} ({head['holds_at']}); the "
                  "report's error budget gives what the RVE leaves out. " + _legend(head))
    return lines


def headline_markdown(head: dict) -> list[str]:
    """:func:`headline` as the first section of ``report.md``."""
    lines = ["## Headline", "", head["fidelity_note"], "",
             "| parametrisation | parameter | best (m^2 K/W) | 90 % interval | flag | "
             "uncorrected voxel and box effects |",
             "|---|---|---|---|---|---|"]
    for par, params in head["parameters"].items():
        name = f"**{par}** (quote)" if par == head["quote"] else par
        for n, e in params.items():
            lo, hi = e["interval_90"]
            c = e.get("numerical_factor")
            effect = "-" if c is None else f"x{c:.2f}" + (
                f" *: beyond the interval's x/{e['interval_factor']:.2f}" if "caveat" in e
                else "")
            without = e.get("interval_90_without_model_form")
            shown = f"{lo:.2e} - {hi:.2e}" + (
                "" if without is None else
                f" (without the model-form error {without[0]:.2e} - {without[1]:.2e})")
            lines.append(f"| {name} | {n} | {e['best']:.2e} | {shown} | "
                         f"{e['flag']} | {effect} |")
    notes = [f"{par}: {f['note']}" for par, f in head.get("fit", {}).items() if f.get("note")]
    if notes:
        lines += [""] + [f"- {n}" for n in notes]
    if head.get("discrepancy"):
        lines += [""] + [f"- {n}" for n in headline_entry_lines(head["discrepancy"])]
    inputs = [(par, n, e) for par, params in head["parameters"].items()
              for n, e in params.items() if e.get("variance_shares")]
    if inputs:
        lines += ["", "The conductivities (and, where none is stated, the contact film, "
                  "uniform over 0-5 nm) are sampled with the resistances "
                  "(`itr_identify.inference.joint`): the value and interval at the nominal "
                  "inputs (the paper's conductivities, film 0; the grid calibration), each "
                  "input's share of the variance of log10 of the value, and the input whose "
                  "measurement (a conductivity to 2 %, a film to 0.5 nm) would narrow the "
                  "interval most, with the interval expected over what that measurement could "
                  "give:", "",
                  "| parametrisation | parameter | at the nominal inputs | shares | "
                  "narrows most (expected interval) |", "|---|---|---|---|---|"]
        for par, n, e in inputs:
            a, b = e["interval_90_nominal_inputs"]
            at = f"{e['best_nominal_inputs']:.2e} ({a:.2e} - {b:.2e})"
            shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in e["variance_shares"].items())
            nf = e.get("narrow_first")
            narrow = "-" if not nf else (f"{nf['input']} ({nf['interval'][0]:.2e} - "
                                         f"{nf['interval'][1]:.2e})")
            lines.append(f"| {par} | {n} | {at} | {shares} | {narrow} |")
    lines += ["", f"Quote **{head['quote']}**: {head['why']}. These values hold at fidelity "
              f"`{head['fidelity']}` ({head['holds_at']}); the error budget below gives what "
              "the RVE leaves out. " + _legend(head)]
    return lines
