"""Continuous-time switched H-infinity proportional-integral observer with a common Lyapunov matrix;
switching on speed or on slip angle.

Menhour, Koenig, d'Andrea-Novel, "Continuous-Time Switched H-infinity Proportional-Integral
Observer: Application for Sideslip and Road Bank Angles Estimation", ECC 2014 (Algorithm 1,
Theorem 2 LMI (20), switching rules (25), (27)).

``representation``: the modes from a switching rule given as data; ``design``: Algorithm 1, the
LMIs (20), the H-infinity check and the exact ZOH of each mode; ``build``: the pipeline;
``validation``: banked-road scenarios on the roll plant and the CommonRoad plant.
"""
from __future__ import annotations

from ...settings import Rule
from ...contract.family import Family


class SwitchedPI(Family):
    name = "switched_pi"
    title = "switched H-infinity PI observer"
    citation = "Menhour, Koenig, d'Andrea-Novel, ECC 2014"
    short_citation = "Menhour et al. 2014"
    observer_keys = {"switching": Rule(dict)}
    example = "switched_pi_bank_angle"
    # capabilities (codegen.contract.capabilities): Scenarios, DemoFigures, Campaigns, Applicability
    demo_scenarios = ("banked_road_braking", "braking_on_bend")
    table_note = "angles in degrees"
    campaign_plant = "banked_road"
    certified_gain_norm = "l2"

    def sensor_noise(self) -> dict:
        from .validation import SENSOR_NOISE
        return dict(SENSOR_NOISE)

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, solver):
        from .build import build
        return build(config, solver)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run_scenario
        return run_scenario(config, scenario, plant, duration, seed, progress=progress, observer=observer)

    def validation_table(self, result: dict) -> str:
        from .validation import format_table
        return format_table(result)

    def demo_report(self, art: dict) -> dict:
        extras = art["certificate"]["extras"]
        return {"gamma": art["gamma"], "hinf": extras["hinf"],
                "worst_lmi_margin": extras["recheck"]["worst_min_eig"],
                "discrete": {k: art["discrete"][k] for k in ("contraction_per_step", "spectral_radius_max")},
                "modes": len(art["switched_model"]["points"])}

    def draw_random_model(self, rng):
        """A random small valid model of this family (:mod:`codegen.families.random_models`)."""
        from ..random_models import draw_switched
        return draw_switched(rng)


FAMILY = SwitchedPI()
