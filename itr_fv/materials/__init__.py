"""Phases and interfaces: the :class:`Materials` of a solve, the flat parameter names, the
material system of a filled composite (fillers, their size distributions, conductivities)
and the paper's shipped tables.

Modules: ``properties`` (:class:`Materials`: conductivity per phase, resistance per phase
pair), ``parameters`` (the flat names ``k_<phase>``, ``R_<A>_<B>``, ``Gc_<A>_<B>``,
``Rff_<A>_<B>``), ``psd`` (lognormal size distributions: a filler's sizes are part of its
material description, Table 1 of the paper), ``material_system``, ``paper_data`` (the one
place the paper's tables are read) and ``formulation_names``.
"""

from .properties import CONTACT_MODELS, Materials

__all__ = ["Materials", "CONTACT_MODELS"]
