"""itr_identify (the repository folder ``identify/``): measurement data reduction, ITR
screening and calibration, validation against measurements, the discrepancy workflow and
the ``itr`` command line.

Subpackages, each below the next in the import order (no import points up):

- :mod:`itr_identify.forward`: forward models per formulation (RVE replicas, reduced basis);
- :mod:`itr_identify.inference`: measurements, formulation names, calibration, screening,
  validation and the staged identification pipeline;
- :mod:`itr_identify.discrepancy`: candidate effects, forward tables, model fits, the
  decision, synthetic measurements;
- :mod:`itr_identify.reporting`: report tables and figures;
- :mod:`itr_identify.workflows`: the jobs (``reproduce``, ``identify``, ``discrepancy``,
  ``demo``) that write an output folder;
- :mod:`itr_identify.cli`: the ``itr`` command line (a common core and one module per
  command).
"""
