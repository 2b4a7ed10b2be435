"""The ``itr`` command line.

Every failure is one line on standard error, ``itr: error: ...`` naming the flag where a
flag is at fault, with exit status 2 for bad input (usage, values, output folder) and 1 for a
failure while running (packing, solver, memory, disk). No traceback is shown unless the
environment sets ``ITR_DEBUG=1``. An output folder that the command created is removed
again when the run fails; files are written atomically and ``manifest.json`` last.

Layout (imports point down only): :mod:`~itr_identify.cli.core` (the error, parser, number
types, flag names, output folder and the flags several commands share); one module per
command (``demo``, ``campaign``, ``corrections``, ``surrogate``, ``reproduce``, ``identify``,
``discrepancy``), each with ``add_parser(sub)``; :mod:`~itr_identify.cli.dispatch`
(``build_parser`` and ``main``, the console script's entry point).
"""

from .core import CLIError
from .dispatch import build_parser, main

__all__ = ["main", "build_parser", "CLIError"]
