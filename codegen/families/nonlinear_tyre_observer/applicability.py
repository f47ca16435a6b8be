"""Whether the nonlinear-tyre observer can take a model with its sensors (``uiogen analyze``).

The family certifies a fixed-gain observer of (v_y, r) with a saturating tyre per axle over a set
of slip angles below sliding; it needs the model file's description of the axles (``AXLES``,
``FORCES``, ``DYNAMICS_IN_FORCES``, ``A_Y_IN_FORCES``), outputs (a_y, r), the box of v_x and
delta, and a tyre slope bounded away from 0 on the set (else v_y is unobservable there). Its
unknown inputs are process noise: it estimates the states only. Its gains are identified on data
(``[design] gain_*``), not designed.
"""
from __future__ import annotations

from ...errors import UiogenError


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from . import build as nt

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "states_only", condition, fix, tuple(checked))

    own = subject.config is not None and subject.config.family == family.name
    try:
        settings = nt.NonlinearTyreSettings(**({} if not own else {
            k: v for k, v in subject.config.design.items() if k in nt.NonlinearTyreSettings.__dataclass_fields__}))
        rep = nt.represent(subject.model_module, subject.parameters, settings, str(subject.model_path))
    except (UiogenError, AttributeError, TypeError) as exc:
        return refuse(str(exc).split(": ", 1)[-1] if isinstance(exc, UiogenError) else
                      f"the model file is not a single-track model with axle descriptions ({exc})",
                      "describe the axle forces (AXLES, FORCES, DYNAMICS_IN_FORCES, A_Y_IN_FORCES) as "
                      "model_defs/single_track_nonlinear_tyre.py does")
    checked = [(f"tyre slope bounded away from 0 on |t| <= {settings.sliding_fraction:g} t_sl per axle "
                f"(sound interval bounds over the set)", "proof")]
    notes = ["the unknown inputs are not estimated (process noise); its gain L is identified on data, not designed: "
             "the analysis proposes L = 0 (the open-loop model), which the certificate may refuse"]
    observer = {"family": family.name, "sample_time": subject.sample_time,
                "design": {"gain_vy_ay": 0.0, "gain_vy_r": 0.0, "gain_r_ay": 0.0, "gain_r_r": 0.0,
                           "sliding_fraction": settings.sliding_fraction}}
    why = {"design.gain_vy_ay": "identify the gains on a log (docs/families/nonlinear_tyre_observer.md)",
           "design.sliding_fraction": "the certified set: |tan alpha| <= this x the sliding slip per axle"}

    def figures(b) -> dict:
        c = b.certificate
        return {"contraction_per_step": (c["contraction_per_step"], "-", "sqrt(V) per step on the certified set")}
    return Applicability(family.name, True, "states_only", checked=tuple(checked), notes=tuple(notes),
                         observer=observer, why=why, figures=figures)
