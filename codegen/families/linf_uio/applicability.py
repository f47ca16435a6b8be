"""Whether Nguyen et al. 2019's L-infinity UIO can take a model with its sensors (``uiogen analyze``).

Theorem 1 needs an LPV model x' = A(rho) x + B u + D d, y = C x + Du u + Dd d whose matrices are
affine in its premises (the exact sector polytope of the scheduling nonlinearities), D of full
column rank and (A, C) detectable at every vertex of that polytope (where its LMIs are imposed);
the unknown inputs are attenuated with a certified gain, not decoupled, so an unknown input the
outputs see only through high derivatives is estimated poorly even when the design certifies.
"""
from __future__ import annotations

from ...errors import ModelDefinitionError, NotAffineError, RankConditionError, UiogenError


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from ...representation import polytope
    from . import design

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "attenuated_box", condition, fix, tuple(checked))

    model = subject.model
    if not hasattr(model, "known_inputs"):
        return refuse(f"model {subject.name!r} is a {type(model).__name__}: Theorem 1 takes one system "
                      f"x' = A(rho) x + B u + D d (a ModelDefinition)", "write the model as a ModelDefinition")
    try:
        lpv = subject.lpv
    except NotAffineError as exc:
        from ...analysis.ranking import not_affine_fix
        return refuse(f"the model is not LPV: {exc}", not_affine_fix(
            subject, exc, "write each nonlinearity through measured signals (a SchedulingSignal bounded in "
                          "[scheduling.NAME], or a derived input); families for nonlinear models rank below"))
    except UiogenError as exc:
        return refuse(f"{type(exc).__name__}: {exc}", "fix the parameter file as the message says")
    signals = [str(s) for s in lpv.scheduling_symbols]
    if not signals or not polytope.scheduling_nonlinearities(lpv):
        return refuse("the matrices do not depend on a scheduling signal (an LTI model): the polytope of Theorem 1 "
                      "has nothing to span", "declare the measured signal the matrices vary with (the speed) as a "
                      "SchedulingSignal, or take a family for LTI models (below)")
    rate = "exact" if len(signals) == 1 else "none"
    try:
        poly = polytope.sector_polytope(lpv, rate)
    except UiogenError as exc:
        fix = ("declare the premise a scheduling signal of its own, derived in the step, as the message says"
               if "scheduling signal of its own" in str(exc) else "fix the scheduling box as the message says")
        return refuse(f"{type(exc).__name__}: {exc}", fix)
    states = lpv.definition.states
    scaled = design._scaled(poly, design.ui_scaling(poly), design.output_scaling(poly))
    where = f"the {poly.n_vertices} vertices of the exact sector polytope in {', '.join(signals)}"
    try:
        design._check_assumptions(scaled, states)
    except RankConditionError as exc:
        text = str(exc)
        key = "observability" if "detectable" in text else "ui_rank"
        return refuse(f"Theorem 1's assumptions fail at {where}: {text}",
                      structure.fix(key, "measure an output that sees the unobservable states"),
                      [(f"D of full column rank and (A, C) detectable at {where}", "vertices")])
    checked = [(f"D of full column rank and (A, C) detectable at {where}", "vertices")]
    notes = []
    late = structure.fact("matching")
    if late is not None and late.holds is False:
        names = late.detail.get("late_unknown_inputs") or list(subject.unknown_inputs)
        notes.append(f"{', '.join(names)} reach{'es' if len(names) == 1 else ''} the measured outputs only through "
                     f"their second or higher derivative: Theorem 1 attenuates {'it' if len(names) == 1 else 'them'} "
                     f"(gamma) without seeing {'its' if len(names) == 1 else 'their'} effect directly, a certified "
                     f"design may still estimate {'it' if len(names) == 1 else 'them'} poorly; to see "
                     f"{'it' if len(names) == 1 else 'them'}: {late.fix}")
    pdlf = rate == "exact"
    from ...analysis.ranking import decay_proposal
    alpha, alpha_why = decay_proposal(2.0, structure.decay_limit())
    observer = {"family": family.name, "polytope": "sector", "rate_bounds": rate, "sample_time": subject.sample_time,
                "design": {"alpha": alpha, "lyapunov": "pdlf" if pdlf else "quadratic",
                           "gain_bound_times_sample_time": 1.0},
                "ui_filter": {"time_constant": 0.005}}
    why = {"polytope": "exact: the sector polytope equals A(rho) on the whole box (the paper's Taylor reduction "
                       "is an approximation)",
           "rate_bounds": ("sound membership-rate bounds over the box, from [scheduling] rate_min/rate_max" if pdlf
                           else "several scheduling signals: no membership-rate bounds, so a common Lyapunov matrix"),
           "sample_time": f"s, from {subject.sample_time_source}",
           "design.alpha": ("certified decay rate of the error (1/s)" + (f", {alpha_why}" if alpha_why else "")
                            + "; `uiogen sweep` measures gamma against it"),
           "design.lyapunov": ("parameter-dependent Lyapunov function (uses the rate bounds)" if pdlf
                               else "common quadratic Lyapunov matrix (no rate bounds)"),
           "design.gain_bound_times_sample_time": "||M(theta)|| <= 1/T_s: an implementable gain at this sample time",
           "ui_filter.time_constant": "s, T_f of the UI filter (45); a UILoopError names the time constant that "
                                      "certifies the loop if this one does not"}

    def figures(b) -> dict:
        unit = ", ".join(subject.unit(u) for u in subject.unknown_inputs if subject.unit(u) != "-") or "unit"
        return {"gamma": (b.design.gamma, f"state error per {unit} of unknown-input error",
                          "certified L-infinity gain of Theorem 1 over the whole box"),
                "contraction_per_step": (b.discrete_certificate.contraction, "-",
                                         "sqrt(V) of the state error per step, certified at the sample time"),
                "ui_loop_contraction_per_step": (b.discrete_certificate.ui_loop.contraction, "-",
                                                 "the same with the unknown-input filter loop closed")}
    # measured: 32 vertices (four scheduling signals) design in about a minute since the UI-filter loop's
    # multipliers are constant past 10 vertices (docs/performance.md); beyond, the blocks grow as N^2
    cost = "seconds" if poly.n_vertices <= 32 else "minutes"
    return Applicability(family.name, True, "attenuated_box", checked=tuple(checked), notes=tuple(notes),
                         observer=observer, why=why, design_cost=cost, figures=figures, decay_key="design.alpha")
