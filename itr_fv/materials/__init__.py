"""Phases and interfaces: the :class:`Materials` of a solve, the flat parameter names, the
material system of a filled composite (fillers, their size distributions, conductivities),
the system file a lab writes, the handbook of common phases and the paper's shipped tables.

Modules: ``properties`` (:class:`Materials`: conductivity per phase, resistance per phase
pair), ``parameters`` (the flat names ``k_<phase>``, ``R_<A>_<B>``, ``Gc_<A>_<B>``,
``Rff_<A>_<B>``), ``psd`` (lognormal size distributions: a filler's sizes are part of its
material description, Table 1 of the paper), ``size_statement`` (sizes as a lab states
them), ``material_system``, ``system_file`` (the TOML a lab writes), ``handbook`` (common
phases with sources), ``paper_data`` (the one place the paper's tables are read) and
``formulation_names``.
"""

from .properties import CONTACT_MODELS, Materials

__all__ = ["Materials", "CONTACT_MODELS", "default_system", "is_default_system"]


def default_system():
    """The package's default material system: the paper's
    (:data:`itr_fv.materials.paper_data.PAPER_SYSTEM`). The one maker of the default: every
    settings object that holds a system takes it from here where none is given."""
    from .paper_data import PAPER_SYSTEM

    return PAPER_SYSTEM


def is_default_system(system) -> bool:
    """Whether ``system`` solves as the default one does (the same matrix, fillers,
    conductivities, size distributions and known resistances, whatever its name or
    source): what the measured defaults of the paper's system (its shipped corrections,
    its fidelity levels' boxes) hold for."""
    return system.solve_inputs() == default_system().solve_inputs()
