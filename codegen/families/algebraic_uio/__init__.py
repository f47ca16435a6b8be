"""Algebraic LPV unknown-input observers for relative degree 1 and arbitrary r, with Levant's
higher-order sliding-mode differentiators for the output derivatives.

Ichalal, Mammar, "On Unknown Input Observers for LPV Systems", IEEE Transactions on Industrial
Electronics 62(9), 2015 (observers (23), (59), (85)/(86); LMI (39); Examples 1-3).

``representation``: relative degrees, M, Gamma, Q, P proven uniform on the box; ``design``: the
classical-UIO check and the LMI (39); ``build``: the pipeline and the step (Gauss-Legendre,
HOSMD); ``validation``: the paper's examples, scenarios as data in the observer file.
"""
from __future__ import annotations

from ...settings import Rule
from ...contract.family import Family


class AlgebraicUIO(Family):
    name = "algebraic_uio"
    title = "algebraic LPV unknown-input observer"
    citation = "Ichalal, Mammar, IEEE T-IE 62(9), 2015"
    short_citation = "Ichalal and Mammar 2015"
    observer_keys = {"validation": Rule(dict, doc="scenarios [validation.NAME] (see the family's validation)")}
    example = "algebraic_uio_example2"
    # capabilities (codegen.contract.capabilities): Scenarios, DemoFigures, BenchFigures, Applicability
    demo_scenarios = ("paper",)
    table_note = "the paper's examples, compiled C step"

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, solver):
        from .build import build
        return build(config, solver)

    def validate(self, config, scenario, plant="nominal", duration=None, seed=0, progress=None, observer=None) -> dict:
        from .validation import run
        return run(config, scenario, plant, duration, seed, progress=progress, observer=observer)

    def validation_table(self, result: dict) -> str:
        from .validation import format_table
        return format_table(result)

    def bench_inputs(self, build):
        from .validation import periodic_inputs      # the paper's scenario, tiled (differentiators settle)
        return periodic_inputs(build)

    def bench_figures(self, build) -> dict:
        from ...representation import differentiators
        from ...emit.flops import flop_count
        specs = build.settings.differentiators
        return {"hosmd_flops_per_step": sum(flop_count(differentiators.hosmd_function(s))["total"]
                                            for s in specs.values()),
                "differentiator_orders": {k: s.order for k, s in specs.items()}}

    def demo_report(self, art: dict) -> dict:
        return {"relative_degrees": art["decoupling"]["relative_degrees"],
                "classical_uio_exists": art["classical_uio_11"]["exists"],
                "worst_lmi_margin": art["certificate"]["extras"]["recheck"]["worst_min_eig"], "discrete": art["discrete"]}

    def draw_random_model(self, rng):
        """A random small valid model of this family (:mod:`codegen.families.random_models`)."""
        from ..random_models import draw_algebraic
        return draw_algebraic(rng)


FAMILY = AlgebraicUIO()
