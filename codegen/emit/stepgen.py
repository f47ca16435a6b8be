"""Building blocks of the CasADi observer steps, shared by the families.

Unrolled solves without pivoting (the step's critical path is the chain of dependent divisions),
sums in a chosen order, constant-times-symbolic products that skip zeros, a clamp written with
selects, and the functions a derived expression may use in a CasADi lambdify. Everything here
builds SX graphs; nothing is evaluated numerically.
"""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import sympy as sp

from ..errors import ModelDefinitionError, brief
from ..model.definition import model_equations

# The functions a model's expressions may use, for every CasADi lambdify of the toolchain (sympy
# prints them unqualified). One table, so a function a user's model uses (tanh of a tyre, say) is
# never NaN in one step and fine in another.
CASADI_FUNCTIONS = {"sqrt": ca.sqrt, "exp": ca.exp, "log": ca.log, "Abs": ca.fabs, "Min": ca.fmin,
                    "Max": ca.fmax, "sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "asin": ca.asin,
                    "acos": ca.acos, "atan": ca.atan, "atan2": ca.atan2, "sinh": ca.sinh, "cosh": ca.cosh,
                    "tanh": ca.tanh, "asinh": ca.asinh, "acosh": ca.acosh, "atanh": ca.atanh, "erf": ca.erf,
                    "erfinv": ca.erfinv, "sign": ca.sign, "floor": ca.floor, "ceiling": ca.ceil,
                    "if_else": ca.if_else, "logic_and": ca.logic_and, "logic_or": ca.logic_or,
                    "logic_not": ca.logic_not}


def _no_casadi(name):
    def refuse(*_):
        raise ModelDefinitionError(f"the function {name} has no counterpart in the generated C (CasADi); the "
                                   f"model may use {', '.join(sorted(k for k in CASADI_FUNCTIONS if k.islower()))}, "
                                   f"Abs, Min, Max, Piecewise and Heaviside")
    return refuse


# Anything else sympy would take from Python's math module is refused by name: math's functions
# applied to a CasADi symbol return NaN, silently (math.atanh(SX) is nan). Only its constants stay.
_MATH = {name: _no_casadi(name) for name in dir(math) if callable(getattr(math, name)) and not name.startswith("_")}
_MATH.update(pi=math.pi, e=math.e, E=math.e, inf=math.inf)
CASADI_MODULES = [CASADI_FUNCTIONS, _MATH]


def supported_functions() -> str:
    """The functions a model's equations may use, as the errors name them."""
    return (f"{', '.join(sorted(k for k in CASADI_FUNCTIONS if k.islower() and '_' not in k and k != 'if_else'))}, "
            f"Abs, Min, Max, Piecewise and Heaviside")


def unsupported(expr, constants=()) -> list:
    """The function applications in ``expr`` that :func:`lambdify` cannot evaluate on CasADi symbols
    (no C counterpart: ``besselj``, ``sinc``, an undefined ``f(x)``), innermost ones only, in sympy's
    order; those reading only ``constants`` (parameters, folded to numbers before any C) are left out."""
    expr = sp.sympify(expr)
    constants = set(constants)
    failing = []
    for atom in sorted(expr.atoms(sp.Function), key=sp.default_sort_key):
        if not atom.free_symbols - constants:
            continue
        free = sorted(atom.free_symbols, key=str)
        try:
            lambdify(free, atom)(*[ca.SX.sym(str(s)) for s in free])
        except Exception:           # NameError, casadi's RuntimeError, the refusal of a math function
            failing.append(atom)
    return [a for a in failing if not any(b is not a and a.has(b) for b in failing)]


