"""Two-stage interconnected LPV unknown-input observer (longitudinal + lateral subsystems, ISS
LMIs); unknown inputs by HOSMD and algebraic inversion.

Sentouh, Fouka, Popieul, "Virtual Sensor: Simultaneous State and Input Estimation for Nonlinear
Interconnected Ground Vehicle System Dynamics", Sensors 23, 4236, 2023 (model (1)-(7), T-S form
(8)-(13), design (17)-(28), UI reconstruction (29)-(31)).

``representation``: the subsystem split and coupling signals; ``design``: (26), the LMIs (27),
the gains (28) and the certificates; ``build``: the step and the pipeline; ``validation``: the
Satory track on the CommonRoad plant, Table 1 of the paper.
"""
from __future__ import annotations

from ..base import Family


class InterconnectedUIO(Family):
    name = "interconnected_uio"
    title = "two-stage interconnected LPV unknown-input observer"
    citation = "Sentouh, Fouka, Popieul, Sensors 23, 4236, 2023"
    short_citation = "Sentouh et al. 2023"
    observer_keys = {}
    demo_scenarios = ("satory",)
    example = "interconnected_uio"

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, tol=None):
        from .build import build
        return build(config, tol)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run_scenario
        return run_scenario(config, scenario, plant, duration, progress=progress, observer=observer)

    def format_validation(self, result: dict) -> str:
        from .validation import format_result
        return format_result(result)

    def validation_header(self, name: str, result: dict) -> str:
        from ...validation.common import SETTLE_TIME
        return (f"{name}: scenario {result['scenario']} on the {result['plant']} plant ({result['plant_model']}), "
                f"{result['samples']} samples, max |a_y| {result['max_abs_ay']:.2f} m/s^2, {result['status_flags']} "
                f"flagged samples; errors after {SETTLE_TIME:g} s (the paper's Table 1 format)")

    def demo_report(self, art: dict) -> dict:
        cert = art["certificate"]["recheck"]
        return {"worst_lmi_margin": cert["worst_min_eig"], "worst_lmi_block": cert["worst_block"],
                "discrete": art["certificate"]["discrete"]}

    def demo_lines(self, e: dict) -> list:
        d = e["discrete"]
        return [f"LMIs (27) ({self.short_citation}): worst margin {e['worst_lmi_margin']:.3g} in {e['worst_lmi_block']}; "
                f"discrete step: sqrt(V) contracts by {d['longitudinal']['contraction_per_step']:.6f} "
                f"(longitudinal), {d['lateral']['contraction_per_step']:.6f} (lateral) per step"]


FAMILY = InterconnectedUIO()
