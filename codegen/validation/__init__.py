"""Validation: an observer against scenarios and real logs, the plants that drive it, the demo.

Modules:

* :mod:`codegen.validation.run`               ``uiogen validate --scenario``: a simulated run through an observer
* :mod:`codegen.validation.logs`              ``uiogen validate --data``: a logged run, one path for every format
* :mod:`codegen.validation.simulate`          the nominal plant (the observer's own model, integrated exactly)
* :mod:`codegen.validation.demo`              ``uiogen demo``: every observer on its scenarios and the real log
* :mod:`codegen.validation.metrics`           per-signal error metrics of the paper papers
* :mod:`codegen.validation.stanford`          the shared logs' format: loader and checks
* :mod:`codegen.validation.peers`             the estimators run beside an observer on a log (KF, EKF, UKF)
* :mod:`codegen.validation.commonroad_plant`  CommonRoad multi-body plant driven by steering torques
* :mod:`codegen.validation.scenarios`         named, seeded, reproducible input profiles

Nothing here is imported by the toolchain itself; :mod:`commonroad_plant` needs the optional
``commonroad-vehicle-models`` distribution and imports it lazily.
"""