def check_functions(model, source) -> None:
    """Refuse a model whose equations use a function the generated C cannot evaluate (``besselj``,
    ``sinc``, an undefined ``f(x)``): every verb would otherwise fail later, the structural analysis
    with a traceback, the C's emission after a design that looked fine. Applications of parameters
    alone are folded to numbers before any C and pass.

    Raises
    ------
    ModelDefinitionError
        naming ``source`` (the model file), the function, the equation and what the model may use; a
        function of measured scheduling signals alone can be computed outside the observer and read
        as a scheduling signal of its own, which the error says.
    """
    constants = set(getattr(model, "parameters", ()))
    measured = {g.symbol for g in getattr(model, "scheduling", ()) if g.derived is None}
    for where, expr in model_equations(model):
        bad = unsupported(expr, constants)
        if not bad:
            continue
        atom = bad[0]
        name = getattr(atom.func, "__name__", str(atom.func))
        if atom.free_symbols - constants <= measured:
            fix = (f"compute {brief(atom)} outside the observer and read it as a scheduling signal of its own: "
                   f"SchedulingSignal(z) in the model with z where {brief(atom)} is, its box in [scheduling.z] of "
                   f"the parameter file and its column z in the data")
        else:
            fix = f"write {brief(atom)} with those functions (an approximation over the box the model runs in)"
        raise ModelDefinitionError(f"{source}: model {model.name!r} uses {name} ({where}: {brief(atom)}), which the "
                                   f"generated C cannot evaluate; a model's equations may use {supported_functions()}; "
                                   f"{fix}")


class _IfElse(sp.Function):
    """if_else(condition, then, else) for the CasADi printer (a Piecewise, a Heaviside)."""

    nargs = 3


def _casadi_form(expr):
    """``expr`` with what CasADi writes as selects (Piecewise, Heaviside) and logic (And, Or, Not)
    in the functions of :data:`CASADI_FUNCTIONS`."""
    expr = sp.sympify(expr)
    if not isinstance(expr, sp.Basic) or not expr.has(sp.Piecewise, sp.Heaviside, sp.And, sp.Or, sp.Not):
        return expr

    def piecewise(*pairs):
        (value, cond), rest = pairs[0], pairs[1:]
        if cond is sp.true or not rest:
            return value
        return _IfElse(cond, value, piecewise(*rest))

    def heaviside(x, h0=sp.Rational(1, 2)):
        return _IfElse(sp.Gt(x, 0), 1, _IfElse(sp.Lt(x, 0), 0, h0))
    expr = expr.replace(sp.Heaviside, heaviside)
    expr = expr.replace(sp.Piecewise, piecewise)
    expr = expr.replace(sp.And, lambda *a: sp.Function("logic_and")(*a) if len(a) == 2 else
                        sp.Function("logic_and")(a[0], sp.And(*a[1:])))
    expr = expr.replace(sp.Or, lambda *a: sp.Function("logic_or")(*a) if len(a) == 2 else
                        sp.Function("logic_or")(a[0], sp.Or(*a[1:])))
    expr = expr.replace(sp.Not, lambda a: sp.Function("logic_not")(a))
    return expr.replace(_IfElse, lambda c, a, b: sp.Function("if_else")(c, a, b))


def lambdify(args, expr, xp=ca, **options):
    """``sympy.lambdify`` for a CasADi graph (``xp`` = casadi: selects for Piecewise/Heaviside, any
    function without a C counterpart refused by name) or for numpy."""
    if xp is not ca:
        return sp.lambdify(args, expr, "numpy", **options)
    if isinstance(expr, (list, tuple)):
        form = [_casadi_form(e) for e in expr]
    elif isinstance(expr, sp.MatrixBase):
        form = expr.applyfunc(_casadi_form)
    else:
        form = _casadi_form(expr)
    return sp.lambdify(args, form, CASADI_MODULES, **options)


TAIL = 3   # trailing block solved by its adjugate (see :func:`solve_unpivoted`)


def reciprocal(x):
    """1/x as its own node: CasADi rewrites (1/x)*y into y/x, which would turn one shared
    reciprocal into one division per use. 0.5*(2/x) is bit-identical to 1/x (power-of-two
    scaling is exact) and is left alone, so each use costs a multiplication."""
    return 0.5 * (2.0 / x)


