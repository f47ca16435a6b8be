"""Takagi-Sugeno form with measured and unmeasured nonlinear consequents (Nguyen et al. 2021, eqs. (8)-(12)).

From a nonlinear model x' = F(x, u) + D_v d, y = C x (outputs select states) this module
derives, with no hand-written split:

* the *measured* states (those an output reads) and the unmeasured ones;
* term by term: terms free of unmeasured states form the measured consequent f_v(xi, u); terms
  linear in one unmeasured state form A_v(xi); every other term (nonlinear in unmeasured
  states, e.g. v_y^2) becomes a component of the unmeasured consequent phi(x) with its column
  of G_v;
* the premise variables: the distinct non-constant factors of A_v and G_v in the measured
  signals (for Nguyen et al. 2021: 1/v_x and r), with ranges over the compact state set D_x (sound
  interval bounds, :mod:`codegen.representation.bounds`), 2^p sector vertices and product memberships;
* Euler discretization at T_s (eq. (9)): A = I + T_s A_v, D = T_s D_v, f = T_s f_v, G = T_s G_v;
* sound bounds of the Jacobian of phi over D_x (Assumption 1, eq. (14)); entries of zero width
  collapse, so the DMVT vertex set V_phi has only the vertices that matter. A bound whose branch
  and bound does not reach its tolerance within ``[design] bounds_max_boxes`` is the sound
  enclosure it has reached (a larger DMVT box, never a smaller one), stated with its gap in the
  artifact (``ts_model.jacobian_bounds``) and the certificate's plant class.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import sympy as sp

from ...representation import canonical
from ...representation.bounds import RangeBound, derivative, range_bound
from ...representation.derived import derived_in_states
from ...emit.stepgen import lambdify
from ...errors import ModelDefinitionError, NotAffineError, SchedulingBoundsError
from ...model import ModelDefinition, ParameterSet, parameter_substitution
from ...model.floats import drop_zero_terms, merge_float_noise
from ...representation.polytope import (Premise, affine_decomposition, memberships, nonlinear_factors,
                                        sector_weights_product, vertex_matrices)


@dataclass(frozen=True)
class TSFuzzyModel:
    """Discrete TS model x+ = sum h_i A_i x + D d + f(xi, u) + sum h_i G_i phi(x, u), y = C x."""

    definition: ModelDefinition
    parameters: ParameterSet
    sample_time: float
    measured: tuple            # state symbols read by the outputs, in output order
    unmeasured: tuple
    premises: tuple            # Premise(expr in measured symbols / known inputs, lower, upper)
    memberships: tuple         # sympy h_i(xi)
    A: np.ndarray              # (N, nx, nx)
    G: np.ndarray              # (N, nx, nphi)
    D: np.ndarray              # (nx, nd)
    C: np.ndarray              # (ny, nx)
    f: sp.Matrix               # T_s f_v, in measured symbols and known inputs
    phi: tuple                 # unmeasured consequents, in state symbols (and known inputs)
    state_box: dict            # {state symbol: (lo, hi)}
    jacobian_bounds: tuple     # ((RangeBound per state) per phi component)

    @property
    def nx(self) -> int:
        return self.A.shape[1]

    @property
    def nd(self) -> int:
        return self.D.shape[1]

    @property
    def ny(self) -> int:
        return self.C.shape[0]

    @property
    def n_rules(self) -> int:
        return self.A.shape[0]

    @property
    def nphi(self) -> int:
        return len(self.phi)

    @cached_property
    def CD_pinv(self) -> np.ndarray:
        """(C D)^+ of (16c), computed once (the numpy reference step runs per sample)."""
        return canonical.pinv(canonical.matmul(self.C, self.D))   # emitted: machine-independent

    @cached_property
    def theta_box(self) -> np.ndarray:
        """(nphi, nx, 2) bounds of d phi_l / d x_j (eq. (14))."""
        return np.array([[[b.lower, b.upper] for b in row] for row in self.jacobian_bounds]).reshape(
            self.nphi, self.nx, 2)

    @property
    def loose_bounds(self) -> list:
        """'d(phi)/dx: ...' for each Jacobian bound that is a sound enclosure short of its tolerance
        (the branch and bound stopped: the DMVT box is larger, still sound); empty when all converged."""
        return [f"d({phi})/d{s}: {b.describe_gap()}" for phi, row in zip(self.phi, self.jacobian_bounds)
                for s, b in zip(self.definition.states, row) if not b.converged]

    @cached_property
    def theta_vertices(self) -> np.ndarray:
        """V_phi: corners of the Jacobian box over its non-degenerate entries, shape (P, nphi, nx)."""
        box = self.theta_box
        free = [(l, j) for l in range(self.nphi) for j in range(self.nx) if box[l, j, 0] < box[l, j, 1]]
        out = []
        for pick in itertools.product((0, 1), repeat=len(free)):
            theta = box[:, :, 0].copy()
            for (l, j), b in zip(free, pick):
                theta[l, j] = box[l, j, b]
            out.append(theta)
        return np.array(out).reshape(len(out), self.nphi, self.nx)

    def A_theta(self, i: int, theta: np.ndarray) -> np.ndarray:
        """A_i(theta) = A_i + G_i Theta (eq. (24))."""
        return self.A[i] + self.G[i] @ theta

    def functions(self, xp) -> tuple:
        """(f, premises, phi) as callables of (measured..., u...) / (x..., u...) for numpy or CasADi."""
        import casadi as ca
        meas_args = (*self.measured, *self.definition.known_inputs)
        state_args = (*self.definition.states, *self.definition.known_inputs)
        return ([lambdify(meas_args, e, xp) for e in self.f],
                [lambdify(meas_args, p.expr, xp) for p in self.premises],
                [lambdify(state_args, e, xp) for e in self.phi])

    @cached_property
    def numpy_functions(self) -> tuple:
        """:meth:`functions` for numpy, compiled once (the reference step runs per sample)."""
        return self.functions(np)

    @cached_property
    def premise_functions(self) -> tuple:
        args = (*self.measured, *self.definition.known_inputs)
        return tuple(sp.lambdify(args, p.expr, "numpy") for p in self.premises)

    def h(self, measured_values, u=()) -> np.ndarray:
        """Membership values h_i at measured values (in ``measured`` order)."""
        xi = np.array([f(*measured_values, *u) for f in self.premise_functions], dtype=float)
        return np.asarray(sector_weights_product(xi, self.premises), dtype=float)

    def to_json(self) -> dict:
        return {
            "sample_time": self.sample_time,
            "measured": [str(s) for s in self.measured],
            "unmeasured": [str(s) for s in self.unmeasured],
            "premises": [{"name": p.name, "expr": str(p.expr), "range": [p.lower, p.upper]}
                         for p in self.premises],
            "memberships": [str(m) for m in self.memberships],
            "A": self.A.tolist(), "G": self.G.tolist(), "D": self.D.tolist(), "C": self.C.tolist(),
            "f": [str(e) for e in self.f], "phi": [str(e) for e in self.phi],
            "state_box": {str(k): list(v) for k, v in self.state_box.items()},
            "jacobian_bounds": [[{"state": str(s), "lower": b.lower, "upper": b.upper,
                                  "attained": [b.attained_min, b.attained_max],
                                  **({} if b.converged else {"enclosure": True, "gap": b.gap, "stopped": b.stopped})}
                                 for s, b in zip(self.definition.states, row)] for row in self.jacobian_bounds],
            "dmvt_vertices": int(self.theta_vertices.shape[0]),
        }


def _signals(model: ModelDefinition) -> tuple:
    """The model's states, inputs and scheduling signals (what a term's coefficient multiplies)."""
    return (*model.states, *model.known_inputs, *model.unknown_inputs, *(g.symbol for g in model.scheduling))


def _output_selection(model: ModelDefinition) -> tuple:
    """Measured states: every output must be one state (y = C x with C a selection)."""
    measured = []
    for name, expr in model.outputs:
        expr = sp.sympify(expr)
        if expr not in model.states:
            # a term that is 0 (v_x + (sin^2 + cos^2 - 1) k d) is no term: the output is the state
            expr = drop_zero_terms([expr], _signals(model))[0]
        if expr not in model.states:
            # an output nonlinear in the unmeasured states (a tyre law of v_y in a_y) is no y = C(rho) x + Du(rho)
            # u, whatever it does with the measured ones (scheduling): the L-infinity UIO cannot take it either,
            # and saying so spares a user the detour
            unmeasured = set(model.states) - {sp.sympify(e) for _, e in model.outputs}
            nonlinear = sorted(str(x) for x in unmeasured if sp.diff(expr, x).free_symbols & unmeasured)
            raise ModelDefinitionError(
                f"model {model.name!r}: output {name!r} = {expr} is not a state; the TS fuzzy UIO needs "
                f"outputs that measure states directly (its premises are measured states). "
                + (f"It is nonlinear in {', '.join(nonlinear)}, which no linear-output family takes (linf_uio "
                   f"needs y = C(rho) x + Du(rho) u); the DMVT observer (family dmvt_observer) takes y = h(x) as it "
                   f"stands, with a box of every state under [state_bounds] and without unknown inputs; otherwise "
                   f"measure the state itself or drop the output"
                   if nonlinear else "The L-infinity UIO (family linf_uio) takes outputs y = C(rho) x + Du(rho) u"))
        measured.append(expr)
    return tuple(measured)


def measured_scheduling(model: ModelDefinition) -> ModelDefinition:
    """The model with every derived scheduling signal replaced by its expression in the measured
    outputs, which this family's outputs make measured states (a speed computed from a measured
    speed is that state): the TS premises are measured states and known inputs.

    Raises
    ------
    ModelDefinitionError
        a scheduling signal that is an input of its own (not derived from the outputs), naming
        what to write instead and the family that takes it.
    """
    raw = [str(g.symbol) for g in model.scheduling if g.derived is None]
    if raw:
        raise ModelDefinitionError(
            f"model {model.name!r}: scheduling signal(s) {', '.join(raw)} given as inputs of their own; the TS fuzzy "
            f"UIO's premises are measured states and known inputs: make each a state with an output, a known input, "
            f"or derived from the measured outputs (SchedulingSignal(..., derived=y_NAME)). The L-infinity UIO "
            f"(family linf_uio) takes scheduling inputs")
    return derived_in_states(model)


def split_consequents(model: ModelDefinition, subs: dict) -> dict:
    """Term-by-term split of the drift into f_v (measured), A_v (linear in unmeasured), phi/G_v.

    Returns {"A": sympy (nx, nx), "f": column, "G": sympy (nx, nphi), "phi": tuple, "D": sympy}.
    """
    x, u, d = tuple(model.states), tuple(model.known_inputs), tuple(model.unknown_inputs)
    measured = _output_selection(model)
    unmeasured = tuple(s for s in x if s not in measured)
    # floats that differ only by rounding are one number (sp.solve's rows): one consequent, not two
    # and a term that is 0 is none (dropped exactly, before the parameters leave a residue of 1e-16)
    F = sp.Matrix(merge_float_noise(sp.Matrix(drop_zero_terms(model.dynamics, _signals(model))).subs(subs)))
    Dv = F.jacobian(sp.Matrix(d)) if d else sp.zeros(len(x), 0)
    if any(e.free_symbols for e in Dv):
        from ...representation.substitution import offer
        nonlinear = [u for j, u in enumerate(d) if any(u in e.free_symbols for e in Dv[:, j])]
        raise NotAffineError(f"model {model.name!r}: the unknown inputs must enter with a constant matrix "
                             f"(D_v depends on {sorted(map(str, set().union(*(e.free_symbols for e in Dv))))}). The "
                             f"L-infinity UIO (family linf_uio) takes a scheduling-dependent D(rho)"
                             + "".join(f"; {offer(model, u)}" for u in nonlinear), unknown_inputs=nonlinear)
    drift = sp.expand(F - Dv * sp.Matrix(d))
    Av = sp.zeros(len(x), len(x))
    fv = sp.zeros(len(x), 1)
    phis, gcols = [], []
    for row, entry in enumerate(drift):
        for term in sp.Add.make_args(entry):
            coeff, dep = term.as_independent(*unmeasured, as_Add=False)
            if dep == 1:
                fv[row] += term
            elif dep in unmeasured:
                Av[row, x.index(dep)] += coeff
            else:
                key = next((k for k, p in enumerate(phis) if sp.simplify(p - dep) == 0), None)
                if key is None:
                    phis.append(dep)
                    gcols.append(sp.zeros(len(x), 1))
                    key = len(phis) - 1
                gcols[key][row] += coeff
    Gv = sp.Matrix.hstack(*gcols) if gcols else sp.zeros(len(x), 0)
    return {"A": Av, "f": fv, "G": Gv, "phi": tuple(phis), "D": Dv, "measured": measured,
            "unmeasured": unmeasured}


#: points of D_x at which the measured consequent is evaluated (beside every corner, up to 2^10)
DEFINED_SAMPLES = 500


def check_defined_on_box(model: ModelDefinition, f: sp.Matrix, symbols: tuple, box: dict, source: str) -> None:
    """Refuse a measured consequent that is not a finite real number somewhere in D_x.

    The step evaluates f_v(xi, u) at the measured values, clamped to D_x, and nothing bounds f_v
    (only A_v, G_v and the Jacobians of phi are bounded), so a sqrt or a fractional power of a
    range reaching below 0, or a division by a measured state whose box holds 0, would give the
    compiled step NaN (and the numpy reference a complex number) inside the certified set. This
    is evidence (every corner and seeded points between them), not a proof, and it never refuses
    a model that is defined: it refuses only at a point where the value is not finite and real.

    Raises
    ------
    SchedulingBoundsError
        naming the row, the point and the parameter file whose box holds it.
    """
    used = tuple(s for s in symbols if any(s in e.free_symbols for e in f))
    rng = np.random.default_rng(0)
    lo = np.array([box[s][0] for s in used], float)
    hi = np.array([box[s][1] for s in used], float)
    corners = (np.array(list(itertools.product(*zip(lo, hi))), float) if len(used) <= 10
               else np.zeros((0, len(used))))
    points = np.vstack([corners, rng.uniform(lo, hi, size=(DEFINED_SAMPLES, len(used)))])
    for i, e in enumerate(f):
        if not e.free_symbols:
            continue
        fn = sp.lambdify(used, e, "mpmath")
        for pt in points:
            try:
                v = complex(fn(*pt))
            except (ZeroDivisionError, ValueError, OverflowError):
                v = complex(float("nan"))
            if v.imag != 0 or not np.isfinite(v.real):
                where = ", ".join(f"{s} = {float(x):.6g}" for s, x in zip(used, pt))
                kind = "a complex number" if np.isfinite(v.imag) and v.imag != 0 else "not finite"
                raise SchedulingBoundsError(
                    f"model {model.name!r}: d{model.states[i]}/dt is {kind} at {where}, inside the set D_x of "
                    f"{source} ([state_bounds], [inputs]) the observer is certified on (a sqrt or power of a "
                    f"negative, a log of 0, a division by 0: {sp.sstr(e)[:200]}); narrow the box or write the "
                    f"equation so that it is defined on all of it")


def build(model: ModelDefinition, params: ParameterSet, sample_time: float,
          rel_tol: float = 1e-3, max_boxes: int = 20000, before_bounds=None) -> TSFuzzyModel:
    """Derive the discrete TS fuzzy model (10) from ``model`` and its parameter file.

    ``before_bounds(n_rules, nx, ny, nphi)`` runs once the rules are known, before the Jacobian
    bounds are computed (the design's size guard refuses a too large model there, in well under
    a second). Only the derivatives along unmeasured states are bounded: the observer evaluates
    phi with the measured states themselves, so its error has no component along them.

    Raises
    ------
    ModelDefinitionError (MissingParameterError, UnknownParameterError), NotAffineError,
    SchedulingBoundsError
    """
    if not sample_time > 0:
        raise ModelDefinitionError(f"sample time must be positive, got {sample_time}")
    model = measured_scheduling(model)
    subs = parameter_substitution(model, params)
    parts = split_consequents(model, subs)
    x = tuple(model.states)
    box = {}
    missing = []
    for s in (*x, *model.known_inputs):
        if str(s) in params.state_bounds:
            box[s] = params.state_bounds[str(s)]
        elif s in model.known_inputs and str(s) in params.inputs:     # a known input's declared range
            box[s] = (float(params.inputs[str(s)]["min"]), float(params.inputs[str(s)]["max"]))
        else:
            missing.append(str(s))
    if missing:
        raise SchedulingBoundsError(
            f"model {model.name!r}: {', '.join(missing)} {'has' if len(missing) == 1 else 'have'} no bound in "
            f"{params.source}; the TS form needs the compact set D_x (eq. (5)): add "
            + "; ".join(f"{n} = [min, max] under [state_bounds]" if n not in map(str, model.known_inputs)
                        else f"[inputs.{n}] with min and max (or {n} under [state_bounds])" for n in missing))
    premise_symbols = (*parts["measured"], *model.known_inputs)
    stray = set().union(*(e.free_symbols for e in (*parts["A"], *parts["G"]))) - set(premise_symbols)
    if stray:
        raise ModelDefinitionError(f"model {model.name!r}: A_v/G_v depend on {sorted(map(str, stray))}, "
                                   f"which are not measured")
    factors = nonlinear_factors((parts["A"], parts["G"]), premise_symbols)
    order = {s: k for k, s in enumerate(premise_symbols)}
    factors = sorted(factors, key=lambda g: (min(order[s] for s in g.free_symbols), sp.count_ops(g)))
    premises = []
    for k, g in enumerate(factors):
        rb = range_bound(g, {s: box[s] for s in g.free_symbols}, rel_tol=1e-9)
        if not rb.upper > rb.lower:
            raise SchedulingBoundsError(f"premise {g} is constant on D_x")
        premises.append(Premise(f"xi{k}", g, rb.lower, rb.upper))
    premises = tuple(premises)
    # after the premises: a division by a measured state is named there, with its box's key
    check_defined_on_box(model, parts["f"], premise_symbols, box, params.source)
    if before_bounds is not None:
        before_bounds(2 ** len(premises), len(x), len(parts["measured"]), len(parts["phi"]))
    decomp = affine_decomposition({"A": parts["A"], "G": parts["G"]}, premise_symbols, tuple(factors))
    p = len(premises)
    corners = [[(pr.upper if (idx >> (p - 1 - j)) & 1 else pr.lower) for j, pr in enumerate(premises)]
               for idx in range(2 ** p)]
    mats = vertex_matrices(decomp, corners)
    Ts = float(sample_time)
    nx = len(x)
    A = np.array([np.eye(nx) + Ts * a for a in mats["A"]])
    G = Ts * mats["G"].reshape(len(corners), nx, len(parts["phi"]))
    D = Ts * np.array(parts["D"], dtype=float).reshape(nx, len(model.unknown_inputs))
    C = np.array([[1.0 if s == m else 0.0 for s in x] for m in parts["measured"]])
    jac = []
    measured = set(parts["measured"])
    for phi in parts["phi"]:
        row = []
        for s in x:
            dphi = derivative(phi, s)        # real symbols; Clarke form where phi switches
            row.append(RangeBound(0.0, 0.0, 0.0, 0.0, 0) if dphi == 0 or s in measured else
                       range_bound(dphi, {v: box[v] for v in dphi.free_symbols}, rel_tol=rel_tol,
                                   max_boxes=max_boxes, enclose=True))
        jac.append(tuple(row))
    return TSFuzzyModel(model, params, Ts, parts["measured"], parts["unmeasured"], premises,
                        memberships(premises), A, G, D, C, Ts * parts["f"], parts["phi"], box, tuple(jac))
