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

from ...contract.family import Family


class InterconnectedUIO(Family):
    name = "interconnected_uio"
    title = "two-stage interconnected LPV unknown-input observer"
    citation = "Sentouh, Fouka, Popieul, Sensors 23, 4236, 2023"
    short_citation = "Sentouh et al. 2023"
    observer_keys = {}
    example = "interconnected_uio"
    # capabilities (codegen.contract.capabilities): Scenarios, DemoFigures, Applicability
    demo_scenarios = ("satory",)
    table_note = "the paper's Table 1 format"

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, solver):
        from .build import build
        return build(config, solver)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run_scenario
        return run_scenario(config, scenario, plant, duration, progress=progress, observer=observer)

    def validation_table(self, result: dict) -> str:
        from .validation import format_result
        return format_result(result)

    def demo_report(self, art: dict) -> dict:
        extras = art["certificate"]["extras"]
        cert = extras["recheck"]
        return {"worst_lmi_margin": cert["worst_min_eig"], "worst_lmi_block": cert["worst_block"],
                "discrete": extras["discrete"]}

    def draw_random_model(self, rng):
        """A random small valid model of this family (:mod:`codegen.families.random_models`)."""
        from ..random_models import draw_interconnected
        return draw_interconnected(rng)


FAMILY = InterconnectedUIO()
