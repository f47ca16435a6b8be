"""Discrete-time Takagi-Sugeno fuzzy unknown-input observer with measured and unmeasured
nonlinear consequents (differential mean-value theorem, Lemma 3 relaxation).

Nguyen, Dinh, Guerra, Pan, "Takagi-Sugeno Fuzzy Unknown Input Observers to Estimate Nonlinear
Dynamics of Autonomous Ground Vehicles: Theory and Real-Time Verification", IEEE/ASME
Transactions on Mechatronics 26(3), 2021 (observer (16)-(17), (30), Theorem 1 LMIs (27)).

``representation``: the TS form with Jacobian bounds; ``design``: (30) and the LMIs (27), the
step (16); ``build``: the pipeline; ``validation``: the paper's scenarios and Table II.
"""
from __future__ import annotations

from ..base import Family


class TSFuzzyUIO(Family):
    name = "ts_fuzzy_uio"
    title = "discrete-time TS fuzzy unknown-input observer"
    citation = "Nguyen, Dinh, Guerra, Pan, IEEE/ASME T-Mech 26(3), 2021"
    short_citation = "Nguyen et al. 2021"
    observer_keys = {}
    bounds_settings = ("bounds_rel_tol", "bounds_max_boxes")
    demo_scenarios = ("random_trajectory_accel", "circular_path_normal", "time_varying_grip_normal")
    example = "ts_fuzzy_uio"

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, tol=None):
        from .build import build
        return build(config, tol)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run
        return run(config, scenario, plant, duration, progress=progress, observer=observer)

    def demo_plant(self, config) -> str:
        """An observer designed for a CommonRoad car runs on the multi-body plant, the counterpart of
        the paper's 15-DOF simulator; the others on their model module's (Pacejka) truth plant."""
        from ...model import load_parameters
        meta = load_parameters(config.parameter_path).meta
        return "commonroad" if meta.get("commonroad_vehicle") is not None else "nominal"

    def format_validation(self, result: dict) -> str:
        from .validation import format_table
        return format_table(result)

    def validation_header(self, name: str, result: dict) -> str:
        from ...validation.common import SETTLE_TIME
        return (f"{name}: scenario {result['scenario']} on the {result['plant']} plant ({result['plant_model']}), "
                f"{result['samples']} samples, max |a_y| {result['max_abs_ay']:.2f} m/s^2, {result['status_flags']} "
                f"flagged samples; errors after {SETTLE_TIME:g} s (SI units, the paper's Table II format)")

    def demo_report(self, art: dict) -> dict:
        cert = art["certificate"]["recheck"]
        return {"worst_lmi_margin": cert["worst_min_eig"], "worst_lmi_block": cert["worst_block"],
                "lmi_blocks": cert["blocks"], "lyapunov_decrease": art["certificate"]["lyapunov_decrease_33"]}

    def bench_family(self) -> list:
        from .scaling import growth
        return growth()

    def bench_family_lines(self, rows: list) -> list:
        from .scaling import lines
        return ["design growth with the number of rules (one model family, fresh process per point):", *lines(rows)]

    def demo_lines(self, e: dict) -> list:
        return [f"LMIs (27) ({self.short_citation}): {e['lmi_blocks']} blocks, worst margin {e['worst_lmi_margin']:.3g} "
                f"in {e['worst_lmi_block']}; (33) on random samples: sqrt(V) contracts by "
                f"{e['lyapunov_decrease']['contraction_per_step']:.6f}/step"]


FAMILY = TSFuzzyUIO()
