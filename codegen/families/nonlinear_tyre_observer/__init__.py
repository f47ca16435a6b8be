"""Nonlinear single-track observer with a saturating (Fiala) tyre per axle, certified by the
differential mean-value theorem over slip angles up to a fraction of each axle's sliding limit.

The DMVT treatment of unmeasured nonlinearities is that of Nguyen, Dinh, Guerra, Pan 2021 (the
``ts_fuzzy_uio`` family), applied here to the tyre force itself: its Jacobian along the
unmeasured lateral speed is bounded soundly over a set of slip values (:mod:`codegen.representation.bounds`),
and one quadratic Lyapunov matrix certifies the fixed-gain error map at every vertex. See
``build.py`` for the equations, ``docs/validation.md`` for the real-data results.
"""
from __future__ import annotations

from ..base import Family


class NonlinearTyreObserver(Family):
    name = "nonlinear_tyre_observer"
    title = "nonlinear single-track observer with saturating axle tyres (DMVT certificate)"
    citation = "DMVT certificate after Nguyen, Dinh, Guerra, Pan, IEEE/ASME T-Mech 26(3), 2021; Fiala tyre (Pacejka 2012, Sec. 3.2)"
    short_citation = "nonlinear-tyre DMVT"
    observer_keys = {}
    demo_scenarios = ()
    example = "stanford_sideslip_nonlinear_tyre"

    def build(self, config, tol=None):
        from .build import build
        return build(config, tol)

    def demo_report(self, art: dict) -> dict:
        c = art["certificate"]["recheck"]
        return {"worst_lmi_margin": c["worst_min_eig"], "worst_lmi_block": c["worst_block"],
                "contraction_per_step": c["contraction_per_step"]}

    def demo_lines(self, e: dict) -> list:
        return [f"vertex LMIs: worst margin {e['worst_lmi_margin']:.3g} in {e['worst_lmi_block']}; sqrt(V) contracts "
                f"by {e['contraction_per_step']:.6f}/step"]


FAMILY = NonlinearTyreObserver()
