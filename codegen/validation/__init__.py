"""Validation groundwork: error metrics, real-data baselines, an independent plant, scenarios.

Modules:

* :mod:`codegen.validation.metrics`           per-signal error metrics of the paper papers
* :mod:`codegen.validation.stanford`          Stanford sideslip data set loader, KF and EKF baselines
* :mod:`codegen.validation.commonroad_plant`  CommonRoad multi-body plant driven by steering torques
* :mod:`codegen.validation.scenarios`         named, seeded, reproducible input profiles

Nothing here is imported by the toolchain itself; :mod:`commonroad_plant` needs the optional
``commonroad-vehicle-models`` distribution and imports it lazily.
"""
