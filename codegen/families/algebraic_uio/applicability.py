"""Whether Ichalal and Mammar 2015's algebraic UIO can take a model with its sensors (``uiogen analyze``).

The observer reconstructs the unknown inputs from output derivatives of their relative degree:
it needs y = C x with a constant C, a relative degree of every output that is uniform on the box
and rank condition (64) (proven here by the family's own sound interval bounds), bounds of the
scheduling derivatives it uses, no fixed mode (invariant zero) with Re >= 0, and a HOSMD
differentiator per output of the order of its relative degree and per scheduling signal of the
order its derivatives appear in. All of them are listed at once, so one run tells the user every
differentiator to add.
"""
from __future__ import annotations

from ...errors import (NotAffineError, RankConditionError, RelativeDegreeError, SchedulingBoundsError,
                       UiogenError)


def _lipschitz(subject, signal: str, order: int) -> tuple:
    """(L, reason) of a differentiator of ``signal`` up to ``order``: the parameter file's bound of
    its derivative order + 1 when it gives one, else a placeholder to measure."""
    box = subject.parameters.scheduling.get(signal)
    if box is not None:
        import tomllib
        with open(subject.parameter_path, "rb") as fh:
            higher = tomllib.load(fh).get("scheduling", {}).get(signal, {}).get("derivative_bounds", [])
        bounds = {**({1: (box.rate_lower, box.rate_upper)} if box.rate_bounded else {}),
                  **{m: tuple(p) for m, p in enumerate(higher, start=2)}}
        if order + 1 in bounds:
            lo, hi = bounds[order + 1]
            return max(abs(lo), abs(hi), 1e-9), (f"bound of |{signal}^({order + 1})| from "
                                                 f"[scheduling.{signal}] of {subject.parameter_path.name}")
    return 100.0, (f"PLACEHOLDER: a bound of |{signal}^({order + 1})| on your runs, in its unit/s^{order + 1} "
                   f"(docs/differentiators.md: too low lags, too high amplifies noise); the design's "
                   f"certificate does not depend on it")


