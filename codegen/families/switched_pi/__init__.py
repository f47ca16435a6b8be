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

from ...project.settings import Rule
from ..base import Family


class SwitchedPI(Family):
    name = "switched_pi"
    title = "switched H-infinity PI observer"
    citation = "Menhour, Koenig, d'Andrea-Novel, ECC 2014"
    short_citation = "Menhour et al. 2014"
    observer_keys = {"switching": Rule(dict)}
    demo_scenarios = ("banked_road_braking", "braking_on_bend")
    example = "switched_pi_bank_angle"
    campaign_plant = "banked_road"
    certified_gain_norm = "l2"

    def sensor_noise(self) -> dict:
        from .validation import SENSOR_NOISE
        return dict(SENSOR_NOISE)

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, tol=None):
        from .build import build
        return build(config, tol)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run_scenario
        return run_scenario(config, scenario, plant, duration, seed, progress=progress, observer=observer)

    def format_validation(self, result: dict) -> str:
        from .validation import format_table
        return format_table(result)

    def validation_header(self, name: str, result: dict) -> str:
        from ...validation.common import SETTLE_TIME
        return (f"{name}: scenario {result['scenario']} on the {result['plant']} plant ({result['plant_model']}), "
                f"{result['samples']} samples, max |a_y| {result['max_abs_ay']:.2f} m/s^2, {result['status_flags']} "
                f"flagged samples; errors after {SETTLE_TIME:g} s (angles in degrees)")

    def demo_report(self, art: dict) -> dict:
        return {"gamma": art["gamma"], "hinf": art["certificate"]["hinf"],
                "worst_lmi_margin": art["certificate"]["recheck"]["worst_min_eig"],
                "discrete": {k: art["discrete"][k] for k in ("contraction_per_step", "spectral_radius_max")},
                "modes": len(art["switched_model"]["points"])}

    def demo_lines(self, e: dict) -> list:
        from .build import PAPER_GAMMA
        return [f"{self.title} ({self.short_citation}), {e['modes']} modes: gamma {e['gamma']:.6g} (paper: "
                f"{PAPER_GAMMA}), max mode H-inf norm {e['hinf']['max_hinf']:.6g} (Hamiltonian bisection and sweep); "
                f"discrete step: sqrt(V) contracts by {e['discrete']['contraction_per_step']:.6f}/step in every mode"]


FAMILY = SwitchedPI()
