"""The naming rule's words (:mod:`itr_identify.discrepancy.naming`): what the verdict says, the
candidates' table, and the identification with the named effect beside the base model."""

from __future__ import annotations

import math

__all__ = ["verdict_sentence", "candidate_lines", "effect_fit_lines", "rule_sentence",
           "headline_entry", "headline_entry_lines", "measurement_to_make"]


def _num(x: float) -> str:
    return f"{x:.3g}"


def _value(fit) -> str:
    """The effect's value as a reader reads it (a log parameter back in its unit)."""
    med, lo, hi = fit.value
    name = fit.parameter
    if name.startswith("ln "):
        med, lo, hi = (math.exp(v) for v in (med, lo, hi))
        name = name[3:] + (" / nominal" if name.startswith("ln k_") else "")
    return f"{name} = {_num(med)} (90 % {_num(lo)} - {_num(hi)})"


def rule_sentence(verdict) -> str:
    """The rule in one sentence, with its settings."""
    s = verdict.settings
    return (f"An effect is named when its log Bayes factor over the base model is at least "
            f"{s.threshold:g} (a factor of {math.exp(s.threshold):.0f}), no other candidate "
            f"comes within {s.tie_margin:g} of it, and its own fit passes (chi-square p >= "
            f"{s.fit_p:g}); every model is the identification's joint model without the "
            "model-form term, the candidates with their effect's parameters added.")


def verdict_sentence(verdict) -> str:
    """What the rule says of the table, in one paragraph."""
    b = verdict.base
    base = (f"The base model's fit: chi-square {b.chi_square:.1f} on {b.dof} dof "
            f"(p = {b.p:.2g}).")
    if verdict.verdict == "named":
        w = verdict.winner
        return (f"{base} **Named: {w.name}**, {_value(w)}, log Bayes factor "
                f"{verdict.log_bayes_factor(w.key):.1f}; with it chi-square {w.chi_square:.1f} "
                f"on {w.dof} dof (p = {w.p:.2g}).")
    if verdict.verdict == "tie":
        return (f"{base} **Tie**: the data do not tell apart {_tied_names(verdict)}. What "
                f"separates them: {_separating(verdict)}. The resistances each would leave: "
                f"{_leaves(verdict)}.")
    if verdict.verdict == "unexplained":
        if verdict.tied:
            return (f"{base} **Unexplained**: {_tied_names(verdict)} tie at the top; each "
                    "reduces the gap and none closes it ("
                    + "; ".join(f"{verdict.candidate(k).name}: chi-square "
                                f"{verdict.candidate(k).chi_square:.1f} on "
                                f"{verdict.candidate(k).dof} dof, p = "
                                f"{verdict.candidate(k).p:.2g}" for k in verdict.tied)
                    + f"). The measurement to make: {measurement_to_make(verdict)}. The "
                    "resistances "
                    f"each would leave: {_leaves(verdict)}.")
        if verdict.over_threshold:
            w = verdict.winner
            return (f"{base} **Unexplained**: the best candidate, {w.name} "
                    f"({_value(w)}, log Bayes factor {verdict.log_bayes_factor(w.key):.1f}), "
                    f"leaves chi-square {w.chi_square:.1f} on {w.dof} dof (p = {w.p:.2g}): it "
                    "reduces the gap, it does not close it. The measurement to make: "
                    f"{measurement_to_make(verdict)}.")
        return (f"{base} **Unexplained**: the base model fails its test and no candidate "
                "is over the threshold; no library effect explains the gap. The measurement "
                f"to make: {measurement_to_make(verdict)}.")
    return f"{base} **Nothing named**: no candidate is over the threshold."


#: What to measure where no candidate is over the threshold and the base fails.
GENERIC_MEASUREMENT = ("the density (Archimedes) and a second powder of another size, which "
                       "tell the library's effects apart")


def measurement_to_make(verdict) -> str:
    """The measurement that would tell the verdict's leading candidates apart (the tied
    ones, else the best over the threshold), else :data:`GENERIC_MEASUREMENT`."""
    if verdict.tied:
        return _separating(verdict)
    if verdict.over_threshold:
        w = verdict.winner
        return f"for {w.name}, {verdict.separate_by.get(w.key, '')}"
    return GENERIC_MEASUREMENT


def headline_entry(verdict=None, effect_fit=None) -> dict:
    """The verdict and the identification with the effect as the headline carries them
    (plain JSON): ``verdict``, ``text`` (one sentence), ``measurement`` (where nothing is
    named) and, with ``effect_fit``, per resistance its value and interval under the base
    model and with the effect."""
    out: dict = {}
    if verdict is not None:
        out["verdict"] = verdict.verdict
        if verdict.verdict == "named":
            w = verdict.winner
            out["text"] = (f"named {w.name}, {_value(w)} (log Bayes factor "
                           f"{verdict.log_bayes_factor(w.key):.1f} over the base model)")
        elif verdict.verdict == "none":
            out["text"] = ("nothing named: the base model passes its test without the "
                           "model-form term and no candidate is over the threshold")
        elif verdict.verdict == "tie":
            out["text"] = ("tie: " + " and ".join(verdict.candidate(k).name
                                                  for k in verdict.tied)
                           + " explain the table alike")
        else:
            lead = verdict.tied or verdict.over_threshold[:1]
            which = (" and ".join(verdict.candidate(k).name for k in lead)
                     + (" tie: each reduces the gap, none closes it" if len(lead) > 1
                        else " reduces the gap, does not close it")) if lead else (
                "no library effect is over the threshold")
            out["text"] = ("unexplained: the base model fails its test without the "
                           f"model-form term (chi-square {verdict.base.chi_square:.1f} on "
                           f"{verdict.base.dof} dof); {which}")
            out["measurement"] = measurement_to_make(verdict)
        if verdict.tied:
            out["each_would_leave"] = {verdict.candidate(k).name: {
                n: list(v) for n, v in verdict.candidate(k).resistances.items()}
                for k in verdict.tied}
    if effect_fit is not None:
        b, e = effect_fit.base, effect_fit.effect
        out["effect"] = {
            "name": e.name, "value": _value(e),
            "resistances": {n: {"base": list(b.resistances[n]),
                                "with_effect": list(e.resistances[n])}
                            for n in b.resistances if n in e.resistances},
            "chi_square": {"base": [b.chi_square, b.dof, b.p],
                           "with_effect": [e.chi_square, e.dof, e.p]},
            "leave_one_out": {"base": list(effect_fit.loo_inside("base")),
                              "with_effect": list(effect_fit.loo_inside("effect"))}}
    return out


