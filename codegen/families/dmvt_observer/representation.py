"""The model as the DMVT observer needs it: x' = f(x, w), y = h(x, w), with sound bounds of the
Jacobians of f and h over the set the state and the measured signals stay in.

Zemouche, Boutayeb, Bara 2005 (the differential mean value theorem, DMVT): for a state x and an
estimate x_hat in a box X (convex) and the same measured signals w in their box W, each row of f
satisfies f_i(x, w) - f_i(x_hat, w) = grad f_i(zeta_i, w) (x - x_hat) at some point zeta_i of the
segment between them. So with every entry d f_i / d x_j enclosed in [a_ij, b_ij] over X x W, the
difference f(x) - f(x_hat) is A (x - x_hat) for some matrix A of the box of matrices
{a_ij <= A_ij <= b_ij}, and the same for h with a matrix H: the estimation error obeys a linear
system whose matrices lie in a polytope, the convex hull of the box's corners. Entries whose bound
has zero width (a linear term) are constants; only the others make corners.

What this module derives from the user's model, with no hand-written split:

* the signals w the step reads: the known inputs, the scheduling signals that are inputs, each with
  its box (``[inputs.NAME]`` min/max or ``[state_bounds]``, ``[scheduling.NAME]``); a scheduling
  signal derived from the outputs is replaced by its expression in the states (the outputs are
  functions of the state), so the DMVT covers it as part of f and h;
* the box X of every state (``[state_bounds]``): the set the certificate holds in, for the car's
  state and for the estimate;
* the Jacobian bounds (:func:`codegen.representation.bounds.range_bound`, sound: interval
  arithmetic with branch and bound; a bound short of its tolerance is a sound enclosure, a larger
  polytope, never a smaller one, stated in the artifact);
* the corners of the (A, H) box.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import sympy as sp

from ...emit.stepgen import lambdify
from ...errors import ModelDefinitionError, SchedulingBoundsError
from ...model import ModelDefinition, ParameterSet, parameter_substitution
from ...model.floats import drop_zero_terms, merge_float_noise
from ...representation.bounds import RangeBound, derivative, range_bound
from ...representation.derived import derived_in_states

#: corners of the Jacobian box beyond which the design is refused (each corner is one LMI block of
#: twice the state's size, and the search for the rate solves about ten problems: the sedan's 256
#: corners of 4 states take 1-3 s a solve)
MAX_CORNERS = 4096


@dataclass(frozen=True)
class DMVTModel:
    """x' = f(x, w), y = h(x, w) with parameters substituted, the boxes, and the Jacobian bounds."""

    definition: ModelDefinition
    parameters: ParameterSet
    states: tuple              # state symbols
    signals: tuple             # w: known inputs, then the scheduling signals the step reads
    f: tuple                   # drift, one expression per state
    h: tuple                   # outputs, one expression per output (in the model's order)
    state_box: tuple           # ((lo, hi) per state)
    signal_box: tuple          # ((lo, hi) per signal of w)
    A_bounds: tuple            # (nx x nx) RangeBound: d f_i / d x_j over X x W
    H_bounds: tuple            # (ny x nx) RangeBound: d h_i / d x_j over X x W

    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def ny(self) -> int:
        return len(self.h)

    @property
    def known_inputs(self) -> tuple:
        return tuple(self.definition.known_inputs)

    @property
    def scheduling(self) -> tuple:
        """The scheduling signals the step reads (its ``rho``), after the known inputs in ``signals``."""
        return self.signals[len(self.known_inputs):]

    @cached_property
    def A_box(self) -> np.ndarray:
        """(nx, nx, 2): lower and upper bounds of d f_i / d x_j."""
        return np.array([[[b.lower, b.upper] for b in row] for row in self.A_bounds], float).reshape(self.nx, self.nx, 2)

    @cached_property
    def H_box(self) -> np.ndarray:
        """(ny, nx, 2): lower and upper bounds of d h_i / d x_j."""
        return np.array([[[b.lower, b.upper] for b in row] for row in self.H_bounds], float).reshape(self.ny, self.nx, 2)

    @cached_property
    def free_entries(self) -> tuple:
        """(("A" or "H", i, j), ...): the entries whose bound has width, each a direction of the polytope."""
        return tuple((k, i, j) for k, box in (("A", self.A_box), ("H", self.H_box))
                     for i in range(box.shape[0]) for j in range(box.shape[1]) if box[i, j, 0] < box[i, j, 1])

    def corners(self) -> list:
        """[(A, H)] at every corner of the box of Jacobians (continuous time, physical units)."""
        out = []
        for pick in itertools.product((0, 1), repeat=len(self.free_entries)):
            A, H = self.A_box[:, :, 0].copy(), self.H_box[:, :, 0].copy()
            for (k, i, j), b in zip(self.free_entries, pick):
                if k == "A":
                    A[i, j] = self.A_box[i, j, b]
                else:
                    H[i, j] = self.H_box[i, j, b]
            out.append((A, H))
        return out

    @property
    def loose_bounds(self) -> list:
        """'d(f_i)/dx_j: ...' for every bound that is a sound enclosure short of its tolerance."""
        names = [str(s) for s in self.states]
        outs = [n for n, _ in self.definition.outputs]
        return ([f"d({names[i]}')/d{names[j]}: {b.describe_gap()}" for i, row in enumerate(self.A_bounds)
                 for j, b in enumerate(row) if not b.converged]
                + [f"d({outs[i]})/d{names[j]}: {b.describe_gap()}" for i, row in enumerate(self.H_bounds)
                   for j, b in enumerate(row) if not b.converged])

    def functions(self, xp) -> tuple:
        """(f, h) as callables of (x..., w...) for numpy or CasADi."""
        args = (*self.states, *self.signals)
        return [lambdify(args, e, xp) for e in self.f], [lambdify(args, e, xp) for e in self.h]

    @cached_property
    def numpy_functions(self) -> tuple:
        """:meth:`functions` for numpy, compiled once (the reference step runs per sample)."""
        return self.functions(np)

    def to_json(self) -> dict:
        names = [str(s) for s in self.states]

        def entries(bounds):
            return [[{"lower": b.lower, "upper": b.upper, "attained": [b.attained_min, b.attained_max],
                      **({} if b.converged else {"enclosure": True, "gap": b.gap, "stopped": b.stopped})}
                     for b in row] for row in bounds]
        return {"states": names, "signals": [str(s) for s in self.signals],
                "f": [str(e) for e in self.f], "h": [str(e) for e in self.h],
                "state_box": {n: list(b) for n, b in zip(names, self.state_box)},
                "signal_box": {str(s): list(b) for s, b in zip(self.signals, self.signal_box)},
                "jacobian_bounds": {"df/dx": entries(self.A_bounds), "dh/dx": entries(self.H_bounds)},
                "free_entries": [f"{k}[{i},{j}]" for k, i, j in self.free_entries],
                "dmvt_corners": 2 ** len(self.free_entries)}


