"""Whether the nonlinear-tyre observer can take a model with its sensors (``uiogen analyze``).

The family designs the gains of a nonlinear single-track observer of (v_y, r) with a saturating
tyre per axle, jointly with one Lyapunov matrix, over a set of slip angles below sliding; it needs
the model file's description of the axles (``AXLES``, ``FORCES``, ``DYNAMICS_IN_FORCES``,
``A_Y_IN_FORCES``), outputs (a_y, r), the boxes of v_x and of the known inputs, and a tyre slope
bounded away from 0 on the set (else v_y is unobservable there). These are roles, read from the
model's structure under its own names (:func:`.representation.signals`). Its unknown inputs are the
unmodelled axle forces: it estimates the states only.
"""
from __future__ import annotations

from ...errors import UiogenError


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from . import build as nt
    from .representation import _check_structure, represent

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "states_only", condition, fix, tuple(checked))

    own = subject.config is not None and subject.config.family == family.name
    try:
        _check_structure(subject.model, str(subject.model_path))
        # the noise levels do not enter the representation; the file's own, else unit levels for this check
        settings = nt.parse(subject.config) if own else nt.NonlinearTyreSettings(sigma_force_front=1.0,
                                                                                 sigma_force_rear=1.0)
        represent(subject.model_module, subject.parameters, settings, str(subject.model_path))
    except (UiogenError, AttributeError, TypeError) as exc:
        return refuse(str(exc).split(": ", 1)[-1] if isinstance(exc, UiogenError) else
                      f"the model file is not a single-track model with axle descriptions ({exc})",
                      "describe the axle forces (AXLES, FORCES, DYNAMICS_IN_FORCES, A_Y_IN_FORCES) as "
                      "model_defs/single_track_nonlinear_tyre.py does")
    checked = [(f"tyre slope bounded away from 0 on |t| <= {settings.sliding_fraction:g} t_sl per axle "
                f"(sound interval bounds over the set)", "proof")]
    notes = ["the unknown inputs (unmodelled axle forces) are not estimated; the design needs their levels "
             "sigma_force_front/rear, identified on a log with a sideslip reference (`uiogen fit`): the analysis "
             "proposes no settings without them"]
    observer = None
    why = {"design.sliding_fraction": "the certified set: |tan alpha| <= this x the sliding slip per axle",
           "design.gain_sliding_fraction": "the set of the l2 gain bound",
           "design.decay_fraction": "the fraction of the largest certifiable decay rate the design requires"}

    def figures(b) -> dict:
        c = b.recheck
        return {"contraction_per_step": (c["contraction_per_step"], "-", "sqrt(V) per step on the certified set"),
                "gamma": (c["gamma_deg"], "deg", "l2 gain to the sideslip error at the noise levels")}
    return Applicability(family.name, True, "states_only", checked=tuple(checked), notes=tuple(notes),
                         observer=observer, why=why, figures=figures)