def assess(family, subject, structure):
    from ...analysis.ranking import Applicability
    from . import design as alg
    from . import representation as rdeg

    def refuse(condition: str, fix: str, checked=()):
        return Applicability(family.name, False, "decoupled", condition, fix, tuple(checked))

    model = subject.model
    if not hasattr(model, "known_inputs"):
        return refuse(f"model {subject.name!r} is a {type(model).__name__}: the algebraic UIO takes one LPV system "
                      f"(a ModelDefinition)", "write the model as a ModelDefinition")
    derived = [str(g.symbol) for g in model.scheduling if g.derived is not None]
    if derived:
        return refuse(f"{', '.join(derived)} {'is' if len(derived) == 1 else 'are'} derived from the outputs: the "
                      f"algebraic UIO differentiates its scheduling signals, which must be measured inputs",
                      f"make {' and '.join(derived)} a measured input (a SchedulingSignal without derived=)")
    try:
        lpv = subject.lpv
        rdeg.check_structure(lpv)
    except NotAffineError as exc:
        from ...analysis.ranking import not_affine_fix
        return refuse(f"{type(exc).__name__}: {exc}",
                      "measure outputs the unknown inputs do not reach directly (y = C x); the L-infinity UIO takes "
                      "the feedthrough" if "reach the outputs" in str(exc) else
                      not_affine_fix(subject, exc, "write each nonlinearity through a measured scheduling signal")
                      if "affine" in str(exc) else "as the message says")
    except UiogenError as exc:
        return refuse(f"{type(exc).__name__}: {exc}", "as the message says")
    try:
        dec = rdeg.derive(lpv)
    except RelativeDegreeError as exc:
        return refuse(f"relative degree (Definition 2, Assumption 1): {exc}",
                      structure.fix("relative_degree", "restrict the scheduling box where the relative degree "
                                    "changes, or measure a signal the unknown inputs reach uniformly"))
    except RankConditionError as exc:
        return refuse(f"{exc}", structure.fix("left_invertibility", "") or structure.fix("matching", "")
                      or "measure more outputs that the unknown inputs reach independently")
    except SchedulingBoundsError as exc:
        return refuse(f"the observer needs derivatives of its scheduling signals that the parameter file does not "
                      f"bound: {exc}",
                      f"bound them in {subject.parameter_path.name}: [scheduling.NAME] rate_min/rate_max (order 1), "
                      f"derivative_bounds = [[min2, max2], ...] (orders 2, 3, ...)")
    cert = dec.certificates
    checked = [(f"relative degree(s) {list(dec.relative_degrees)} of {', '.join(subject.outputs)} uniform on the "
                f"box (M_(r-1) D never 0)", "proof"),
               (f"rank condition (64): {cert['rank_condition_64']['quantity']} in "
                f"[{cert['rank_condition_64']['bound'][0]:.4g}, {cert['rank_condition_64']['bound'][1]:.4g}]",
                "proof")]
    fixed = alg.fixed_modes(dec, samples=400)
    if fixed["count"] and fixed["real_range"][1] >= 0:
        return refuse(f"a fixed mode of A - Q M (an invariant zero of (A, D, C)) has Re = {fixed['real_range'][1]:.4g}"
                      f" >= 0: no gain makes the error decay (LMI (39) is infeasible)",
                      structure.fix("strong_detectability", "measure a signal along the zero's direction"),
                      checked + [("fixed modes at the box corners and random points (a sound refutation)", "sampled")])
    limit = fixed["decay_limit"]
    alpha = 1.0 if limit is None else min(1.0, 0.5 * limit)
    needs = {f"y_{o}": r for o, r in zip(subject.outputs, dec.relative_degrees)}
    needs.update({str(s): max(dec.derivative_orders[s], 1) for s in dec.base})
    diffs, why = {}, {}
    for signal, order in needs.items():
        L, reason = _lipschitz(subject, signal, order)
        diffs[signal] = {"order": order, "lipschitz": L}
        kind = "relative degree" if signal.startswith("y_") and signal[2:] in subject.outputs else "its derivatives"
        why[f"design.differentiators.{signal}"] = (f"order {order}: {'the output' if kind == 'relative degree' else 'the scheduling signal'} "
                                                   f"and its derivatives up to {order} ({kind}); lipschitz: {reason}")
    design = {"lmi": "direct", "alpha": alpha, "differentiators": diffs}
    if lpv.nu:
        design.update(auxiliary="output_injection", auxiliary_alpha=0.5)
    observer = {"family": family.name, "sample_time": subject.sample_time, "design": design}
    why.update({"sample_time": f"s, the Gauss-Legendre step; from {subject.sample_time_source}",
                "design.lmi": "LMI (39) in its direct form (any relative degree)",
                "design.alpha": ("certified decay rate (1/s)" + (f", half the fastest decay the fixed modes allow "
                                                                 f"({limit:.4g} 1/s)" if limit is not None else "")),
                "design.auxiliary": "known inputs through s' = (A - K_s C) s + B u + K_s y (bounded for any A(rho))",
                "design.auxiliary_alpha": "decay rate of that auxiliary system (1/s)"})
    checked.append((f"fixed modes of A - Q M: {fixed['count'] or 'none'}" + (
        f", Re in [{fixed['real_range'][0]:.4g}, {fixed['real_range'][1]:.4g}] (the decay of any gain is at most "
        f"{limit:.4g} 1/s)" if fixed["count"] else ""), "sampled"))

    def figures(b) -> dict:
        dc = b.discrete
        return {"alpha": (b.settings.alpha, "1/s", "certified decay rate of the error (LMI (39)), whatever the "
                                                   "unknown inputs"),
                "contraction_per_step": (dc["contraction_bound_per_step"], "-",
                                         "sqrt(V) per step of the Gauss-Legendre step (proof)")}
    return Applicability(family.name, True, "decoupled", checked=tuple(checked), observer=observer,
                         why=why, differentiators=needs, figures=figures)
