"""Interconnected T-S representation of Sentouh et al. 2023, eqs. (8)-(13), derived from one vehicle model.

Input: an :class:`InterconnectedModelDefinition` (one set of nonlinear equations for the whole
vehicle plus the partition of its states into subsystems) and its parameter file. Nothing about
the interconnection is typed in: :func:`build` finds, term by term,

* which unknown inputs and outputs belong to which subsystem (the equations they enter, the
  states they read);
* the scheduling variables: the declared scheduling states (v_x), wherever they appear, and the
  switched signals of eq. (7) (q_f, q_r), given by their definitions;
* for each subsystem S and each term t of an equation of S (parameters substituted, expanded):

  - t linear in one unknown input of S, with a coefficient in the scheduling variables -> B;
  - t linear in one own non-scheduling state, coefficient in the scheduling variables -> A;
  - t free of own non-scheduling states but with an own scheduling state (v_x^2, v_x^2 q_f): one
    factor of that state is the state, the rest the coefficient -> A;
  - anything else (products of the other subsystem's states such as v_y r, exogenous forces such
    as F_rr and F_w) is a coupling signal zeta_F with its column of D (eq. (8));

  output terms that are a constant times an own state form C; the rest (exogenous forces in the
  accelerometer signals, c_a v_x^2) are coupling signals with an output feedthrough E;
* the premise variables (11): the distinct non-constant factors of A, B, D in the scheduling
  variables (:func:`codegen.representation.polytope.nonlinear_factors`), with their ranges from the state box
  (sound interval bounds) or, for premises of the switched signals, from ``[premise_bounds]``;
* the 2^q-vertex matrices of (9) (sector nonlinearity, product memberships, exact:
  sum_i eta_i A_i = A(theta)).

A column of B that depends on the premises (kappa enters as -kappa v_x) would make H_eta of (26)
time-varying and bring T_eta' into (20). When the column is a scalar function of the premises
times a constant column, we take that product as the unknown input (kappa' = v_x kappa, the road
heading rate) and recover kappa = kappa'/v_x after the inversion (30); B, H and T are then
constant and T' = 0 exactly. Other premise-dependent B columns are refused.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from typing import Mapping

import numpy as np
import sympy as sp

from ...representation.bounds import range_bound
from ...errors import (MissingParameterError, ModelDefinitionError, NotAffineError, SchedulingBoundsError,
                     UnknownParameterError, brief)
from ...model import ParameterSet, load_parameters, parameter_substitution
from ...representation.polytope import (Premise, affine_decomposition, nonlinear_factors, sector_weights_product,
                                        vertex_matrices)


@dataclass(frozen=True)
class SwitchedSignal:
    """A switched premise signal such as q_i of Sentouh et al. 2023 eq. (7), given by its definition."""

    symbol: sp.Symbol
    definition: sp.Expr
    doc: str = ""


@dataclass(frozen=True)
class InterconnectedModelDefinition:
    """One nonlinear vehicle model and the partition of its states into subsystems.

    Attributes
    ----------
    name : str
    subsystems : tuple of (str, tuple of sympy.Symbol)
        Subsystem name and its states, in order; every state in exactly one subsystem.
    unknown_inputs : tuple of sympy.Symbol
    exogenous : tuple of sympy.Symbol
        Exogenous signals (wind, rolling resistance); nominal values come from ``[exogenous]``.
    switched : tuple of SwitchedSignal
    scheduling_states : tuple of sympy.Symbol
        States that may appear in premise variables (Sentouh et al. 2023: v_x).
    dynamics : tuple of (state, expression)
    outputs : tuple of (str, expression)
    parameters : tuple of sympy.Symbol
    units : mapping of str to str
    doc : str
    """

    name: str
    subsystems: tuple
    unknown_inputs: tuple
    exogenous: tuple
    switched: tuple
    scheduling_states: tuple
    dynamics: tuple
    outputs: tuple
    parameters: tuple
    units: Mapping[str, str] = field(default_factory=dict)
    doc: str = ""

    def __post_init__(self):
        states = [s for _, sub in self.subsystems for s in sub]
        if len(set(states)) != len(states):
            raise ModelDefinitionError(f"model {self.name!r}: a state is in two subsystems")
        if len(self.subsystems) < 2:
            raise ModelDefinitionError(f"model {self.name!r}: an interconnected model needs at least two subsystems")
        lhs = [s for s, _ in self.dynamics]
        if sorted(map(str, lhs)) != sorted(map(str, states)):
            raise ModelDefinitionError(f"model {self.name!r}: dynamics must give one equation per state "
                                       f"(states {sorted(map(str, states))}, equations for {sorted(map(str, lhs))})")
        declared = {str(s) for s in (*states, *self.unknown_inputs, *self.exogenous, *self.parameters,
                                     *(w.symbol for w in self.switched))}
        names = [str(s) for s in (*states, *self.unknown_inputs, *self.exogenous, *self.parameters,
                                  *(w.symbol for w in self.switched))]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ModelDefinitionError(f"model {self.name!r}: symbol(s) declared twice: {', '.join(dup)}")
        for s, e in self.dynamics:
            stray = {str(x) for x in sp.sympify(e).free_symbols} - declared
            if stray:
                raise ModelDefinitionError(f"model {self.name!r}: d{s}/dt uses undeclared symbol(s) "
                                           f"{', '.join(sorted(stray))}")
        for n, e in self.outputs:
            stray = {str(x) for x in sp.sympify(e).free_symbols} - declared
            if stray:
                raise ModelDefinitionError(f"model {self.name!r}: output {n!r} uses undeclared symbol(s) "
                                           f"{', '.join(sorted(stray))}")
        for w in self.switched:
            stray = {str(x) for x in sp.sympify(w.definition).free_symbols} - {str(s) for s in (*states, *self.parameters)}
            if stray:
                raise ModelDefinitionError(f"model {self.name!r}: switched signal {w.symbol} uses {sorted(stray)}; "
                                           f"it may only use states and parameters")
        if not set(self.scheduling_states) <= set(states):
            raise ModelDefinitionError(f"model {self.name!r}: scheduling_states must be states")

    @property
    def states(self) -> tuple:
        return tuple(s for _, sub in self.subsystems for s in sub)

    @property
    def output_names(self) -> tuple:
        return tuple(n for n, _ in self.outputs)

    @property
    def rhs(self) -> dict:
        return dict(self.dynamics)

    def as_model_definition(self):
        """The same equations as one system (:class:`codegen.model.ModelDefinition`), for the paths
        that do not need the subsystems (the excitation scenario, campaign plants, logs): the
        switched signals replaced by their definitions, the exogenous signals as known inputs
        (the plant's; the observer assumes their nominal ``[exogenous]`` values)."""
        from ...model import ModelDefinition
        switched = {w.symbol: w.definition for w in self.switched}
        rhs = self.rhs
        return ModelDefinition(
            name=self.name, states=self.states, known_inputs=tuple(self.exogenous),
            unknown_inputs=tuple(self.unknown_inputs),
            dynamics=sp.Matrix([sp.sympify(rhs[s]).subs(switched) for s in self.states]),
            outputs=tuple((n, sp.sympify(e).subs(switched)) for n, e in self.outputs), scheduling=(),
            parameters=tuple(self.parameters), units=dict(self.units), doc=self.doc)


@dataclass(frozen=True)
class CouplingSignal:
    """One entry of zeta_F: an expression in states of any subsystem and exogenous signals."""

    expr: sp.Expr

    @property
    def name(self) -> str:
        return str(self.expr)


@dataclass(frozen=True)
class SubsystemTS:
    """T-S form (9) of one subsystem: x' = sum eta_i (A_i x + D_i zeta) + B u', y = C x + E zeta.

    ``B`` is constant: an unknown input whose column was a premise function g(theta) times a
    constant column is replaced by u' = g(theta) u (``ui_scales``)."""

    name: str
    states: tuple
    unknown_inputs: tuple
    ui_scales: tuple            # sympy g_j (1 when the input enters with a constant column)
    output_names: tuple
    coupling: tuple             # CouplingSignal
    premises: tuple             # Premise, expr in the scheduling variables
    A_sym: sp.Matrix
    D_sym: sp.Matrix
    A: np.ndarray               # (N, n, n)
    B: np.ndarray               # (n, p)
    D: np.ndarray               # (N, n, nzeta)
    C: np.ndarray               # (ny, n)
    E: np.ndarray               # (ny, nzeta)

    @property
    def n(self) -> int:
        return len(self.states)

    @property
    def ny(self) -> int:
        return self.C.shape[0]

    @property
    def nu(self) -> int:
        return self.B.shape[1]

    @property
    def nzeta(self) -> int:
        return len(self.coupling)

    @property
    def n_vertices(self) -> int:
        return self.A.shape[0]

    def eta(self, theta) -> np.ndarray:
        return np.asarray(sector_weights_product(np.asarray(theta, float), self.premises), dtype=float)

    def to_json(self) -> dict:
        return {
            "states": [str(s) for s in self.states],
            "unknown_inputs": [str(u) for u in self.unknown_inputs],
            "unknown_input_scales": [str(g) for g in self.ui_scales],
            "outputs": list(self.output_names),
            "coupling_signals": [c.name for c in self.coupling],
            "premises": [{"name": p.name, "expr": str(p.expr), "range": [p.lower, p.upper]} for p in self.premises],
            "vertices": self.n_vertices,
            "A": self.A.tolist(), "B": self.B.tolist(), "D": self.D.tolist(), "C": self.C.tolist(),
            "E": self.E.tolist(),
        }


@dataclass(frozen=True)
class InterconnectedTS:
    """The whole interconnected T-S model (8): one SubsystemTS per subsystem + run-time signals."""

    definition: InterconnectedModelDefinition
    parameters: ParameterSet
    subsystems: tuple
    state_box: dict             # {state symbol: (lo, hi)} of the declared [state_bounds]
    exogenous_nominal: dict     # {symbol: value}
    switched: dict              # {symbol: definition with parameters substituted}
    subs: dict                  # parameter substitution

    @cached_property
    def scheduling_symbols(self) -> tuple:
        return (*self.definition.scheduling_states, *self.switched)

    def to_json(self) -> dict:
        return {
            "subsystems": {s.name: s.to_json() for s in self.subsystems},
            "switched_signals": {str(k): str(v) for k, v in self.switched.items()},
            "exogenous_nominal": {str(k): v for k, v in self.exogenous_nominal.items()},
            "state_box": {str(k): list(v) for k, v in self.state_box.items()},
        }

    def rhs_function(self):
        """Numeric callable (x, u, exogenous) -> x' of the full nonlinear model (switched signals
        by their definitions), parameters substituted; for simulations and exactness checks."""
        d = self.definition
        rhs = d.rhs
        expr = [sp.sympify(rhs[s]).subs(self.subs).subs(self.switched) for s in d.states]
        return sp.lambdify((d.states, d.unknown_inputs, d.exogenous), expr, "numpy")

    def output_function(self):
        d = self.definition
        expr = [sp.sympify(e).subs(self.subs) for _, e in d.outputs]
        return sp.lambdify((d.states, d.exogenous), expr, "numpy")


def _read_extra_tables(path) -> dict:
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    out = {}
    for table in ("exogenous", "premise_bounds"):
        raw = data.get(table) or {}
        vals = {}
        for k, v in raw.items():
            if table == "exogenous":
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise ModelDefinitionError(f"{path}: [exogenous] {k} must be a number, got {v!r}")
                vals[k] = float(v)
            else:
                if (not isinstance(v, list) or len(v) != 2 or
                        not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
                    raise SchedulingBoundsError(f"{path}: [premise_bounds] {k!r} must be [min, max], got {v!r}")
                if not float(v[0]) < float(v[1]):
                    raise SchedulingBoundsError(f"{path}: [premise_bounds] {k!r} needs min < max")
                vals[k] = (float(v[0]), float(v[1]))
        out[table] = vals
    return out


def _classify_drift(entry, own, own_sched, uis, sched, others, subsystem, state):
    """Split one equation into (A row dict, B row dict, [(coefficient, coupling expr)])."""
    arow, brow, coupling = {}, {}, []
    for term in sp.Add.make_args(sp.expand(entry)):
        if term == 0:
            continue
        syms = term.free_symbols
        ui_here = [u for u in uis if u in syms]
        if ui_here:
            if len(ui_here) > 1:
                raise NotAffineError(f"{subsystem}: d{state}/dt term {brief(term)} multiplies two unknown inputs")
            u = ui_here[0]
            coeff = sp.simplify(term / u)
            if coeff.free_symbols - set(sched):
                raise NotAffineError(f"{subsystem}: unknown input {u} enters d{state}/dt with coefficient {coeff}, "
                                     f"which is not a function of the scheduling variables {sorted(map(str, sched))}")
            brow[u] = brow.get(u, 0) + coeff
            continue
        picked = None
        nonsched = [s for s in own if s in syms and s not in own_sched]
        if len(nonsched) == 1:
            coeff = sp.simplify(term / nonsched[0])
            if not (coeff.free_symbols - set(sched)):
                picked = (nonsched[0], coeff)
        elif not nonsched:
            for s in own_sched:
                if s in syms:
                    coeff = sp.simplify(term / s)
                    if not (coeff.free_symbols - set(sched)):
                        picked = (s, coeff)
                        break
        if picked is not None:
            arow[picked[0]] = arow.get(picked[0], 0) + picked[1]
            continue
        coeff, dep = term.as_independent(*others, as_Add=False)
        if dep == 1 or coeff.free_symbols - set(sched):
            raise NotAffineError(f"{subsystem}: term {brief(term)} of d{state}/dt is neither a premise times one own "
                                 f"state or unknown input, nor a premise times a coupling signal")
        coupling.append((coeff, dep))
    return arow, brow, coupling


def _refuse_constant(model, params: ParameterSet, subs: dict, state, subsystem: str, source) -> None:
    """Refuse the terms of d``state``/dt made of parameters alone (rolling resistance -f_r g), as
    written, naming the model file, the exogenous signal that takes them and its nominal value: the
    family has no input of value 1 (Sentouh et al. 2023 (8): A x + B u + D zeta)."""
    consts = set(model.parameters)
    raw = sp.expand(sp.sympify(model.rhs[state]))
    term = sp.Add(*(t for t in sp.Add.make_args(raw) if not t.free_symbols - consts))
    value = sp.sympify(term).subs(subs)
    if term == 0 or not value.is_number or value == 0:
        return
    used = {str(x) for x in (*model.states, *model.unknown_inputs, *model.exogenous, *consts)}
    k = next(n for n in (f"k_{state}", *(f"k_{state}_{i}" for i in range(1, 100))) if n not in used)
    raise NotAffineError(
        f"{source or 'model ' + repr(model.name)}: the term {brief(term)} of d{state}/dt (subsystem {subsystem}) is a "
        f"constant ({float(value):.6g} with the values of {params.source}); the interconnected UIO takes a term as a "
        f"premise times one own state or unknown input, or a premise times a coupling signal (Sentouh et al. 2023, "
        f"(8)), and has no input of value 1 (the L-infinity UIO, family linf_uio, takes constant terms): make it an "
        f"exogenous signal at its nominal value, as the built-in model's rolling resistance F_rr: write {k} for "
        f"{brief(term)} in d{state}/dt, add {k} to exogenous=(...) of model {model.name!r} and {k} = "
        f"{float(value)!r} to [exogenous] of {params.source}")


def build(model: InterconnectedModelDefinition, params: ParameterSet, source=None) -> InterconnectedTS:
    """Derive the interconnected T-S model of Sentouh et al. 2023 (8)-(13) from ``model`` and its parameters
    (``source``: the model file, named by the errors about what it writes).

    Raises
    ------
    MissingParameterError, UnknownParameterError, ModelDefinitionError, NotAffineError,
    SchedulingBoundsError
    """
    subs = parameter_substitution(model, params)
    extra = _read_extra_tables(params.source)
    exo_nominal = {}
    for e in model.exogenous:
        if str(e) not in extra["exogenous"]:
            raise MissingParameterError(f"{params.source}: [exogenous] lacks the nominal value of {e}")
        exo_nominal[e] = extra["exogenous"][str(e)]
    stray = set(extra["exogenous"]) - {str(e) for e in model.exogenous}
    if stray:
        raise UnknownParameterError(f"{params.source}: [exogenous] sets {sorted(stray)}, not exogenous signals of "
                                    f"model {model.name!r}")
    switched = {w.symbol: sp.sympify(w.definition).subs(subs) for w in model.switched}
    sched = (*model.scheduling_states, *switched)
    rhs = model.rhs
    state_box = {}
    for s in model.states:
        if str(s) in params.state_bounds:
            state_box[s] = params.state_bounds[str(s)]
    for s in model.scheduling_states:
        if s not in state_box:
            raise SchedulingBoundsError(f"model {model.name!r}: scheduling state {s} has no [state_bounds] entry in "
                                        f"{params.source}")
    # unknown inputs: the subsystem whose equations they enter
    owner = {}
    for u in model.unknown_inputs:
        subs_in = [name for name, st in model.subsystems if any(u in sp.sympify(rhs[s]).free_symbols for s in st)]
        if len(subs_in) != 1:
            raise ModelDefinitionError(f"model {model.name!r}: unknown input {u} enters "
                                       f"{'no subsystem' if not subs_in else 'subsystems ' + ', '.join(subs_in)}; "
                                       f"each must enter exactly one")
        owner[u] = subs_in[0]
    # outputs: the subsystem whose states they read
    out_owner = {}
    for name, e in model.outputs:
        e = sp.sympify(e)
        subs_in = [sn for sn, st in model.subsystems if any(s in e.free_symbols for s in st)]
        linear_in = [sn for sn, st in model.subsystems
                     if any(sp.diff(sp.expand(e.subs(subs)), s).free_symbols == set() and sp.diff(e, s) != 0 for s in st)]
        if len(linear_in) != 1:
            raise ModelDefinitionError(f"model {model.name!r}: output {name!r} = {e} must read the states of exactly "
                                       f"one subsystem linearly (found {subs_in})")
        out_owner[name] = linear_in[0]
    subsystems = []
    for sname, own in model.subsystems:
        own = tuple(own)
        own_sched = tuple(s for s in model.scheduling_states if s in own)
        uis = tuple(u for u in model.unknown_inputs if owner[u] == sname)
        others = tuple(s for s in model.states if s not in own) + tuple(model.exogenous) + own
        n, p = len(own), len(uis)
        A_sym, B_sym = sp.zeros(n, n), sp.zeros(n, p)
        coupling = []

        def add_coupling(row, coeff, dep, target):
            key = next((k for k, c in enumerate(coupling) if sp.simplify(c.expr - dep) == 0), None)
            if key is None:
                coupling.append(CouplingSignal(dep))
                key = len(coupling) - 1
            target.setdefault(key, {})
            target[key][row] = target[key].get(row, 0) + coeff

        dmap = {}
        for i, s in enumerate(own):
            _refuse_constant(model, params, subs, s, sname, source)
            entry = sp.sympify(rhs[s]).subs(subs)
            arow, brow, cpl = _classify_drift(entry, own, own_sched, uis, sched, others, sname, s)
            for st, c in arow.items():
                A_sym[i, own.index(st)] += c
            for u, c in brow.items():
                B_sym[i, uis.index(u)] += c
            for coeff, dep in cpl:
                add_coupling(i, coeff, dep, dmap)
        outs = [(nm, sp.expand(sp.sympify(e).subs(subs))) for nm, e in model.outputs if out_owner[nm] == sname]
        C = np.zeros((len(outs), n))
        emap = {}
        for k, (nm, e) in enumerate(outs):
            for term in sp.Add.make_args(e):
                if term == 0:
                    continue
                if any(u in term.free_symbols for u in model.unknown_inputs):
                    raise NotAffineError(f"output {nm!r}: unknown inputs may not reach the outputs of the interconnected "
                                         f"UIO (term {brief(term)}); the L-infinity UIO (family linf_uio) takes that "
                                         f"feedthrough")
                lin = [s for s in own if s in term.free_symbols]
                if len(lin) == 1 and not (term / lin[0]).free_symbols:
                    C[k, own.index(lin[0])] += float(term / lin[0])
                    continue
                coeff, dep = term.as_independent(*others, as_Add=False)
                if coeff.free_symbols:
                    raise NotAffineError(f"output {nm!r}: term {brief(term)} has a non-constant coefficient {brief(coeff)}")
                add_coupling(k, coeff, dep, emap)
        nz = len(coupling)
        D_sym = sp.zeros(n, nz)
        for key, rows in dmap.items():
            for row, c in rows.items():
                D_sym[row, key] += c
        E = np.zeros((len(outs), nz))
        for key, rows in emap.items():
            for row, c in rows.items():
                E[row, key] += float(c)
        # premise-dependent B columns: g(theta) times a constant column -> u' = g u (see module docstring)
        scales, B_cols = [], []
        for j in range(p):
            col = B_sym[:, j]
            nonzero = [e for e in col if e != 0]
            if not nonzero:
                raise ModelDefinitionError(f"{sname}: unknown input {uis[j]} has a zero column")
            c0, g = sp.sympify(nonzero[0]).as_independent(*sched, as_Add=False)
            ratios = [sp.simplify(e / nonzero[0]) for e in col]
            if any(r.free_symbols for r in ratios) or (g != 1 and not g.free_symbols):
                raise NotAffineError(f"{sname}: the column of {uis[j]} depends on the premises other than through one "
                                     f"scalar factor; H_eta of (26) would vary and T_eta' enter (20)")
            scales.append(g)
            B_cols.append([float(c0 * r) for r in ratios])
        B = np.array(B_cols, dtype=float).T.reshape(n, p)
        factors = nonlinear_factors((A_sym, D_sym), sched)
        premises = []
        for k, g in enumerate(factors):
            premises.append(_premise(f"{sname[:3]}{k}", g, model, state_box, switched, extra["premise_bounds"],
                                     params.source))
        premises = tuple(premises)
        decomp = affine_decomposition({"A": A_sym, "D": D_sym}, sched, tuple(factors))
        q = len(premises)
        corners = [[(pr.upper if (idx >> (q - 1 - j)) & 1 else pr.lower) for j, pr in enumerate(premises)]
                   for idx in range(2 ** q)]
        mats = vertex_matrices(decomp, corners)
        subsystems.append(SubsystemTS(sname, own, uis, tuple(scales), tuple(nm for nm, _ in outs), tuple(coupling),
                                      premises, A_sym, D_sym, mats["A"].reshape(2 ** q, n, n), B,
                                      mats["D"].reshape(2 ** q, n, nz), C, E))
    return InterconnectedTS(model, params, tuple(subsystems), state_box, exo_nominal, switched, subs)


def _premise(name, g, model, state_box, switched, premise_bounds, source) -> Premise:
    """Range of premise g: ``[premise_bounds]`` if given there, else sound interval bounds over the
    state box (premises of switched signals must be given)."""
    for key, (lo, hi) in premise_bounds.items():
        if sp.simplify(sp.sympify(key, locals={str(s): s for s in g.free_symbols}) - g) == 0:
            return Premise(name, g, lo, hi)
    if any(s in switched for s in g.free_symbols):
        raise SchedulingBoundsError(f"premise {g} involves a switched signal; give its range in [premise_bounds] of "
                                    f"{source} (e.g. \"{g}\" = [min, max])")
    rb = range_bound(g, {s: state_box[s] for s in g.free_symbols}, rel_tol=1e-9)
    if not rb.upper > rb.lower:
        raise SchedulingBoundsError(f"premise {g} is constant on the state box")
    return Premise(name, g, rb.lower, rb.upper)


def _families() -> tuple:
    from ... import families
    return families.names()


def load(config) -> InterconnectedTS:
    """The representation of an observer file's model (``model = "NAME"`` of ``model_defs/`` or a
    ``.py`` path beside the file), which must define ``MODEL = InterconnectedModelDefinition(...)``."""
    model = config.load_definition()
    if not isinstance(model, InterconnectedModelDefinition):
        raise ModelDefinitionError(
            f"{config.model_path}: the interconnected UIO (family interconnected_uio) needs the states partitioned "
            f"into subsystems: MODEL = InterconnectedModelDefinition(subsystems=..., ...) "
            f"(codegen.families.interconnected_uio.representation); MODEL is a {type(model).__name__}, one system "
            f"of equations, which the other families take ({', '.join(f for f in _families() if f != 'interconnected_uio')})")
    return build(model, load_parameters(config.parameter_path), config.model_path)


def vertex_check(ts: InterconnectedTS, samples: int = 200, seed: int = 0) -> float:
    """Largest |sum eta_i A_i x + B u' + sum eta_i D_i zeta - f(x, u)| over random points of the box
    (the exactness of the sector representation; used by the tests)."""
    rng = np.random.default_rng(seed)
    d = ts.definition
    f = ts.rhs_function()
    worst = 0.0
    lo = {s: ts.state_box.get(s, (-1.0, 1.0))[0] for s in d.states}
    hi = {s: ts.state_box.get(s, (-1.0, 1.0))[1] for s in d.states}
    for _ in range(samples):
        x = {s: rng.uniform(lo[s], hi[s]) for s in d.states}
        u = {s: rng.normal() for s in d.unknown_inputs}
        exo = {s: rng.normal() for s in d.exogenous}
        sched_vals = {s: x[s] for s in d.scheduling_states}
        for sym, expr in ts.switched.items():
            sched_vals[sym] = float(expr.subs({s: x[s] for s in expr.free_symbols}))
        ok = True
        full = np.array(f([x[s] for s in d.states], [u[s] for s in d.unknown_inputs], [exo[s] for s in d.exogenous]),
                        dtype=float)
        for sub in ts.subsystems:
            theta = [float(p.expr.subs(sched_vals)) for p in sub.premises]
            if any(t < p.lower - 1e-12 or t > p.upper + 1e-12 for t, p in zip(theta, sub.premises)):
                ok = False
                break
        if not ok:
            continue
        for sub in ts.subsystems:
            theta = [float(p.expr.subs(sched_vals)) for p in sub.premises]
            eta = sub.eta(theta)
            xs = np.array([x[s] for s in sub.states])
            ups = np.array([float(g.subs(sched_vals)) * u[s] for g, s in zip(sub.ui_scales, sub.unknown_inputs)])
            zeta = np.array([float(c.expr.subs({**x, **exo})) for c in sub.coupling])
            A = np.einsum("i,ijk->jk", eta, sub.A)
            D = np.einsum("i,ijk->jk", eta, sub.D)
            approx = A @ xs + sub.B @ ups + (D @ zeta if sub.nzeta else 0.0)
            idx = [d.states.index(s) for s in sub.states]
            worst = max(worst, float(np.abs(approx - full[idx]).max() / (1.0 + np.abs(full[idx]).max())))
    return worst