def _box_of(name: str, params: ParameterSet, kind: str) -> tuple | None:
    if name in params.state_bounds:
        return tuple(float(v) for v in params.state_bounds[name])
    if kind == "input" and name in params.inputs and {"min", "max"} <= set(params.inputs[name]):
        return float(params.inputs[name]["min"]), float(params.inputs[name]["max"])
    if kind == "scheduling" and name in params.scheduling:
        box = params.scheduling[name]
        return float(box.lower), float(box.upper)
    return None


def build(model: ModelDefinition, params: ParameterSet, rel_tol: float = 1e-3, max_boxes: int = 20000,
          max_corners: int = MAX_CORNERS) -> DMVTModel:
    """The DMVT form of ``model`` with the values of ``params``.

    Raises
    ------
    ModelDefinitionError
        a model with unknown inputs (this family estimates states), or an output that reads no state.
    SchedulingBoundsError
        a state or measured signal without a box, a box of zero width, or a Jacobian box with more
        corners than ``max_corners``.
    MissingParameterError, UnknownParameterError, BoundsError
    """
    if model.unknown_inputs:
        raise ModelDefinitionError(
            f"model {model.name!r}: unknown inputs {', '.join(map(str, model.unknown_inputs))}: the DMVT observer "
            f"estimates the state of a model without unknown inputs; make each a known input (measured), a state "
            f"with its own dynamics (a slowly varying disturbance: d' = 0), or choose an unknown-input family "
            f"(linf_uio, ts_fuzzy_uio, algebraic_uio)")
    if not model.outputs:
        raise ModelDefinitionError(f"model {model.name!r}: no outputs; the observer needs a measured signal")
    model = derived_in_states(model)
    subs = parameter_substitution(model, params)
    x = tuple(model.states)
    w = (*model.known_inputs, *(g.symbol for g in model.scheduling))
    signals = (*x, *w)
    # floats that differ only by rounding are one number, and a term that is 0 is none (sp.solve's rows)
    f = tuple(merge_float_noise(sp.Matrix(drop_zero_terms(model.dynamics, signals)).subs(subs)))
    h = tuple(merge_float_noise(sp.Matrix(drop_zero_terms([e for _, e in model.outputs], signals)).subs(subs)))
    for (name, _), e in zip(model.outputs, h):
        if not (sp.sympify(e).free_symbols & set(x)):
            raise ModelDefinitionError(f"model {model.name!r}: output {name!r} = {e} reads no state: it tells the "
                                       f"observer nothing; drop it or make it a known input")
    stray = set().union(*(sp.sympify(e).free_symbols for e in (*f, *h))) - set(signals)
    if stray:
        raise ModelDefinitionError(f"model {model.name!r}: f or h depend on {', '.join(sorted(map(str, stray)))}, "
                                   f"which is no state, known input or scheduling signal of the model")
    missing, state_box, signal_box = [], [], []
    for s in x:
        b = _box_of(str(s), params, "state")
        missing += [] if b else [f"{s} = [min, max] under [state_bounds]"]
        state_box.append(b)
    for s in w:
        kind = "input" if s in model.known_inputs else "scheduling"
        b = _box_of(str(s), params, kind)
        missing += [] if b else [f"[inputs.{s}] with min and max" if kind == "input" else
                                 f"[scheduling.{s}] with min and max"]
        signal_box.append(b)
    if missing:
        raise SchedulingBoundsError(
            f"model {model.name!r}: the DMVT observer is certified on a box of the state and of every signal it "
            f"reads; {params.source} lacks: " + "; ".join(missing))
    for s, (lo, hi) in zip(x, state_box):
        if not hi > lo:
            raise SchedulingBoundsError(f"{params.source}: [state_bounds] {s} = [{lo:g}, {hi:g}]: the box needs "
                                        f"min < max (the certificate's set; it scales the design)")
    boxes = {**dict(zip(x, state_box)), **dict(zip(w, signal_box))}

    def jacobian(rows):
        out = []
        for e in rows:
            row = []
            for s in x:
                d = derivative(e, s)
                if d == 0:
                    row.append(RangeBound(0.0, 0.0, 0.0, 0.0, 0))
                elif not d.free_symbols:
                    v = float(d)
                    row.append(RangeBound(v, v, v, v, 0))
                else:
                    row.append(range_bound(d, {v: boxes[v] for v in d.free_symbols}, rel_tol=rel_tol,
                                           max_boxes=max_boxes, enclose=True))
            out.append(tuple(row))
        return tuple(out)

    A_bounds, H_bounds = jacobian(f), jacobian(h)
    rep = DMVTModel(model, params, x, w, f, h, tuple(state_box), tuple(signal_box), A_bounds, H_bounds)
    if 2 ** len(rep.free_entries) > max_corners:
        names = [str(s) for s in x]
        outs = [n for n, _ in model.outputs]
        which = ", ".join(f"d({names[i]}')/d{names[j]}" if k == "A" else f"d({outs[i]})/d{names[j]}"
                          for k, i, j in rep.free_entries)
        raise SchedulingBoundsError(
            f"model {model.name!r}: {len(rep.free_entries)} Jacobian entries vary over the box ({which}): "
            f"{2 ** len(rep.free_entries)} DMVT corners, above [design] max_corners = {max_corners}; narrow "
            f"[state_bounds] or the signals' boxes where an entry is nearly constant, or raise max_corners")
    return rep
