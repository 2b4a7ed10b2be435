"""Readable figure labels: the one place where a flat parameter name
(:mod:`itr_fv.materials.parameters`: ``k_<phase>``, ``R_<A>_<B>``, ``Rff_<A>_<B>``, ``Gc_<A>_<B>``)
becomes a symbol with its unit, in matplotlib mathtext.

>>> parameter_label("R_Al2O3_silicone")
'$R_{\\\\mathrm{Al_{2}O_{3}/silicone}}$ (m$^2$ K/W)'
"""

from __future__ import annotations

import re

from itr_fv.materials.parameters import UNITS, parse_parameter

__all__ = ["MICRO_M", "phase_label", "parameter_symbol", "parameter_unit", "parameter_label"]

#: Micrometre with the micro sign (U+00B5), for every figure text.
MICRO_M = "µm"

#: Mathtext symbol of each parameter kind; ``{p}`` is the phase (pair) subscript.
_SYMBOLS = {"k": "k_{{{p}}}", "R": "R_{{{p}}}", "Rff": "R^{{\\mathrm{{contact}}}}_{{{p}}}",
            "Gc": "G^{{\\mathrm{{contact}}}}_{{{p}}}"}


def _math_phase(phase: str) -> str:
    """A phase name in mathtext roman with its digits as subscripts (``Al_{2}O_{3}``)."""
    return re.sub(r"(\d+)", r"_{\1}", phase)


def phase_label(phase: str) -> str:
    """A phase name or a ``+``-joined system for titles and legends: ``Al2O3`` ->
    ``$\\mathrm{Al_{2}O_{3}}$`` (names without digits stay plain text)."""
    parts = [p if not re.search(r"\d", p) else f"$\\mathrm{{{_math_phase(p)}}}$"
             for p in str(phase).split("+")]
    return "+".join(parts)


def parameter_symbol(name: str) -> str:
    """Mathtext symbol of a flat parameter name, without unit: ``R_Al2O3_silicone`` ->
    ``$R_{\\mathrm{Al_{2}O_{3}/silicone}}$``. ValueError (naming it) if malformed."""
    kind, phases = parse_parameter(name)
    sub = "\\mathrm{" + "/".join(_math_phase(p) for p in phases) + "}"
    return "$" + _SYMBOLS[kind].format(p=sub) + "$"


def parameter_unit(name: str) -> str:
    """The unit of a flat parameter name as figure text (``m$^2$ K/W``, ``W/(m K)``,
    ``W/K``), from :data:`itr_fv.materials.parameters.UNITS`."""
    kind, _ = parse_parameter(name)
    return UNITS[kind].replace("^2", "$^2$")


def parameter_label(name: str, *, log10: bool = False) -> str:
    """Axis label of a parameter: its symbol and unit, e.g. ``R_Al2O3_silicone`` ->
    ``R_{Al2O3/silicone} (m^2 K/W)`` in mathtext; with ``log10=True`` the label of an axis
    of decimal logarithms, ``log10(R_{Al2O3/silicone} / (m^2 K/W))``."""
    if log10:
        return f"$\\log_{{10}}$({parameter_symbol(name)} / ({parameter_unit(name)}))"
    return f"{parameter_symbol(name)} ({parameter_unit(name)})"
