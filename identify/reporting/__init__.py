"""Reports of the workflows: markdown tables (:mod:`~itr_identify.reporting.report`,
:mod:`~itr_identify.reporting.discrepancy_report`) and figures
(:mod:`~itr_identify.reporting.figures`)."""
