"""Whether Menhour et al. 2014's switched H-infinity PI observer can take a model with its sensors
(``uiogen analyze``).

The observer switches between modes, each the model frozen at an operating point of a switching
rule; the analysis proposes the speed rule (25) on every measured scheduling signal: each split
into three equal bands over its box (one axis each; the modes are the combinations), up to
:data:`MAX_MODES` modes; a signal beyond is held at the middle of its box and the proposal says
so (``frozen``), since the observer then does not read it. Algorithm 1 needs y = C x (no
feedthrough), in every mode rank F = n_w and rank C = m (A1) and the augmented pair
([[A, F], [0, 0]], [C, 0]) detectable (A2: no invariant zero of (A, F, C) at s = 0, which the
integral of the unknown-input estimate would leave undamped). Its certificate covers the modes'
models, not the model between the operating points.
"""
from __future__ import annotations

from ...errors import NotAffineError, UiogenError


#: three bands per axis (the speed rule (25)); an axis per measured scheduling signal while the
#: modes (the product of the bands) stay within MAX_MODES: beyond, the remaining signals are held
#: at mid-box, which the proposal says (``Applicability.frozen``) and the ranking puts last
BANDS = 3
MAX_MODES = 27


def proposed_rule(subject) -> dict | None:
    """The [switching] table over the subject's scheduling box: the speed rule (25), three equal
    bands, on every measured scheduling signal (one axis each, modes their combinations) while the
    modes stay within :data:`MAX_MODES`; the signals left over are held at the middle of their box
    in ``fixed`` (frozen: the observer does not read them)."""
    model = subject.model
    boxes = subject.parameters.scheduling
    signals = [g for g in model.scheduling if g.derived is None] or list(model.scheduling)
    signals = [g for g in signals if str(g.symbol) in boxes]
    if not signals:
        return None
    axes = []
    for g in signals:
        if BANDS ** (len(axes) + 1) > MAX_MODES:
            break
        name = str(g.symbol)
        lo, hi = boxes[name].lower, boxes[name].upper
        centres = [float(lo + (2 * k + 1) * (hi - lo) / (2 * BANDS)) for k in range(BANDS)]
        axes.append({"name": name, "premise": name, "unit": g.unit or "-", "centres": centres,
                     "points": [{name: c} for c in centres]})
    on_axis = {a["name"] for a in axes}
    rule = {"performance": [str(s) for s in model.states], "axis": axes}
    others = {str(g.symbol): 0.5 * (boxes[str(g.symbol)].lower + boxes[str(g.symbol)].upper)
              for g in model.scheduling if str(g.symbol) not in on_axis and str(g.symbol) in boxes}
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
    at = " x ".join(f"{axis['premise']} = {', '.join(f'{c:g}' for c in axis.get('centres', []))}"
                    for axis in raw["axis"])
    checked = [(f"assumptions A1 (rank F = {sm.nw}, rank C = {sm.m}) and A2 (augmented pair detectable) in each of "
                f"the {n_modes} modes at {at}", "exact")]
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
           "switching": (f"the speed rule (25) on {'each measured scheduling signal' if len(rule['axis']) > 1 else 'the scheduling signal'}: "
                         f"{BANDS} equal bands over its box" + ("; the modes are the combinations of one band per axis"
                                                                if len(rule["axis"]) > 1 else "")),
           "switching.performance": "xi = the states: gamma bounds the L2 gain from the unknown inputs to them"}

    frozen = dict(rule.get("fixed", {}))
    if frozen:
        why["switching.fixed"] = (f"FROZEN: {', '.join(frozen)} held at mid-box: more axes would make more than "
                                  f"{MAX_MODES} modes; the observer does not read "
                                  f"{'them' if len(frozen) > 1 else 'it'} and the certificate covers only these "
                                  f"values (add an axis by hand, or another family reads every signal)")

    def figures(b) -> dict:
        return {"gamma": (b.design.gamma, "L2 gain", f"certified H-infinity gain from the unknown inputs to "
                          f"{', '.join(raw.get('performance', []))} in every mode"),
                "contraction_per_step": (b.discrete_certificate["contraction_per_step"], "-",
                                         "sqrt(V) per step in every mode, under any switching")}
    return Applicability(family.name, True, "attenuated_points", checked=tuple(checked), notes=notes,
                         observer=observer, why=why, figures=figures, decay_key="design.decay_rate",
                         frozen=frozen)
