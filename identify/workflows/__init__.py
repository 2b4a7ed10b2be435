"""The jobs of the ``itr`` command, each writing one output folder (manifest last):
:func:`~itr_identify.workflows.reproduce.run_reproduce` and
:func:`~itr_identify.workflows.reproduce.run_identify`,
:func:`~itr_identify.workflows.discrepancy.run_discrepancy` and
:func:`~itr_identify.workflows.demo.run_demo`."""
