"""Discrete-time Takagi-Sugeno fuzzy unknown-input observer with measured and unmeasured
nonlinear consequents (differential mean-value theorem, Lemma 3 relaxation).

Nguyen, Dinh, Guerra, Pan, "Takagi-Sugeno Fuzzy Unknown Input Observers to Estimate Nonlinear
Dynamics of Autonomous Ground Vehicles: Theory and Real-Time Verification", IEEE/ASME
Transactions on Mechatronics 26(3), 2021 (observer (16)-(17), (30), Theorem 1 LMIs (27)).

``representation``: the TS form with Jacobian bounds; ``design``: (30) and the LMIs (27), the
step (16); ``build``: the pipeline; ``validation``: the paper's scenarios and Table II.
"""
from __future__ import annotations

from ...contract.family import Family


class TSFuzzyUIO(Family):
    name = "ts_fuzzy_uio"
    title = "discrete-time TS fuzzy unknown-input observer"
    citation = "Nguyen, Dinh, Guerra, Pan, IEEE/ASME T-Mech 26(3), 2021"
    short_citation = "Nguyen et al. 2021"
    observer_keys = {}
    bounds_settings = ()       # its Jacobian bounds short of their tolerance are sound enclosures, never refused
    example = "ts_fuzzy_uio"
    # capabilities (codegen.contract.capabilities): Scenarios, DemoPlant, DemoFigures, BenchStudy, Applicability
    demo_scenarios = ("random_trajectory_accel", "circular_path_normal", "time_varying_grip_normal")
    table_note = "the paper's Table II format, then every figure in its unit"

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, solver):
        from .build import build
        return build(config, solver)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run
        return run(config, scenario, plant, duration, progress=progress, observer=observer)

    def demo_plant(self, config) -> str:
        """An observer designed for a CommonRoad car runs on the multi-body plant, the counterpart of
        the paper's 15-DOF simulator; the others on their model module's (Pacejka) truth plant."""
        from ...model import load_parameters
        meta = load_parameters(config.parameter_path).meta
        return "commonroad" if meta.get("commonroad_vehicle") is not None else "nominal"

    def validation_table(self, result: dict) -> str:
        from .validation import format_table
        return format_table(result)

    def demo_report(self, art: dict) -> dict:
        extras = art["certificate"]["extras"]
        cert = extras["recheck"]
        return {"worst_lmi_margin": cert["worst_min_eig"], "worst_lmi_block": cert["worst_block"],
                "lmi_blocks": cert["blocks"], "lyapunov_decrease": extras["lyapunov_decrease_33"]}

    def bench_family(self) -> list:
        from .scaling import growth
        return growth()

    def bench_family_table(self, rows: list) -> list:
        from .scaling import lines
        return ["design growth with the number of rules (one model family, fresh process per point):", *lines(rows)]

    def draw_random_model(self, rng):
        """A random small valid model of this family (:mod:`codegen.families.random_models`)."""
        from ..random_models import draw_ts
        return draw_ts(rng)


FAMILY = TSFuzzyUIO()
