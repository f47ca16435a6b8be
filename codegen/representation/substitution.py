"""Unknown inputs that enter through a nonlinearity: the change of variables that makes them affine.

Every observer family needs the unknown inputs to enter affinely (``x' = ... + D d``). A road
bank angle enters as ``g sin(phi_r)``, a steering angle the driver sets enters through the front
tyre's saturating law. When an unknown input ``d`` enters *only* through one expression
``c(d, x, ...)`` (its *carrier*: the same expression in every equation, nowhere else), the model is
affine in the carrier's value ``w = c``: the observer is designed with ``w`` as its unknown input,
and ``d`` is recovered in the step by inverting the carrier,

    d_hat = c^{-1}(w_hat; x_hat, u, y),

with ``w_hat`` kept inside the range ``c`` takes on the declared box (outside it the inverse is not
defined; a sample beyond it is clamped *and flagged*). The inverse exists when ``c`` is strictly
monotone in ``d`` on the box: :func:`analyse` proves this with a sound interval bound of ``dc/dd``
(:func:`codegen.representation.bounds.range_bound`) over the declared ranges of ``d``, the states
and the other signals ``c`` depends on, and finds the inverse in closed form (sympy), checked at
points of the box. Otherwise it says exactly why not.

An observer file asks for it by naming the new unknown input::

    [substitute]
    phi_r = "bank_accel"      # design for w = the one expression phi_r enters through

:func:`offer` writes that line into the error a family raises for a non-affine unknown input.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import sympy as sp

from ..errors import ModelDefinitionError, NotAffineError
from ..model.floats import merge_float_noise


@dataclass(frozen=True)
class Substitution:
    """One unknown input replaced by the value of its carrier."""

    unknown: sp.Symbol          # d, the user's unknown input
    carrier: sp.Expr            # c(d, ...), as written in the model (parameters symbolic)
    symbol: sp.Symbol           # w, the new unknown input
    inverse: sp.Expr            # d = inverse(w, other variables), parameters substituted
    lower: float                # range of w on the box
    upper: float
    slope: tuple                # sound [min, max] of dc/dd on the box (bounded away from 0)

    def describe(self) -> str:
        return (f"{self.unknown} enters only through {self.symbol} = {self.carrier}; designed for {self.symbol} "
                f"in [{self.lower:.6g}, {self.upper:.6g}], {self.unknown} recovered as {self.inverse}")

    def to_json(self) -> dict:
        return {"unknown_input": str(self.unknown), "carrier": str(self.carrier), "as": str(self.symbol),
                "inverse": str(self.inverse), "range": [self.lower, self.upper], "slope_bound": list(self.slope)}


def _variables(model) -> set:
    return {*model.states, *model.known_inputs, *model.unknown_inputs, *(g.symbol for g in model.scheduling),
            *(w.symbol for w in getattr(model, "derived_inputs", ()))}


def _is_nonlinear_node(e, d) -> bool:
    """A node that is not affine in ``d`` by its own operation (a function, a power, a product
    of two factors in ``d``)."""
    if isinstance(e, (sp.Function, sp.Piecewise, sp.Min, sp.Max)):
        return True
    if e.is_Pow:
        base, exp = e.args
        return d in exp.free_symbols or (d in base.free_symbols and exp != 1)
    if e.is_Mul:
        return sum(1 for a in e.args if d in a.free_symbols) > 1
    return False


def carriers(expr, d) -> tuple:
    """(set of outermost nonlinear nodes containing ``d``, whether ``d`` also appears outside them)."""
    found, direct = set(), [False]

    def visit(e):
        if d not in e.free_symbols:
            return
        if e == d:
            direct[0] = True
            return
        if _is_nonlinear_node(e, d):
            found.add(e)
            return
        for a in e.args:
            visit(a)
    visit(sp.sympify(expr))
    return found, direct[0]


def _rows(model) -> list:
    return merge_float_noise([*list(sp.Matrix(model.dynamics)), *[sp.sympify(e) for _, e in model.outputs]])


def find_carrier(model, d) -> tuple:
    """(carrier, None) when ``d`` enters every equation through one and the same expression, or
    (None, why not)."""
    found, direct = set(), False
    for row in _rows(model):
        c, dr = carriers(row, d)
        found |= c
        direct = direct or dr
    if not found:
        return None, f"{d} enters affinely already"
    if direct:
        return None, (f"{d} enters both directly and through {', '.join(sorted(map(str, found)))}: no single "
                      f"expression carries it")
    if len(found) > 1:
        combined = _combined(model, d, found)
        if combined is None:
            return None, (f"{d} enters through {len(found)} different expressions "
                          f"({'; '.join(sorted(map(str, found)))}) that no one expression combines (their "
                          f"coefficients are not in the same ratio in every equation): the change of variables needs "
                          f"one")
        return combined, None
    return next(iter(found)), None


def _coefficients(expr, d, nodes) -> list | None:
    """[coefficient of each node of ``nodes`` in ``expr``, the rest of ``expr``] where ``expr`` is
    affine in the nodes with coefficients free of ``d``; None where it is not."""
    zs = [sp.Dummy(f"z{k}") for k in range(len(nodes))]
    e = sp.sympify(expr).xreplace(dict(zip(nodes, zs)))
    if d in e.free_symbols:
        return None
    coeffs = [sp.diff(e, z) for z in zs]
    if any(c.free_symbols & set(zs) for c in coeffs):
        return None
    return [*coeffs, e.xreplace({z: 0 for z in zs})]


def _combined(model, d, found) -> sp.Expr | None:
    """The one expression ``sum_k v_k g_k`` through which ``d`` enters, where it enters every equation
    through the nodes ``g_k`` of ``found`` with coefficients in the same ratio ``v`` (a grade
    through ``m g (sin(theta) + f_r cos(theta))``); None where the ratios differ between equations.
    ``v`` is scaled to make the simplest expression (a coefficient 1 on one node)."""
    nodes = sorted(found, key=sp.default_sort_key)
    rows = []
    for row in _rows(model):
        if d not in sp.sympify(row).free_symbols:
            continue
        coeffs = _coefficients(row, d, nodes)
        if coeffs is None:
            return None
        rows.append(coeffs[:-1])
    best = None
    for k0 in range(len(nodes)):
        if rows[0][k0] == 0:
            continue
        v = [sp.simplify(c / rows[0][k0]) for c in rows[0]]
        if best is None or sum(sp.count_ops(x) for x in v) < sum(sp.count_ops(x) for x in best[1]):
            best = (k0, v)
    if best is None:
        return None
    k0, v = best
    for coeffs in rows[1:]:
        if any(sp.simplify(c - coeffs[k0] * vk) != 0 for c, vk in zip(coeffs, v)):
            return None
    return sp.Add(*(vk * g for vk, g in zip(v, nodes)))


def replace_carrier(expr, d, carrier, w) -> sp.Expr:
    """``expr`` with the carrier of ``d`` replaced by ``w``: the node itself, or for a carrier that
    combines several nodes (:func:`_combined`), the part ``alpha * carrier`` of ``expr`` by ``alpha * w``
    (``expr`` unchanged where the nodes are not in the carrier's ratio: the caller finds ``d`` left)."""
    expr = sp.sympify(expr)
    found, _ = carriers(carrier, d)
    if carrier in found or d not in expr.free_symbols:
        return expr.xreplace({carrier: w})
    nodes = sorted(found, key=sp.default_sort_key)
    mine, coeffs = _coefficients(carrier, d, nodes), _coefficients(expr, d, nodes)
    if mine is None or coeffs is None:
        return expr
    k0 = next(k for k, c in enumerate(mine[:-1]) if c != 0)
    alpha = coeffs[k0] / mine[k0]
    if any(sp.simplify(c - alpha * m) != 0 for c, m in zip(coeffs[:-1], mine[:-1])):
        return expr
    return coeffs[-1] + alpha * (w - mine[-1])


def _box(params, symbols, source: str) -> tuple:
    """({symbol: (lo, hi)}, missing names with the table that declares them)."""
    box, missing = {}, []
    for s in symbols:
        name = str(s)
        if name in params.state_bounds:
            box[s] = tuple(params.state_bounds[name])
        elif name in params.inputs:
            box[s] = (float(params.inputs[name]["min"]), float(params.inputs[name]["max"]))
        elif name in params.scheduling:
            b = params.scheduling[name]
            box[s] = (b.lower, b.upper)
        else:
            missing.append(name)
    return box, missing


def analyse(model, params, subs: dict, d, name: str) -> tuple:
    """(Substitution, None) for unknown input ``d`` as new unknown input ``name``, or (None, why not).
    ``subs``: the model's parameter values (``definition.parameter_substitution``, computed by the
    caller: the model layer's definitions import this module for :func:`offer`)."""
    from .bounds import range_bound
    carrier, why = find_carrier(model, d)
    if carrier is None:
        return None, why
    c = sp.sympify(carrier).subs(subs)
    others = sorted(c.free_symbols - {d}, key=str)
    stray = [s for s in others if s not in _variables(model)]
    if stray:
        return None, f"the carrier {carrier} of {d} depends on {', '.join(map(str, stray))}, which are not signals"
    box, missing = _box(params, [d, *others], params.source)
    if missing:
        return None, (f"proving {carrier} invertible in {d} needs the range of {', '.join(missing)}: add "
                      f"[inputs.NAME] min/max (inputs) or [state_bounds] NAME = [min, max] (states) to {params.source}")
    try:
        slope = range_bound(sp.diff(c, d), box, rel_tol=1e-2)
        rng = range_bound(c, box, rel_tol=1e-3)
    except ModelDefinitionError as exc:
        return None, f"{carrier} cannot be bounded on the box ({exc})"
    if slope.lower <= 0.0 <= slope.upper:
        return None, (f"{carrier} is not monotone in {d} on the box (its slope d/d{d} ranges over "
                      f"[{slope.lower:.4g}, {slope.upper:.4g}], which contains 0): {d} cannot be recovered from "
                      f"its value; narrow [inputs.{d}] or the state box")
    w = sp.Symbol(name)
    solutions = _inverses(c, d, w)
    rng_pts = np.random.default_rng(0)
    syms = [d, *others]
    pts = np.array([[rng_pts.uniform(*box[s]) for s in syms] for _ in range(200)])
    fc = sp.lambdify(syms, c, "numpy")
    for inv in solutions:
        finv = sp.lambdify([w, *others], inv, "numpy")
        with np.errstate(all="ignore"):
            wv = np.asarray(fc(*pts.T), dtype=complex)
            back = np.asarray(finv(wv, *pts[:, 1:].T), dtype=complex)
        if np.all(np.isfinite(back)) and np.allclose(back.real, pts[:, 0], rtol=1e-7, atol=1e-9) \
                and np.allclose(back.imag, 0.0, atol=1e-9):
            return Substitution(d, carrier, w, sp.simplify(inv) if sp.count_ops(inv) < 60 else inv,
                                float(rng.lower), float(rng.upper), (float(slope.lower), float(slope.upper))), None
    return None, f"no closed-form inverse of {carrier} in {d} (sympy found {len(solutions)} candidate(s), none exact)"


# f -> f^-1 for the functions a carrier is made of (the principal branch; checked numerically)
_INVERSE = {sp.tanh: sp.atanh, sp.atanh: sp.tanh, sp.sin: sp.asin, sp.asin: sp.sin, sp.tan: sp.atan,
            sp.atan: sp.tan, sp.sinh: sp.asinh, sp.asinh: sp.sinh, sp.exp: sp.log, sp.log: sp.exp,
            sp.cos: sp.acos, sp.acos: sp.cos, sp.erf: sp.erfinv}


def _inverses(c, d, w) -> list:
    """Candidate closed forms of d from w = c(d): peeled operation by operation when d occurs once
    in c (each elementary function by its principal inverse), else sympy's solve for a rational
    c. The caller checks each candidate at points of the box."""
    if sp.sympify(c).count(d) == 1:
        e, target = sp.sympify(c), w
        while e != d:
            if e.is_Add:
                inner = next(a for a in e.args if d in a.free_symbols)
                target, e = target - (e - inner), inner
            elif e.is_Mul:
                inner = next(a for a in e.args if d in a.free_symbols)
                target, e = target / (e / inner), inner
            elif e.is_Pow and d in e.args[0].free_symbols and d not in e.args[1].free_symbols:
                target, e = target ** (1 / e.args[1]), e.args[0]
            elif e.is_Pow and d in e.args[1].free_symbols and d not in e.args[0].free_symbols:
                target, e = sp.log(target) / sp.log(e.args[0]), e.args[1]
            elif isinstance(e, sp.Function) and e.func in _INVERSE and len(e.args) == 1:
                target, e = _INVERSE[e.func](target), e.args[0]
            else:
                return []
        return [target]
    harmonic = _harmonic(c, d, w)
    if harmonic:
        return harmonic
    if sp.sympify(c).is_rational_function(d):
        try:
            return list(sp.solve(sp.Eq(w, c), d))
        except (NotImplementedError, ValueError):
            return []
    return []


def _harmonic(c, d, w) -> list:
    """Candidates for d from w = a sin(E) + b cos(E) (+ c0), a, b, c0 free of d and E of one
    occurrence of d: a sin(E) + b cos(E) = R sin(E + phi) with R = sqrt(a^2 + b^2), phi = atan2(b, a),
    so E = asin((w - c0) / R) - phi or pi - asin((w - c0) / R) - phi, each peeled to d."""
    found, direct = carriers(c, d)
    if direct or len(found) != 2:
        return []
    nodes = sorted(found, key=lambda g: type(g) is sp.sin)        # cos, then sin
    if [type(g) for g in nodes] != [sp.cos, sp.sin] or nodes[0].args != nodes[1].args:
        return []
    inner = nodes[0].args[0]
    if sp.sympify(inner).count(d) != 1:
        return []
    coeffs = _coefficients(c, d, nodes)
    if coeffs is None:
        return []
    b, a, c0 = coeffs          # nodes sorted: cos before sin
    R, phi = sp.sqrt(a ** 2 + b ** 2), sp.atan2(b, a)
    out = []
    for e_val in (sp.asin((w - c0) / R) - phi, sp.pi - sp.asin((w - c0) / R) - phi):
        out += [sp.sympify(x).xreplace({w: e_val}) for x in _inverses(inner, d, w)]
    return out


def offer(model, d, params=None, subs: dict | None = None) -> str:
    """The sentence a family's "not affine in the unknown inputs" error ends with. With the
    parameter file (``params``, and the parameter values ``subs``) the change of variables is
    also proven (:func:`analyse`): where the box rules it out, the sentence says why instead of
    offering a table the design would refuse."""
    carrier, why = find_carrier(model, d)
    if carrier is None:
        return f"no change of variables applies: {why}"
    if params is not None:
        _, why = analyse(model, params, subs if subs is not None else {}, d, new_name(model, carrier, d))
        if why is not None:
            return f"{d} enters only through {carrier}, but no change of variables applies: {why}"
    return (f"{d} enters only through {carrier}: add [substitute] {d} = \"{d}_carrier\" to the observer file to "
            f"design for that expression's value and recover {d} by inverting it in the step (docs: tutorial, "
            f"'Unknown inputs inside a nonlinearity')")


def new_name(model, carrier, d, taken=()) -> str:
    """The name :func:`propose` gives the value of ``carrier``: ``sin_phi_r`` for ``sin(phi_r)`` (the
    carrier's outermost function and the input), ``phi_r_carrier`` for any other expression; a
    name the model already uses gets ``_w`` appended until it is new."""
    used = {str(s) for s in _variables(model)} | {str(p) for p in model.parameters} | set(taken)
    head = getattr(getattr(carrier, "func", None), "__name__", "")
    name = f"{head}_{d}" if isinstance(carrier, sp.Function) and head.isidentifier() else f"{d}_carrier"
    while name in used:
        name += "_w"
    return name


def propose(model, params, subs: dict) -> tuple:
    """({unknown input: new name}, {unknown input: why not}): the ``[substitute]`` table that makes
    ``model`` affine in its unknown inputs, for every unknown input that enters through a
    nonlinearity and whose carrier :func:`analyse` proves invertible on the box of ``params``
    (``subs``: the parameter values); the others with the reason no change of variables applies.
    An unknown input that enters affinely is in neither. ``uiogen analyze`` applies the table with
    :func:`apply`, as an observer file's ``[substitute]`` is applied."""
    table, refused = {}, {}
    for d in model.unknown_inputs:
        if not any(carriers(row, d)[0] for row in _rows(model)):
            continue                                    # affine in d already
        carrier, why = find_carrier(model, d)
        if carrier is not None:
            name = new_name(model, carrier, d, table.values())
            _, why = analyse(model, params, subs, d, name)
        if why is None:
            table[str(d)] = name
        else:
            refused[str(d)] = why
    return table, refused


def apply(model, params, subs: dict, table: dict, source: str) -> tuple:
    """(model with every named unknown input replaced by its carrier's value, [Substitution]).

    Raises
    ------
    NotAffineError
        naming the observer file, the unknown input and why the change of variables does not apply.
    ConfigurationError
        a key that is not an unknown input, or a name already used.
    """
    from ..settings import config_error, suggest
    uis = {str(d): d for d in model.unknown_inputs}
    taken = {str(s) for s in _variables(model)} | {str(p) for p in model.parameters}
    out, done = model, []
    for key, name in table.items():
        if key not in uis:
            raise config_error(source, "substitute", key, name, f"an unknown input of model {model.name!r} "
                               f"({', '.join(uis) or 'none'})", suggest(key, list(uis)))
        if not isinstance(name, str) or not name.isidentifier() or name in taken:
            raise config_error(source, "substitute", key, name, "a new identifier, not a name the model uses")
        sub, why = analyse(out, params, subs, uis[key], name)
        if sub is None:
            raise NotAffineError(f"{source}: [substitute] {key}: {why}")
        merged = _rows(out)           # the rows the carrier was found in (floats of rounding noise merged)
        rows = sp.Matrix([replace_carrier(e, uis[key], sub.carrier, sub.symbol)
                          for e in merged[:len(sp.Matrix(out.dynamics))]])
        outputs = tuple((n, replace_carrier(e, uis[key], sub.carrier, sub.symbol))
                        for (n, _), e in zip(out.outputs, merged[len(sp.Matrix(out.dynamics)):]))
        left = [str(e) for e in (*rows, *(e for _, e in outputs)) if uis[key] in e.free_symbols]
        if left:
            raise NotAffineError(f"{source}: [substitute] {key}: {key} is still in {left[0]} after the change of "
                                 f"variables")
        units = dict(out.units)
        out = replace(out, unknown_inputs=tuple(sub.symbol if u == uis[key] else u for u in out.unknown_inputs),
                      dynamics=rows, outputs=outputs, units=units)
        taken.add(name)
        done.append(sub)
    return out, done
