"""Whether Menhour et al. 2014's switched H-infinity PI observer can take a model with its sensors
(``uiogen analyze``).

The observer switches between modes, each the model frozen at an operating point of a switching
rule; the analysis proposes the speed rule (25): the first scheduling signal split into three
equal bands over its box, the others at the middle of theirs. Algorithm 1 needs y = C x (no
feedthrough), in every mode rank F = n_w and rank C = m (A1) and the augmented pair
([[A, F], [0, 0]], [C, 0]) detectable (A2: no invariant zero of (A, F, C) at s = 0, which the
integral of the unknown-input estimate would leave undamped). Its certificate covers the modes'
models, not the model between the operating points.
"""
from __future__ import annotations

from ...errors import NotAffineError, UiogenError


def proposed_rule(subject) -> dict | None:
    """The [switching] table of the speed rule (25) over the subject's scheduling box: three modes."""
    model = subject.model
    signals = [g for g in model.scheduling if g.derived is None] or list(model.scheduling)
    if not signals:
        return None
    boxes = subject.parameters.scheduling
    first = str(signals[0].symbol)
    if first not in boxes:
        return None
    lo, hi = boxes[first].lower, boxes[first].upper
    centres = [float(lo + (2 * k + 1) * (hi - lo) / 6) for k in range(3)]
    rule = {"performance": [str(s) for s in model.states],
            "axis": [{"name": first, "premise": first, "unit": signals[0].unit or "-", "centres": centres,
                      "points": [{first: c} for c in centres]}]}
    others = {str(g.symbol): 0.5 * (boxes[str(g.symbol)].lower + boxes[str(g.symbol)].upper)
              for g in model.scheduling if str(g.symbol) != first and str(g.symbol) in boxes}
    if others:
        rule["fixed"] = others
    return rule


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from . import design as sw_design
    from . import representation

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "attenuated_points", condition, fix, tuple(checked))

    model = subject.model
    if not hasattr(model, "known_inputs"):
        return refuse(f"model {subject.name!r} is a {type(model).__name__}: the modes are frozen LPV models "
                      f"(a ModelDefinition)", "write the model as a ModelDefinition")
    try:
        lpv = subject.lpv
        lpv.require_no_ui_feedthrough("switched H-infinity PI observer", "Menhour et al. 2014, eq. (2): y = C x")
    except UiogenError as exc:
        from ...analysis.ranking import not_affine_fix
        return refuse(f"{type(exc).__name__}: {exc}", "measure outputs the unknown inputs do not reach directly; "
                      "the L-infinity UIO takes the feedthrough" if "reach the outputs" in str(exc)
                      else not_affine_fix(subject, exc, "write each nonlinearity through a measured scheduling "
                                                        "signal") if isinstance(exc, NotAffineError)
                      else "as the message says")
    if not lpv.nd:
        return refuse("the model has no unknown input to estimate", "declare the unknown inputs")
    rule = proposed_rule(subject)
    if rule is None:
        return refuse("no scheduling signal with a [scheduling] box to switch on", "declare the speed as a "
                      "SchedulingSignal with [scheduling.NAME] min/max, or write a switching rule by hand")
    raw = subject.config.switching if (subject.config is not None and subject.config.family == family.name) else rule
    try:
        sm = representation.build(model, subject.parameters, raw, subject.name)
        T, _ = sw_design.decoupling_matrices(sm.C[0])
        report = sw_design.check_assumptions(sm, T)
    except UiogenError as exc:
        text = str(exc)
        fix = (structure.fix("strong_detectability") or structure.fix("observability")
               or "measure an output that sees the unknown input's effect at rest") if "A2" in text or \
            "detectable" in text else ("measure outputs the known inputs do not reach directly (y = C x); the "
                                       "L-infinity UIO takes y = C x + Du u") if "known-input feedthrough" in text \
            else "measure linearly independent outputs; merge dependent unknown inputs"
        return refuse(f"{type(exc).__name__}: {text}", fix)
    n_modes = sm.n_modes
    axis = raw["axis"][0]
    checked = [(f"assumptions A1 (rank F = {sm.nw}, rank C = {sm.m}) and A2 (augmented pair detectable) in each of "
                f"the {n_modes} modes at {axis['premise']} = {', '.join(f'{c:g}' for c in axis.get('centres', []))}",
                "exact")]
    notes = (f"the certificate covers the {n_modes} frozen models at the operating points, not the model between "
             f"them (the error from a mode's model grows with the distance to its point)",)
    pole = min(100.0, 0.5 / subject.sample_time)
    from ...analysis.ranking import decay_proposal
    decay, decay_why = decay_proposal(min(1.0, 0.5 * pole), structure.decay_limit())
    observer = {"family": family.name, "sample_time": subject.sample_time,
                "design": {"pole_radius": pole, "decay_rate": decay}, "switching": rule}
    why = {"sample_time": f"s, exact ZOH per mode; from {subject.sample_time_source}",
           "design.pole_radius": "rad/s: every mode's error poles in |s| < r, r T_s <= 0.5",
           "design.decay_rate": ("1/s: every error mode, the unknown-input estimate's included, decays at least as "
                                 "exp(-a t)" + (f"; {decay_why}" if decay_why else "")),
           "switching": "the speed rule (25): three equal bands over the scheduling box",
           "switching.performance": "xi = the states: gamma bounds the L2 gain from the unknown inputs to them"}

    def figures(b) -> dict:
        return {"gamma": (b.design.gamma, "L2 gain", f"certified H-infinity gain from the unknown inputs to "
                          f"{', '.join(raw.get('performance', []))} in every mode"),
                "contraction_per_step": (b.discrete_certificate["contraction_per_step"], "-",
                                         "sqrt(V) per step in every mode, under any switching")}
    return Applicability(family.name, True, "attenuated_points", checked=tuple(checked), notes=notes,
                         observer=observer, why=why, figures=figures, decay_key="design.decay_rate")
