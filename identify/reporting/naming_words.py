"""The naming rule's words (:mod:`itr_identify.discrepancy.naming`): what the verdict says, the
candidates' table, and the identification with the named effect beside the base model."""

from __future__ import annotations

import math

__all__ = ["verdict_sentence", "candidate_lines", "effect_fit_lines", "rule_sentence"]


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
        names = "; ".join(f"{verdict.candidate(k).name} (log Bayes factor "
                          f"{verdict.log_bayes_factor(k):.1f})" for k in verdict.tied)
        seps = "; ".join(f"{verdict.candidate(k).name}: {verdict.separate_by.get(k, '')}"
                         for k in verdict.tied)
        return (f"{base} **Tie**: the data do not tell apart {names}. What separates them: "
                f"{seps}.")
    if verdict.verdict == "unexplained":
        if verdict.over_threshold:
            w = verdict.winner
            return (f"{base} **Unexplained**: the best candidate, {w.name} "
                    f"({_value(w)}, log Bayes factor {verdict.log_bayes_factor(w.key):.1f}), "
                    f"leaves chi-square {w.chi_square:.1f} on {w.dof} dof (p = {w.p:.2g}): it "
                    "reduces the gap, it does not close it. The measurement to make: "
                    f"{verdict.separate_by.get(w.key, '')}.")
        return (f"{base} **Unexplained**: the base model fails its test and no candidate "
                "is over the threshold; no library effect explains the gap. The measurement "
                "to make: the density (Archimedes) and a second powder of another size, "
                "which tell the library's effects apart.")
    return f"{base} **Nothing named**: no candidate is over the threshold."


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