def adjugate(S):
    """Adjugate of a 1x1, 2x2 or 3x3 matrix given as nested lists (cofactors by 2x2 minors)."""
    n = len(S)
    if n == 1:
        return [[1.0]]
    if n == 2:
        return [[S[1][1], -S[0][1]], [-S[1][0], S[0][0]]]

    def minor(r0, r1, c0, c1):
        return S[r0][c0] * S[r1][c1] - S[r0][c1] * S[r1][c0]
    return [[minor(1, 2, 1, 2), -minor(0, 2, 1, 2), minor(0, 1, 1, 2)],
            [-minor(1, 2, 0, 2), minor(0, 2, 0, 2), -minor(0, 1, 0, 2)],
            [minor(1, 2, 0, 1), -minor(0, 2, 0, 1), minor(0, 1, 0, 1)]]


def solve_unpivoted(G, rhs, tail: int = TAIL):
    """Unrolled solve without pivoting, for matrices where that is known to be safe (checked by
    :func:`lu_without_pivoting_is_safe`, or with a positive definite symmetric part, ``tail=0``).

    The leading columns are eliminated by LU; the trailing ``tail`` x ``tail`` Schur complement
    is solved by its adjugate and one reciprocal of its determinant; back substitution gives the
    leading unknowns. Unlike a full LU, whose pivots form a chain of dependent divisions, the
    adjugate's cofactors are all computed at once: the step's critical path is much shorter.
    ``tail=0`` is a plain unpivoted LU.
    """
    n = G.shape[0]
    G = [[G[i, j] for j in range(n)] for i in range(n)]
    b = [rhs[i] for i in range(n)]
    lead = max(n - tail, 0)
    for k in range(lead):
        for i in range(k + 1, n):
            factor = G[i][k] / G[k][k]
            for j in range(k + 1, n):
                G[i][j] = G[i][j] - factor * G[k][j]
            b[i] = b[i] - factor * b[k]
    m = n - lead
    x = [None] * n
    if m:
        S = [row[lead:] for row in G[lead:]]
        adj = adjugate(S)
        inv_det = reciprocal(sum_in_order([S[0][k] * adj[k][0] for k in range(m)]))
        x[lead:] = [sum_in_order([adj[i][k] * b[lead + k] for k in range(m)]) * inv_det for i in range(m)]
    for i in reversed(range(lead)):
        acc = b[i]
        for j in reversed(range(i + 1, n)):
            acc = acc - G[i][j] * x[j]
        x[i] = acc * reciprocal(G[i][i])
    return ca.vertcat(*x)


def tree_sum(terms):
    """Sum as a balanced tree (shorter dependency chains than a running sum)."""
    while len(terms) > 1:
        terms = [terms[t] + terms[t + 1] if t + 1 < len(terms) else terms[t] for t in range(0, len(terms), 2)]
    return terms[0]


def sum_in_order(terms):
    """Running sum in the given order (terms ready last go last)."""
    total = terms[0]
    for t in terms[1:]:
        total = total + t
    return total


def const_times(a: np.ndarray, b: ca.SX) -> ca.SX:
    """Constant matrix times symbolic matrix, each entry summed as a balanced tree (shorter
    dependency chains than CasADi's running sum); zero coefficients are skipped."""
    rows = []
    for i in range(a.shape[0]):
        row = []
        for j in range(b.shape[1]):
            terms = [a[i, k] * b[k, j] for k in range(a.shape[1]) if a[i, k] != 0.0]
            row.append(tree_sum(terms) if terms else ca.SX(0))
        rows.append(ca.horzcat(*row))
    return ca.vertcat(*rows)


def clamp(v, lo: float, hi: float):
    """v clamped to [lo, hi] by comparisons and selects, exact for every finite v (the sum adds a
    zero). CasADi's fmax/fmin helpers call libm, which compilers do not inline without
    -ffinite-math-only: a call in the step around which every live floating-point register is
    spilled. A NaN v gives NaN (fmax would give lo); the wrapper flags such a sample and keeps
    nothing the step computed from it."""
    low = ca.if_else(v < lo, lo, v)
    return ca.if_else(hi < low, hi, low)
