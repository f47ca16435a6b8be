"""Observer of a nonlinear model with nonlinear outputs, by the differential mean value theorem.

Zemouche, Boutayeb, Bara, "Observer design for nonlinear systems: an approach based on the differential
mean value theorem", 44th IEEE CDC-ECC 2005, applied here to the outputs h as to the dynamics f: the error
of x_hat+ = x_hat + Ts f(x_hat) + L (y - h(x_hat)) is a linear system whose matrices lie in the box of the
Jacobians of f AND h over the set the state stays in, so one Lyapunov matrix at the box's corners
certifies the observer for any model whose Jacobians are bounded there, outputs y = h(x) included (a
lateral acceleration through tyre laws). The gains minimise a certified noise bound (ours).

``representation``: the model with its boxes and the sound Jacobian bounds; ``design``: the LMIs and
the gains that minimise the certified RMS bound at the sensors' noise levels; ``build``: the pipeline
and the step. Without unknown inputs: it estimates the state.
"""
from __future__ import annotations

from ...contract.family import Family


class DMVTObserver(Family):
    name = "dmvt_observer"
    title = "DMVT observer of a nonlinear model with nonlinear outputs"
    citation = "Zemouche, Boutayeb, Bara, 44th IEEE CDC-ECC 2005"
    short_citation = "Zemouche et al. 2005"
    observer_keys = {}
    bounds_settings = ("bounds_rel_tol", "bounds_max_boxes")
    example = "roll_sedan_tanh_dmvt"
    # capabilities (codegen.contract.capabilities): Applicability, RandomModels

    def applicability(self, subject, structure):
        from .applicability import assess
        return assess(self, subject, structure)

    def build(self, config, solver):
        from .build import build
        return build(config, solver)

    def draw_random_model(self, rng):
        """A random small valid model of this family (:mod:`codegen.families.random_models`)."""
        from ..random_models import draw_dmvt
        return draw_dmvt(rng)


FAMILY = DMVTObserver()