def headline_entry_lines(entry: dict) -> list[str]:
    """:func:`headline_entry` as plain lines (terminal and report)."""
    lines = []
    if "text" in entry:
        lines.append(f"discrepancy: {entry['text']}"
                     + (f"; the measurement to make: {entry['measurement']}"
                        if entry.get("measurement") else "") + ".")
    for name, res in entry.get("each_would_leave", {}).items():
        lines.append(f"  were it {name}: " + ", ".join(
            f"{n} = {m:.2e} ({lo:.2e} - {hi:.2e})" for n, (m, lo, hi) in res.items()))
    e = entry.get("effect")
    if e:
        (cb, db, pb), (ce, de, pe) = e["chi_square"]["base"], e["chi_square"]["with_effect"]
        lines.append(f"with {e['name']} ({e['value']}), without the model-form term:")
        for n, r in e["resistances"].items():
            (mb, lb, hb), (me, le, he) = r["base"], r["with_effect"]
            lines.append(f"  {n} = {me:.2e} ({le:.2e} - {he:.2e}) m^2 K/W; base model "
                         f"{mb:.2e} ({lb:.2e} - {hb:.2e})")
        lo_b, lo_e = e["leave_one_out"]["base"], e["leave_one_out"]["with_effect"]
        lines.append(f"  chi-square {ce:.1f} on {de} (p = {pe:.2g}); base model {cb:.1f} on "
                     f"{db} (p = {pb:.2g}); leave-one-out inside the 90 % interval "
                     f"{lo_e[0]} of {lo_e[1]} (base {lo_b[0]} of {lo_b[1]})")
    return lines


def _tied_names(verdict) -> str:
    return " and ".join(f"{verdict.candidate(k).name} (log Bayes factor "
                        f"{verdict.log_bayes_factor(k):.1f})" for k in verdict.tied)


def _separating(verdict) -> str:
    return "; ".join(f"for {verdict.candidate(k).name}, {verdict.separate_by.get(k, '')}"
                     for k in verdict.tied)


def _leaves(verdict) -> str:
    """Per tied candidate the resistances (median, 90 %) the identification would give
    were it the effect."""
    return "; ".join(
        f"under {verdict.candidate(k).name}, " + ", ".join(
            f"{n} {_num(m)} ({_num(lo)} - {_num(hi)})"
            for n, (m, lo, hi) in verdict.candidate(k).resistances.items())
        for k in verdict.tied)


def candidate_lines(verdict) -> list[str]:
    """The candidates' table: evidence, fit, value, resistances."""
    lines = ["| model | log Bayes factor | chi-square / dof (p) | value (90 %) | "
             "resistances (median, 90 %) |", "|---|---|---|---|---|"]
    for fit in (verdict.base, *verdict.candidates):
        lbf = "0 (base)" if fit.key == "base" else f"{verdict.log_bayes_factor(fit.key):.1f}"
        value = _value(fit) if fit.value else "-"
        res = "; ".join(f"{n} {_num(m)} ({_num(lo)} - {_num(hi)})"
                        for n, (m, lo, hi) in fit.resistances.items())
        lines.append(f"| {fit.name} | {lbf} | {fit.chi_square:.1f} / {fit.dof} "
                     f"({fit.p:.2g}) | {value} | {res} |")
    return lines


def effect_fit_lines(effect_fit) -> list[str]:
    """The identification with the effect beside the base model."""
    b, e = effect_fit.base, effect_fit.effect
    ib, nb = effect_fit.loo_inside("base")
    ie, ne = effect_fit.loo_inside("effect")
    lines = ["| | base model | with " + e.name + " |", "|---|---|---|"]
    for n in b.resistances:
        mb, lb, hb = b.resistances[n]
        me, le, he = e.resistances.get(n, (float("nan"),) * 3)
        lines.append(f"| {n} (m^2 K/W) | {_num(mb)} ({_num(lb)} - {_num(hb)}) | "
                     f"{_num(me)} ({_num(le)} - {_num(he)}) |")
    lines += [f"| {e.parameter} | - | {_value(e)} |",
              f"| chi-square without the model form | {b.chi_square:.1f} on {b.dof} "
              f"(p = {b.p:.2g}) | {e.chi_square:.1f} on {e.dof} (p = {e.p:.2g}) |",
              f"| leave-one-out inside the 90 % interval | {ib} of {nb} | {ie} of {ne} |"]
    return lines
