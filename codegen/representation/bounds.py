"""Sound bounds of symbolic functions over a box: interval arithmetic with branch and bound.

Used for the differential mean-value theorem (Nguyen et al. 2021, Assumption 1: the Jacobian
entries of an unmeasured nonlinearity phi(x) are bounded over the compact state set D_x) and for
the ranges of premise variables.

Soundness: what an enclosure holds
----------------------------------
:func:`evaluate` returns an interval that contains the value of the *real* function (the exact
expression, not its floating-point evaluation) at every point of the box:

* ``+``, ``*`` and ``1/x`` are IEEE-754 operations, correctly rounded; each end is moved outward by
  one ulp (``math.nextafter``), which covers that rounding. Integer powers are products of the
  same kind.
* Library calls (exp, log, sin, cos, tan, atan, tanh, sinh, cosh, asin, acos, the inverse
  hyperbolic functions and ``pow``) are widened by 16 ulps of their result (and 8 subnormal ulps
  near 0). The GNU C library documents its errors in a few ulps per function (glibc manual,
  section 19.7 "Known Maximum Errors in Math Functions"; its test suite refuses a recorded double
  error above 9 ulps), and every other mainstream libm is of the same order.
* A constant that is not a double (1/3, 10**17 + 1, pi, E, a Float of more than 53 bits) is the
  interval between its two neighbouring doubles; an exponent that is not a double (x**(1/3)) is
  an interval too.
* sin, cos and tan find their interior extremes and poles by a test that assumes an extremum (a
  pole) whenever the rounding of the argument reduction cannot exclude one, at any magnitude of
  the argument; their end values are the library's, which reduces large arguments correctly.

Functions made of branches
--------------------------
``Piecewise``, ``Min``, ``Max``, ``Abs``, ``sign`` and ``Heaviside`` (tyre laws with a sliding
clamp, a magic formula with a sign) are bounded by their branches. A ``Piecewise`` branch is
bounded on the part of the box where its condition can hold: a condition ``s < e`` (``<=``,
``>``, ``>=``, ``==``) on a symbol s of the box narrows s's range to where it can hold, ``And`` and
``Or`` combine them. Where a condition's truth is undecided on a box (the switch lies inside it)
the enclosure is the union of every branch that can apply there; branch and bound then splits
the box so that the pieces away from the switch are decided. A ``Heaviside`` or ``sign`` node
undecided on a box is a *switch*: the whole expression is bounded once per side of it (its value
fixed, the box narrowed to that side when its argument is linear in one symbol), since the terms
of a derivative that switch together must not be bounded as if they switched apart.
``DiracDelta`` is refused: it is the derivative of a jump, and a jump has no derivative bound.

Derivatives for the mean-value theorem
--------------------------------------
:func:`derivative` differentiates with the box's symbols taken real and drops the Dirac terms
that vanish (``g(u) DiracDelta(u)`` with ``g = 0`` where ``u = 0``, as in ``d/dt [sign(t) F(|t|)]``
with F(0) = 0); a Dirac term that does not vanish is refused (the function jumps). Where the
derivative switches (a clamp, an ``Abs``, a ``sign``), its enclosure over any box containing the
switch holds both one-sided derivatives: :func:`evaluate` contains, at every point of the box,
the value of the derivative expression *and its limits from every side within the box*. For a
function phi that is continuous on a box B and piecewise C^1 along each coordinate, any two
points a, b of B then satisfy the mean-value theorem in its Lipschitz form::

    phi(b) - phi(a) = sum_j theta_j (b_j - a_j),   theta_j in [lower_j, upper_j]

(walk from a to b one coordinate at a time, inside B; along each leg phi is absolutely
continuous and its derivative, where it exists, lies in the enclosure of d phi/d x_j; at a switch
theta_j lies between the one-sided derivatives, as in Clarke's generalized Jacobian).

Tightness
---------
:func:`range_bound` refines by branch and bound: the piece of the box holding the current worst
bound is bisected along its widest side until that bound is within ``rel_tol`` of a value the
function takes at a point of the box. A piece that reaches the top of the heap is first tightened
by its mean-value form f(c) + sum_j (d f/d x_j)(B) (B_j - c_j) (each case of its switches being a
continuous function: the same Lipschitz form of the theorem), which is far tighter than the
natural form where the function is flat (a tyre's slope fading into sliding); the mean-value form
is skipped for a while after it stops paying. The attained values come from the pieces' centres
and a few local searches (compass search in double precision), and are evaluated in mpmath at 128 bits
(rounded to the nearest double): ``lower <= attained_min <= attained_max <= upper`` holds as a
consequence of soundness, and the gap measures how tight the bounds are. Where the refinement stops
short of its tolerance (its budget of boxes spent, or a piece doubles cannot split), a caller that
only needs a sound bound (``enclose=True``: a DMVT vertex set, where a looser bound is a larger
polytope, not a wrong one) gets the enclosure reached, the least lower bound over the pieces left,
marked ``converged=False`` with its gap; it is refused only where that enclosure is not finite.
"""
from __future__ import annotations

import heapq
import math
import sys
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache

import mpmath
import sympy as sp

from ..errors import BoundsError

_INF = math.inf
_MAX = sys.float_info.max
_LIBM_REL = 2.0 ** -48       # >= 16 ulps of a result: |v| 2^-48 >= 16 ulp(v)
_LIBM_ABS = 8 * 2.0 ** -1074  # 8 subnormal ulps, for results near 0
_POINT_PREC = 128             # bits of the mpmath evaluation of attained values
_GUIDE = 1e-9                 # a double-precision value this close to an attained one is checked in mpmath
_SEARCH_EVALUATIONS = 400     # double-precision evaluations of one local search


def _down(x: float) -> float:
    return math.nextafter(x, -_INF)


def _up(x: float) -> float:
    return math.nextafter(x, _INF)


# A sum with a 0 operand and a product with a 0 or +-1 operand are exact: no outward step, which would
# lose the sign of a range that starts at 0 (sqrt, log and the Piecewise narrowing rely on it) and
# blur the values of a switch (Heaviside, sign). 0 * inf is 0 here: an infinite end means
# "unbounded", and 0 times any real number is 0.

def _sum_down(a: float, b: float) -> float:
    return a + b if (a == 0.0 or b == 0.0) else _down(a + b)


def _sum_up(a: float, b: float) -> float:
    return a + b if (a == 0.0 or b == 0.0) else _up(a + b)


def _product_down(a: float, b: float) -> float:
    if a == 0.0 or b == 0.0:
        return 0.0
    return a * b if (abs(a) == 1.0 or abs(b) == 1.0) else _down(a * b)


def _product_up(a: float, b: float) -> float:
    if a == 0.0 or b == 0.0:
        return 0.0
    return a * b if (abs(a) == 1.0 or abs(b) == 1.0) else _up(a * b)


def _lib_down(v: float) -> float:
    """A lower bound of the true value of a library call that returned ``v``."""
    if math.isinf(v):
        return v if v < 0 else _MAX       # +inf: the call overflowed, the true value is above DBL_MAX
    return _down(v - (abs(v) * _LIBM_REL + _LIBM_ABS))


def _lib_up(v: float) -> float:
    """An upper bound of the true value of a library call that returned ``v``."""
    if math.isinf(v):
        return v if v > 0 else -_MAX
    return _up(v + (abs(v) * _LIBM_REL + _LIBM_ABS))


def _call(fn, x: float) -> float:
    """``fn(x)`` with an overflow as the infinity of the result's sign (exp, sinh, cosh grow past DBL_MAX)."""
    try:
        return fn(x)
    except OverflowError:
        return -_INF if (fn is math.sinh and x < 0) else _INF


@dataclass(slots=True)
class Interval:
    """Closed interval [lo, hi] with outward-rounded arithmetic."""

    lo: float
    hi: float

    def __add__(self, other: "Interval") -> "Interval":
        return Interval(_sum_down(self.lo, other.lo), _sum_up(self.hi, other.hi))

    def __sub__(self, other: "Interval") -> "Interval":
        return self + (-other)

    def __neg__(self) -> "Interval":
        return Interval(-self.hi, -self.lo)

    def __mul__(self, other: "Interval") -> "Interval":
        ends = [(a, b) for a in (self.lo, self.hi) for b in (other.lo, other.hi)]
        return Interval(min(_product_down(a, b) for a, b in ends), max(_product_up(a, b) for a, b in ends))

    def hull(self, other: "Interval") -> "Interval":
        return Interval(min(self.lo, other.lo), max(self.hi, other.hi))

    def contains_zero(self) -> bool:
        return self.lo <= 0.0 <= self.hi

    def reciprocal(self) -> "Interval":
        if self.contains_zero():
            raise BoundsError(f"division by an interval containing 0: [{self.lo}, {self.hi}]")
        return Interval(_down(1.0 / self.hi), _up(1.0 / self.lo))

    def power(self, n: int) -> "Interval":
        """self ** n for an integer n, by products rounded outward (no library call)."""
        if n == 0:
            return Interval(1.0, 1.0)
        if n < 0:
            return self.power(-n).reciprocal()
        a, b = abs(self.lo), abs(self.hi)
        if n % 2 == 0:
            return Interval(0.0 if self.contains_zero() else _pow_down(min(a, b), n), _pow_up(max(a, b), n))
        # odd: monotone increasing, keeps the signs of the ends
        lo_end = -_pow_up(a, n) if self.lo < 0 else _pow_down(a, n)
        hi_end = -_pow_down(b, n) if self.hi < 0 else _pow_up(b, n)
        return Interval(lo_end, hi_end)

    def monotone(self, fn, increasing: bool = True) -> "Interval":
        """The image under a library function ``fn`` monotone on the interval, widened by its error."""
        a, b = _call(fn, self.lo), _call(fn, self.hi)
        if not increasing:
            a, b = b, a
        return Interval(_lib_down(a), _lib_up(b))


def _pow_down(a: float, n: int) -> float:
    """A lower bound of a**n for a >= 0 (binary powering, each product rounded down)."""
    out, base = 1.0, a
    while n:
        if n & 1:
            out = max(0.0, _down(out * base))
        n >>= 1
        if n:
            base = max(0.0, _down(base * base))
    return out


def _pow_up(a: float, n: int) -> float:
    """An upper bound of a**n for a >= 0."""
    out, base = 1.0, a
    while n:
        if n & 1:
            out = _up(out * base)
        n >>= 1
        if n:
            base = _up(base * base)
    return out


# --- constants -----------------------------------------------------------------------------------

def _rational(value: Fraction) -> Interval:
    """The double nearest ``value``, or its two neighbouring doubles when it is not one."""
    try:
        v = value.numerator / value.denominator          # Python's int division is correctly rounded
    except OverflowError:
        raise BoundsError(f"constant {value} is beyond the double range") from None
    exact = Fraction(v)
    if exact == value:
        return Interval(v, v)
    return Interval(_down(v), v) if exact > value else Interval(v, _up(v))


@lru_cache(maxsize=4096)
def _constant(expr: sp.Expr) -> Interval:
    if expr.is_Rational:
        return _rational(Fraction(int(expr.p), int(expr.q)))
    if expr.is_Float:
        if not expr.is_finite:
            raise BoundsError(f"constant {expr} is not finite")
        r = sp.Rational(expr)                               # the Float's exact binary value
        return _rational(Fraction(int(r.p), int(r.q)))
    if expr.is_NumberSymbol:                                # pi, E, ...: irrational, strictly between
        v = float(expr.evalf(40))
        return Interval(_down(v), _up(v))
    raise BoundsError(f"constant {expr} is not a finite real number")


# --- periodic functions --------------------------------------------------------------------------

_TWO_PI = 2.0 * math.pi


def _may_reach(lo: float, hi: float, offset: float, period: float) -> bool:
    """Whether [lo, hi] may hold a point offset + k period (k an integer), True when rounding cannot exclude it.

    ``offset`` and ``period`` are doubles of pi multiples (relative error 2^-53 each); the quotient
    below is then within (|q| + 1) 2^-50 of the true one, far inside the slack of 2^-46.
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return True
    a, b = (lo - offset) / period, (hi - offset) / period
    slack = (abs(a) + abs(b) + 1.0) * 2.0 ** -46
    return math.floor(b + slack) >= math.ceil(a - slack)


def _sin_cos(iv: Interval, fn, top: float, bottom: float) -> Interval:
    """Range of sin or cos (``fn``) over iv; maxima at top + 2k pi, minima at bottom + 2k pi."""
    if not (math.isfinite(iv.lo) and math.isfinite(iv.hi)) or iv.hi - iv.lo >= _TWO_PI:
        return Interval(-1.0, 1.0)
    a, b = fn(iv.lo), fn(iv.hi)
    lo, hi = min(_lib_down(a), _lib_down(b)), max(_lib_up(a), _lib_up(b))
    if _may_reach(iv.lo, iv.hi, top, _TWO_PI):
        hi = 1.0
    if _may_reach(iv.lo, iv.hi, bottom, _TWO_PI):
        lo = -1.0
    return Interval(max(-1.0, lo), min(1.0, hi))


def _tan(iv: Interval, expr) -> Interval:
    if _may_reach(iv.lo, iv.hi, math.pi / 2, math.pi):
        raise BoundsError(f"{expr}: the range [{iv.lo}, {iv.hi}] of the argument may reach a pole of tan")
    return iv.monotone(math.tan)


# --- the rules -----------------------------------------------------------------------------------

def _clip(iv: Interval, lo: float, hi: float) -> Interval:
    """``iv`` intersected with the function's known range [lo, hi] (the library may overshoot it by ulps)."""
    return Interval(max(lo, iv.lo), min(hi, iv.hi))


def _domain(expr, iv: Interval, lo: float, hi: float, open_: bool = False) -> None:
    inside = (lo < iv.lo and iv.hi < hi) if open_ else (lo <= iv.lo and iv.hi <= hi)
    if not inside:
        where = f"({lo}, {hi})" if open_ else f"[{lo}, {hi}]"
        raise BoundsError(f"{expr}: the argument's range [{iv.lo}, {iv.hi}] leaves the domain {where}")


def _log(iv: Interval, expr) -> Interval:
    if iv.lo <= 0:
        raise BoundsError(f"{expr}: log of a range reaching {iv.lo}")
    return iv.monotone(math.log)


def _cosh(iv: Interval) -> Interval:
    if iv.contains_zero():
        return Interval(1.0, max(_lib_up(_call(math.cosh, iv.lo)), _lib_up(_call(math.cosh, iv.hi))))
    return _clip(Interval(min(abs(iv.lo), abs(iv.hi)), max(abs(iv.lo), abs(iv.hi))).monotone(math.cosh), 1.0, _INF)


def _abs(iv: Interval) -> Interval:
    if iv.contains_zero():
        return Interval(0.0, max(-iv.lo, iv.hi))
    return Interval(min(abs(iv.lo), abs(iv.hi)), max(abs(iv.lo), abs(iv.hi)))


def _sign(iv: Interval) -> Interval:
    return Interval(-1.0 if iv.lo < 0 else (0.0 if iv.lo == 0 else 1.0),
                    1.0 if iv.hi > 0 else (0.0 if iv.hi == 0 else -1.0))


_UNARY = {
    sp.sin: lambda a, e: _sin_cos(a, math.sin, math.pi / 2, -math.pi / 2),
    sp.cos: lambda a, e: _sin_cos(a, math.cos, 0.0, math.pi),
    sp.tan: _tan,
    sp.atan: lambda a, e: a.monotone(math.atan),
    sp.tanh: lambda a, e: _clip(a.monotone(math.tanh), -1.0, 1.0),
    sp.exp: lambda a, e: _clip(a.monotone(math.exp), 0.0, _INF),
    sp.log: _log,
    sp.sinh: lambda a, e: a.monotone(math.sinh),
    sp.cosh: lambda a, e: _cosh(a),
    sp.asinh: lambda a, e: a.monotone(math.asinh),
    sp.acosh: lambda a, e: (_domain(e, a, 1.0, _INF), _clip(a.monotone(math.acosh), 0.0, _INF))[1],
    sp.atanh: lambda a, e: (_domain(e, a, -1.0, 1.0, open_=True), a.monotone(math.atanh))[1],
    sp.asin: lambda a, e: (_domain(e, a, -1.0, 1.0), a.monotone(math.asin))[1],
    sp.acos: lambda a, e: (_domain(e, a, -1.0, 1.0), _clip(a.monotone(math.acos, increasing=False), 0.0, _INF))[1],
    sp.Abs: lambda a, e: _abs(a),
}


def _const_pow(b: Interval, e: Interval, expr) -> Interval:
    """b ** e for a constant non-integer exponent e (an interval when e is not a double)."""
    if b.lo < 0 or (e.hi < 0 and b.lo <= 0):
        raise BoundsError(f"{expr}: base range [{b.lo}, {b.hi}] is not positive")
    # t**e is monotone in t (for a sign of e) and in e (on each side of t = 1): extremes at the corners
    vals = [_pow_call(t, x) for t in (b.lo, b.hi) for x in (e.lo, e.hi)]
    return Interval(max(0.0, min(map(_lib_down, vals))), max(map(_lib_up, vals)))


def _symbolic_pow(b: Interval, e: Interval, expr) -> Interval:
    """b ** e = exp(e log b) for a positive base."""
    if b.lo <= 0:
        raise BoundsError(f"{expr}: a symbolic exponent needs a positive base, the base reaches {b.lo}")
    return _clip((e * _log(b, expr)).monotone(math.exp), 0.0, _INF)


def _pow_call(t: float, x: float) -> float:
    try:
        return math.pow(t, x)
    except OverflowError:
        return _INF


_HALF_PI = Interval(_down(math.pi / 2), _up(math.pi / 2))    # fl(pi/2) < pi/2 < its successor


def _atan2(y: Interval, x: Interval) -> Interval:
    if x.lo > 0:                          # atan(y / x)
        return (y * x.reciprocal()).monotone(math.atan)
    if y.lo > 0:                          # pi/2 - atan(x / y)
        return _HALF_PI - (x * y.reciprocal()).monotone(math.atan)
    if y.hi < 0:                          # -pi/2 - atan(x / y)
        return -_HALF_PI - (x * y.reciprocal()).monotone(math.atan)
    pi = _up(math.pi)                     # the box reaches the branch cut (or the origin)
    return Interval(-pi, pi)


def _heaviside(a: Interval, h0: Interval) -> Interval:
    out = None
    for holds, part in ((a.lo < 0, Interval(0.0, 0.0)), (a.contains_zero(), h0), (a.hi > 0, Interval(1.0, 1.0))):
        if holds:
            out = part if out is None else out.hull(part)
    return out


# --- conditions and Piecewise --------------------------------------------------------------------

def _relation(cond, L: Interval, R: Interval, env: dict) -> tuple:
    """(truth, env) of a relational whose sides enclose to L and R: truth True/False on the whole box
    or None (undecided), and the box narrowed to where the relation can hold when one side is a
    symbol of the box."""
    op, lhs, rhs = cond.rel_op, cond.lhs, cond.rhs
    if op in (">", ">="):                                   # a > b  is  b < a
        op, lhs, rhs, L, R = {">": "<", ">=": "<="}[op], rhs, lhs, R, L
    if op == "<":
        truth = True if L.hi < R.lo else (False if L.lo >= R.hi else None)
    elif op == "<=":
        truth = True if L.hi <= R.lo else (False if L.lo > R.hi else None)
    elif op == "==":
        truth = (True if L.lo == L.hi == R.lo == R.hi else
                 False if (L.hi < R.lo or R.hi < L.lo) else None)
    elif op == "!=":
        truth = (False if L.lo == L.hi == R.lo == R.hi else
                 True if (L.hi < R.lo or R.hi < L.lo) else None)
    else:
        raise BoundsError(f"no interval rule for the condition {cond}")
    if truth is not None or op == "!=":
        return truth, env
    # narrow a symbol's range to where the relation can hold (closed ends: a superset)
    narrowed = dict(env)
    for side, other, below in ((lhs, R, True), (rhs, L, False)):
        if side.is_Symbol and side in env:
            lo, hi = narrowed[side]
            if op == "==":
                lo, hi = max(lo, other.lo), min(hi, other.hi)
            elif below:                                     # s < other
                hi = min(hi, other.hi)
            else:                                           # other < s
                lo = max(lo, other.lo)
            if lo > hi:
                return False, env
            narrowed[side] = (lo, hi)
    return None, narrowed


@lru_cache(maxsize=4096)
def _compile_condition(cond):
    """A function env -> (truth, env): whether ``cond`` holds on all of the box (True), none of it
    (False) or is undecided (None), and a sub-box holding every point of the box where it can hold."""
    if cond is sp.true:
        return lambda env: (True, env)
    if cond is sp.false:
        return lambda env: (False, env)
    if isinstance(cond, sp.core.relational.Relational):
        fl, fr = _compile(cond.lhs), _compile(cond.rhs)
        return lambda env: _relation(cond, fl(env), fr(env), env)
    parts = [_compile_condition(c) for c in cond.args] if isinstance(cond, (sp.And, sp.Or, sp.Not)) else None
    if isinstance(cond, sp.And):
        def conjunction(env):
            truth, narrowed = True, env
            for part in parts:
                t, narrowed = part(narrowed)        # points satisfying all lie in each narrowing
                if t is False:
                    return False, env
                if t is None:
                    truth = None
            return truth, narrowed
        return conjunction
    if isinstance(cond, sp.Or):
        def disjunction(env):
            outcomes = [part(env) for part in parts]
            if any(t is True for t, _ in outcomes):
                return True, env
            live = [b for t, b in outcomes if t is None]
            if not live:
                return False, env
            return None, {k: (min(b[k][0] for b in live), max(b[k][1] for b in live)) for k in env}
        return disjunction
    if isinstance(cond, sp.Not):
        def negation(env):
            t, _ = parts[0](env)
            return (None if t is None else not t), env
        return negation
    return _refuse(f"no interval rule for the condition {cond}")


def _compile_piecewise(expr):
    parts = [(_compile(b), _compile_condition(c), _compile_condition(sp.Not(c))) for b, c in expr.args]
    total = sp.Or(*(c for _, c in expr.args)) is sp.true

    def piecewise(env):
        out, reaching = None, env          # ``reaching``: holds every point where no earlier condition holds
        for branch, cond, negation in parts:
            truth, narrowed = cond(reaching)
            if truth is False:
                continue
            iv = branch(narrowed)
            out = iv if out is None else out.hull(iv)
            if truth is True:
                return out
            _, reaching = negation(reaching)
        if out is None or not total:
            raise BoundsError(f"{expr} may be undefined on part of the box (no condition holds there); end it "
                              f"with (expression, True)")
        return out
    return piecewise


# --- compilation: a sympy tree into nested interval functions --------------------------------------

def _refuse(message: str):
    def refuse(env):
        raise BoundsError(message)
    return refuse


def _fold(fs: list, op):
    first, rest = fs[0], fs[1:]

    def fold(env):
        out = first(env)
        for f in rest:
            out = op(out, f(env))
        return out
    return fold


@lru_cache(maxsize=16384)
def _compile(expr):
    """A function env -> Interval enclosing ``expr``; env holds {symbol: (lo, hi)}, and
    {switch: (lo, hi)} for a switch (Heaviside or sign node) whose value a case of :func:`_enclose`
    has fixed. Errors (a singular range, a missing rule) are raised when the function runs, so a
    Piecewise branch that no point reaches never raises."""
    if expr.is_Symbol:
        def symbol(env):
            try:
                lo, hi = env[expr]
            except KeyError:
                raise BoundsError(f"symbol {expr} has no range in the box") from None
            return Interval(lo, hi)
        return symbol
    if expr.is_Number or expr.is_NumberSymbol:
        try:
            iv = _constant(expr)
        except BoundsError as exc:
            return _refuse(str(exc))
        return lambda env: iv
    args = expr.args
    if expr.is_Add:
        return _fold([_compile(a) for a in args], Interval.__add__)
    if expr.is_Mul:
        if args[0] is sp.S.NegativeOne:                 # -e: exact
            rest = _compile(expr.func(*args[1:]))
            return lambda env: -rest(env)
        return _fold([_compile(a) for a in args], Interval.__mul__)
    if expr.is_Pow:
        base, exp = args
        fb = _compile(base)
        if exp.is_Integer or (exp.is_Float and float(exp).is_integer() and abs(float(exp)) < 2 ** 31):
            n = int(exp)
            if n >= 0:
                return lambda env: fb(env).power(n)

            def inverse(env):
                b = fb(env)
                if b.contains_zero():
                    raise _division_by_zero(expr, base, b, env)
                return b.power(n)
            return inverse
        if exp.is_Rational or exp.is_Float:
            e = _constant(exp)
            return lambda env: _const_pow(fb(env), e, expr)
        fe = _compile(exp)
        return lambda env: _symbolic_pow(fb(env), fe(env), expr)
    fn = expr.func
    if fn is sp.Piecewise:
        return _compile_piecewise(expr)
    if fn is sp.Min or fn is sp.Max:
        fs, pick = [_compile(a) for a in args], (min if fn is sp.Min else max)

        def min_max(env):
            parts = [f(env) for f in fs]
            return Interval(pick(p.lo for p in parts), pick(p.hi for p in parts))
        return min_max
    if fn is sp.Heaviside or fn is sp.sign:
        fa = _compile(args[0])
        if fn is sp.Heaviside:
            h0 = _constant(args[1]) if len(args) > 1 else Interval(0.5, 0.5)
            rule = lambda env: _heaviside(fa(env), h0)           # noqa: E731
        else:
            rule = lambda env: _sign(fa(env))                    # noqa: E731

        def switch(env):
            fixed = env.get(expr)
            return Interval(*fixed) if fixed is not None else rule(env)
        return switch
    if fn is sp.atan2:
        fy, fx = _compile(args[0]), _compile(args[1])
        return lambda env: _atan2(fy(env), fx(env))
    if fn is sp.DiracDelta:
        return _refuse(f"{expr}: a DiracDelta is the derivative of a jump and has no bound; a law whose "
                       f"derivative is bounded must be continuous (codegen.representation.bounds.derivative drops the "
                       f"Dirac terms that vanish, such as t DiracDelta(t))")
    if fn in _UNARY and len(args) == 1:
        fa, rule = _compile(args[0]), _UNARY[fn]
        return lambda env: rule(fa(env), expr)
    return _refuse(f"no interval rule for {getattr(fn, '__name__', fn)} in {expr}")


def _division_by_zero(expr, base, b: Interval, env: dict) -> BoundsError:
    """The error of ``expr`` = ``base`` ** -n where ``base`` encloses 0 on the box ``env``: it names
    the denominator, its range, and the box's signals of the denominator whose range reaches 0
    (``singular``; else every signal it depends on)."""
    from ..errors import brief
    free = sorted(base.free_symbols, key=str)
    ranges = {s: env[s] for s in free if s in env}
    reach = [s for s, (lo, hi) in ranges.items() if lo <= 0.0 <= hi] or list(ranges)
    where = ", ".join(f"{s} in [{ranges[s][0]:.6g}, {ranges[s][1]:.6g}]" for s in reach)
    return BoundsError(f"division by an interval containing 0: {brief(expr)} divides by {brief(base)}, whose range "
                       f"[{b.lo:.6g}, {b.hi:.6g}] contains 0" + (f" where {where}" if where and not base.is_Symbol
                                                                 else ""),
                       singular=tuple(str(s) for s in reach))


def _eval(expr, box: dict) -> Interval:
    """The enclosure of ``expr`` on ``box`` (see :func:`_compile`)."""
    return _compile(expr)(box)


def evaluate(expr: sp.Expr, box: dict) -> Interval:
    """Interval enclosure of ``expr`` for symbol values in ``box`` ({symbol: (lo, hi)}).

    The enclosure holds the exact real value at every point of the box (see the module docstring
    for what each rule assumes), and, for a function with branches, every one-sided limit from
    within the box.

    Raises
    ------
    BoundsError
        for a function without an interval rule, a singularity (a division by a range holding 0,
        a log or a power of a range reaching 0, a pole of tan) or a DiracDelta.
    """
    expr = sp.sympify(expr)
    return _enclose(expr, {s: (float(lo), float(hi)) for s, (lo, hi) in box.items()}, _switches(expr))


# --- switches: one case per side ------------------------------------------------------------------

_MAX_CASE_SWITCHES = 8      # undecided switches split into cases per box; beyond, their own rule (sound, wider)


@lru_cache(maxsize=1024)
def _switches(expr: sp.Expr) -> tuple:
    """The Heaviside and sign nodes of ``expr``, each with how its argument's sign narrows the box.

    The same switch appears in several terms of a derivative (d/dt of a clamped law is a sum of
    terms each multiplied by the same Heaviside); bounding each term with the switch's whole range
    [0, 1] loses that they switch together, and no subdivision recovers it at the switch. So
    :func:`_enclose` evaluates the whole expression once per side of each undecided switch.
    """
    out = []
    for atom in sorted(expr.atoms(sp.Heaviside, sp.sign), key=sp.default_sort_key):
        u, narrowing = atom.args[0], None
        if len(u.free_symbols) == 1:
            (s,) = u.free_symbols
            k = sp.diff(u, s)
            if k.is_number and not k.has(sp.nan, sp.zoo):
                kv = _eval(k, {})
                if kv.lo > 0 or kv.hi < 0:                  # u = k (s - root), k of one sign
                    narrowing = (s, kv.lo > 0, _eval(-u.subs(s, 0) / k, {}))
        out.append((atom, narrowing))
    return tuple(out)


def _side_box(box: dict, narrowing, side: int):
    """``box`` narrowed to where the switch's argument u has the sign ``side`` (-1, 0, 1), or None if empty."""
    if narrowing is None:
        return box
    s, rising, root = narrowing
    if s not in box:
        return box
    lo, hi = box[s]
    if side == 0:
        lo, hi = max(lo, root.lo), min(hi, root.hi)
    elif (side < 0) == rising:          # u < 0 with k > 0, or u > 0 with k < 0: s <= root
        hi = min(hi, root.hi)
    else:
        lo = max(lo, root.lo)
    return None if lo > hi else {**box, s: (lo, hi)}


def _enclose(expr, box: dict, switches: tuple, centered: tuple = (), k: int = 0, undecided: int = 0,
             fixed: tuple = ()) -> Interval:
    """``_eval`` with each undecided switch of ``switches[k:]`` fixed to each of its values in turn
    (union); with ``centered`` (the box's symbols), each case is also bounded by its mean-value form."""
    if k == len(switches):
        natural = _eval(expr, box)
        return _mean_value_form(expr, box, fixed, centered, natural) if centered else natural
    atom, narrowing = switches[k]
    u = _eval(atom.args[0], box)
    if atom.func is sp.Heaviside:
        values = {-1: sp.S.Zero, 0: atom.args[1] if len(atom.args) > 1 else sp.S.Half, 1: sp.S.One}
    else:
        values = {-1: sp.S.NegativeOne, 0: sp.S.Zero, 1: sp.S.One}
    sides = [side for side, holds in ((-1, u.lo < 0), (0, u.lo <= 0 <= u.hi), (1, u.hi > 0)) if holds]
    if len(sides) > 1 and undecided >= _MAX_CASE_SWITCHES:
        return _enclose(expr, box, switches, centered, k + 1, undecided, fixed)
    out = None
    for side in sides:
        part = _side_box(box, narrowing, side)
        if part is None:
            continue
        v = _constant(values[side])
        iv = _enclose(expr, {**part, atom: (v.lo, v.hi)}, switches, centered, k + 1, undecided + (len(sides) > 1),
                      fixed + ((atom, values[side]),))
        out = iv if out is None else out.hull(iv)
    return out if out is not None else _eval(expr, box)


_NOT_CONTINUOUS = (sp.Piecewise, sp.atan2, sp.Heaviside, sp.sign, sp.DiracDelta)


@lru_cache(maxsize=4096)
def _case_gradient(expr: sp.Expr, fixed: tuple, symbols: tuple):
    """(f, gradient) of ``expr`` with its switches fixed, or None where that case may not be continuous
    (a Piecewise, an atan2 or a switch left in it): the mean-value form needs a continuous function."""
    case = expr.xreplace(dict(fixed))
    if case.has(*_NOT_CONTINUOUS):
        return None
    try:
        return _compile(case), tuple(_compile(derivative(case, s)) for s in symbols)
    except BoundsError:
        return None


def _mean_value_form(expr, box: dict, fixed: tuple, symbols: tuple, natural: Interval) -> Interval:
    """``natural`` intersected with f(c) + sum_j g_j(B) (B_j - c_j): c the box's centre, g_j an enclosure
    of d f/d x_j on B, f the case (continuous on B: the mean-value theorem in Lipschitz form, leg by
    leg from c). Far tighter than the natural form where the derivative is small: near a smooth
    extremum, where a tyre's slope fades into sliding."""
    found = _case_gradient(expr, fixed, symbols)
    if found is None:
        return natural
    f, grads = found
    try:
        centre = {s: 0.5 * (box[s][0] + box[s][1]) for s in symbols}
        acc = f({**box, **{s: (c, c) for s, c in centre.items()}})
        for s, g in zip(symbols, grads):
            lo, hi = box[s]
            if lo < hi:
                c = centre[s]
                acc = acc + g(box) * Interval(_sum_down(lo, -c), _sum_up(hi, -c))
    except BoundsError:                     # a derivative unbounded on the box (sqrt at 0, ...)
        return natural
    lo, hi = max(natural.lo, acc.lo), min(natural.hi, acc.hi)
    return Interval(lo, hi) if lo <= hi else natural


# --- derivatives ---------------------------------------------------------------------------------

_JUMPS = (sp.sign, sp.Heaviside, sp.Piecewise, sp.DiracDelta, sp.floor, sp.ceiling, sp.frac)


class _RealAbs(sp.Function):
    """|u| of a real u: d|u|/du = sign(u) (sympy writes re/im forms when it cannot prove u real,
    as for (l r - v)/w, which is not real where w = 0)."""

    def fdiff(self, argindex=1):
        return sp.sign(self.args[0])


class _RealSign(sp.Function):
    """sign(u) of a real u: d sign(u)/du = 2 DiracDelta(u) (sympy leaves it unevaluated otherwise)."""

    def fdiff(self, argindex=1):
        return 2 * sp.DiracDelta(self.args[0])


def _indicator(cond, pw) -> sp.Expr:
    """1 where ``cond`` holds, else 0, as Heaviside steps (value at the switch as the condition's)."""
    if cond is sp.true:
        return sp.S.One
    if cond is sp.false:
        return sp.S.Zero
    if isinstance(cond, sp.core.relational.Relational) and cond.rel_op in ("<", "<=", ">", ">="):
        below, above = (cond.lhs, cond.rhs) if cond.rel_op in ("<", "<=") else (cond.rhs, cond.lhs)
        return sp.Heaviside(above - below, 1 if cond.rel_op in ("<=", ">=") else 0)
    if isinstance(cond, sp.And):
        return sp.Mul(*(_indicator(c, pw) for c in cond.args))
    if isinstance(cond, sp.Or):
        return 1 - sp.Mul(*(1 - _indicator(c, pw) for c in cond.args))
    if isinstance(cond, sp.Not):
        return 1 - _indicator(cond.args[0], pw)
    raise BoundsError(f"{pw}: the condition {cond} holds on a set without interior (or has no interval rule); its "
                      f"derivative is not bounded: write the switch with <, <=, >, >=")


def _piecewise_as_steps(pw: sp.Piecewise) -> sp.Expr:
    """A Piecewise as a sum of branches times Heaviside steps: differentiating it gives a Dirac term
    per switch whose weight is the jump there (0 for a continuous law), instead of sympy's branchwise
    derivative, which would hide a jump."""
    out, rest = sp.S.Zero, sp.S.One
    for branch, cond in pw.args:
        ind = _indicator(cond, pw)
        out += branch * ind * rest
        rest = rest * (1 - ind)
    return out


def _atan2_continuous(y, x) -> sp.Expr:
    # equal to atan2 off the cut (x <= 0, y = 0), singular on it: a box reaching the cut is refused
    return 2 * sp.atan(y / (sp.sqrt(x ** 2 + y ** 2) + x))


def derivative(expr: sp.Expr, symbol: sp.Symbol) -> sp.Expr:
    """d expr / d symbol, in a form :func:`evaluate` bounds soundly (see the module docstring).

    The free symbols are taken real (a box holds real numbers). A jump must show in the
    derivative, so ``Piecewise`` is differentiated as branches times Heaviside steps and
    ``atan2`` in a form that is singular on its cut. Each resulting Dirac term
    ``g DiracDelta(u)`` is dropped when g vanishes where u = 0 (u linear in one of its symbols)
    and does not switch there: the function does not jump (``t DiracDelta(t)`` from
    ``d/dt [t Heaviside(t)]``, ``F(|t|) DiracDelta(t)`` from ``d/dt [sign(t) F(|t|)]`` with
    F(0) = 0, the difference of two branches that meet). ``u sign(u)`` is written ``|u|``.

    Raises
    ------
    BoundsError
        when a Dirac term does not vanish or cannot be shown to: the function jumps (or may),
        and its derivative has no bound.
    """
    expr = sp.sympify(expr)
    real = {s: sp.Dummy(s.name, real=True) for s in expr.free_symbols if not s.is_real}
    back = {v: k for k, v in real.items()}
    work = (expr.replace(lambda e: isinstance(e, sp.Piecewise), _piecewise_as_steps)
                .replace(sp.atan2, _atan2_continuous)
                .replace(sp.Abs, _RealAbs).replace(sp.sign, _RealSign)
                .xreplace(real))
    d = sp.diff(work, real.get(symbol, symbol)).replace(_RealAbs, sp.Abs).replace(_RealSign, sp.sign)
    for delta in sorted(d.atoms(sp.DiracDelta), key=sp.default_sort_key):
        d = _drop_vanishing_dirac(d, delta, expr, symbol, back)
    for sg in d.atoms(sp.sign):
        d = d.subs(sg.args[0] * sg, sp.Abs(sg.args[0]))
    return d.xreplace(back)


def _linear_root(u: sp.Expr):
    """(s, root) with u = 0 exactly where s = root (u's numerator linear in s with a constant
    coefficient), or None."""
    num, _ = sp.fraction(sp.together(u))
    for s in sorted(u.free_symbols, key=str):
        k = sp.diff(num, s)
        if k.is_number and k != 0:
            return s, sp.expand(-(num - k * s) / k)
    return None


def _drop_vanishing_dirac(d: sp.Expr, delta, expr, symbol, back: dict) -> sp.Expr:
    def refuse(why: str):
        raise BoundsError(f"d({expr})/d{symbol} holds {delta.xreplace(back)} ({why}): the function jumps there "
                          f"(or cannot be shown not to), so its derivative has no bound; the mean-value theorem "
                          f"needs a continuous law")
    u = delta.args[0]
    if len(delta.args) > 1 and delta.args[1] != 0:
        refuse("a derivative of a Dirac")
    z = sp.Dummy("z")
    linear = d.xreplace({delta: z})
    weight = sp.diff(linear, z)
    if weight.has(z):
        refuse("not as a linear term")
    found = _linear_root(u)
    if found is None:
        refuse(f"its argument {u.xreplace(back)} is not linear in one of its symbols")
    s, root = found
    if any(j.has(*u.free_symbols) for j in weight.atoms(*_JUMPS)):
        refuse("with a weight that switches at the same place")
    at = weight.subs(s, root)
    if at != 0 and sp.simplify(at) != 0:
        refuse(f"with the weight {weight.xreplace(back)}, not 0 where {u.xreplace(back)} = 0")
    return linear.subs(z, 0)


# --- branch and bound ----------------------------------------------------------------------------

@dataclass(frozen=True)
class RangeBound:
    """Sound bounds [lower, upper] and the attained values proving their tightness.

    ``attained_min``/``attained_max`` are values the function takes at the points ``argmin`` /
    ``argmax`` of the box (((symbol name, value), ...); empty where the bound was not computed by
    :func:`range_bound`), evaluated in mpmath at 128 bits.
    """

    lower: float
    upper: float
    attained_min: float
    attained_max: float
    boxes_examined: int
    argmin: tuple = ()
    argmax: tuple = ()
    #: False where the refinement stopped before its tolerance (``enclose=True``): [lower, upper] is
    #: still a sound enclosure, only looser; :attr:`gap` says by how much at most
    converged: bool = True
    #: why it stopped short ("" when converged): the budget, or a piece doubles cannot split
    stopped: str = ""

    @property
    def constant(self) -> bool:
        return self.lower == self.upper

    @property
    def gap(self) -> float:
        """The largest distance of a bound from the attained values: how much looser than the true
        range the enclosure may be (0 where it is the attained range itself)."""
        return max(self.attained_min - self.lower, self.upper - self.attained_max, 0.0)

    def describe_gap(self) -> str:
        """'enclosure, gap G (...)' for a bound that did not converge; '' otherwise."""
        if self.converged:
            return ""
        return (f"sound enclosure [{self.lower:.6g}, {self.upper:.6g}], not tight: the values attained span "
                f"[{self.attained_min:.6g}, {self.attained_max:.6g}] (gap {self.gap:.3g}; {self.stopped})")


def _bisect(box: dict, scale: dict | None = None):
    """The two halves of ``box`` across its widest side, or None when no side can be split further:
    widest in absolute terms, or relative to ``scale`` (the root box's widths) when given, so that a
    variable in large units (a stiffness in N/rad beside a slip) does not take every cut."""
    sym = max(box, key=lambda s: (box[s][1] - box[s][0]) / (scale[s] if scale else 1.0))
    lo, hi = box[sym]
    mid = 0.5 * (lo + hi)
    if not lo < mid < hi:
        return None
    return {**box, sym: (lo, mid)}, {**box, sym: (mid, hi)}


def _point_function(expr: sp.Expr, used: list):
    """(value, rough): ``expr`` at a point in mpmath at 128 bits rounded to the nearest double (the
    attained values), and in double precision (+-inf where it fails) to guide the search."""
    fn = sp.lambdify(used, expr, "mpmath")
    fast = sp.lambdify(used, expr, "math")

    def value(point: tuple) -> float:
        with mpmath.workprec(_POINT_PREC):
            try:
                v = fn(*(mpmath.mpf(p) for p in point))
            except (ZeroDivisionError, ValueError) as exc:
                raise BoundsError(f"{expr} cannot be evaluated at {dict(zip(map(str, used), point))}: {exc}") from None
            if isinstance(v, mpmath.mpc) or not mpmath.isfinite(v):
                raise BoundsError(f"{expr} is not a finite real number at {dict(zip(map(str, used), point))}: {v}")
            return float(v)

    def rough(point) -> float:
        try:
            v = float(fast(*(float(p) for p in point)))
        except (ArithmeticError, ValueError, TypeError, NameError):
            return math.nan
        return v if math.isfinite(v) else math.nan
    return value, rough


def _nan_to_inf(v: float) -> float:
    return _INF if math.isnan(v) else v


def _local_search(rough, b: dict, used: list, start: tuple, sign: float) -> tuple:
    """A point of box ``b`` where sign * expr is small: a compass search from ``start`` (steps of a
    quarter of each side, halved when no step along any axis improves), in double precision. A better
    attained value closes the gap sooner where the extremes lie along a curve (a kink of |t|)."""
    sides = [b[s] for s in used]
    x = [min(max(float(v), lo), hi) for v, (lo, hi) in zip(start, sides)]
    fx = _nan_to_inf(sign * rough(x))
    steps = [0.25 * (hi - lo) for lo, hi in sides]
    for _ in range(_SEARCH_EVALUATIONS // (2 * len(sides))):
        moved = False
        for j, (lo, hi) in enumerate(sides):
            for direction in (1.0, -1.0):
                y = list(x)
                y[j] = min(max(x[j] + direction * steps[j], lo), hi)
                fy = _nan_to_inf(sign * rough(y))
                if fy < fx:
                    x, fx, moved = y, fy, True
                    break
        if not moved:
            steps = [0.5 * h for h in steps]
            if all(x[j] + h == x[j] for j, h in enumerate(steps)):
                break
    return tuple(x)


def range_bound(expr: sp.Expr, box: dict, rel_tol: float = 1e-3, max_boxes: int = 20000,
                relative_cuts: bool = False, enclose: bool = False) -> RangeBound:
    """Guaranteed [lower, upper] of ``expr`` over ``box``, within ``rel_tol`` of attained values.

    ``relative_cuts``: bisect the side widest relative to the root box (variables of very different
    units); default: the widest in absolute terms.

    ``enclose``: where the refinement stops before its tolerance (the budget ``max_boxes`` spent, or
    a piece doubles cannot split), return the sound enclosure it has reached instead of refusing:
    the smallest lower bound over the box pieces still in the heap (they cover the box), never an
    attained value. The result then has ``converged`` False, and its ``gap`` and ``stopped`` say how
    loose it may be and why. For a use where a looser bound is only more conservative (a DMVT
    vertex set, a premise range), that is a larger polytope, not a wrong one.

    The bounds hold for the exact real function (:func:`evaluate`); ``attained_min`` and
    ``attained_max`` are values it takes at points of the box, so they lie inside the bounds.

    Raises
    ------
    BoundsError
        if the expression cannot be enclosed (or only by an infinite bound), or, without
        ``enclose``, the refinement budget runs out (or a box piece can no longer be split) before
        the bounds are within tolerance (the message gives the gap reached).
    """
    expr = sp.sympify(expr)
    stray = expr.free_symbols - set(box)
    if stray:
        raise BoundsError(f"{expr} depends on {', '.join(sorted(map(str, stray)))}, which has no range")
    used = sorted(expr.free_symbols, key=str)
    sub = {s: (float(box[s][0]), float(box[s][1])) for s in used}
    for s, (lo, hi) in sub.items():
        if not lo <= hi:
            raise BoundsError(f"the range of {s} is empty: [{lo}, {hi}]")
    switches = _switches(expr)
    whole = _enclose(expr, sub, switches)
    value, rough = _point_function(expr, used)
    widths = {s: (sub[s][1] - sub[s][0]) or 1.0 for s in used} if relative_cuts else None

    def mid(b):
        return tuple(0.5 * (b[s][0] + b[s][1]) for s in used)

    points = [mid(sub)] + [tuple(sub[s][(bits >> k) & 1] for k, s in enumerate(used)) for bits in range(2 ** len(used))]
    seen = [(value(p), p) for p in points]
    low, high = min(seen), max(seen)
    examined = 1

    def consider(p: tuple) -> None:
        """Take the value at p into the attained ones (in mpmath) when its double-precision value
        looks better than one of them, or cannot be computed in doubles."""
        nonlocal low, high
        r = rough(p)
        if math.isnan(r) or r < low[0] + _GUIDE * abs(low[0]) or r > high[0] - _GUIDE * abs(high[0]):
            v = value(p)
            low, high = min(low, (v, p)), max(high, (v, p))

    stopped = []                            # why a side stopped short of its tolerance (enclose=True)

    def short(lb: float, why: str) -> float:
        """The enclosure reached, lb: the least lower bound of sign * expr over the heap's pieces,
        which cover the box (sound whatever the tolerance); refused only where it is not finite."""
        if not math.isfinite(lb):
            raise BoundsError(f"bounding {expr}: no finite enclosure over the box ({why})")
        stopped.append(why)
        return lb

    def refine(sign: float) -> float:
        # minimize sign * expr: a heap of (lower bound of sign * expr, tiebreak, box piece, tightened), the
        # lower bound first from the natural form; a piece that reaches the top is tightened once by its
        # mean-value form (dearer: only the pieces that matter pay for it), then split
        nonlocal examined
        lb = whole.lo if sign > 0 else -whole.hi
        heap, count, pops = [(lb, 0, sub, False)], 1, 0
        misses, wait = 0, 0                 # the mean-value form is skipped for a while after it stops helping
        while True:
            lb, _, b, tightened = heap[0]
            best = min(sign * low[0], sign * high[0])
            scale = max(abs(low[0]), abs(high[0]), 1e-300)
            if best - lb <= rel_tol * scale:
                return lb
            if pops & (pops - 1) == 0:             # after 0, 1, 2, 4, 8, ... pieces: a better attained value
                start = (low if sign > 0 else high)[1] if pops == 0 else mid(b)
                consider(_local_search(rough, sub if pops == 0 else b, used, start, sign))
                pops += 1
                continue
            if not tightened and wait == 0:
                iv = _enclose(expr, b, switches, tuple(used))
                tighter = max(lb, iv.lo if sign > 0 else -iv.hi)
                misses = 0 if tighter - lb > 0.25 * (best - lb) else misses + 1
                wait = min(2 ** misses - 1, 64)
                heapq.heapreplace(heap, (tighter, count, b, True))
                count += 1
                continue
            wait = max(0, wait - 1) if not tightened else wait
            pops += 1
            halves = _bisect(b, widths)
            if halves is None:
                if enclose:
                    return short(lb, f"a box piece doubles cannot split at {dict(zip(map(str, used), mid(b)))}")
                raise BoundsError(f"bounding {expr}: gap {best - lb:.3g} (tolerance {rel_tol * scale:.3g}) on a box "
                                  f"piece doubles cannot split, {dict(zip(map(str, used), mid(b)))}: the gap is "
                                  f"rounding of the expression there; loosen the bounds' tolerance")
            if examined >= max_boxes:
                if enclose:
                    return short(lb, f"branch and bound stopped after {examined} boxes, tolerance "
                                     f"{rel_tol * scale:.3g}")
                raise BoundsError(f"bounding {expr}: gap {best - lb:.3g} after {examined} boxes "
                                  f"(tolerance {rel_tol * scale:.3g}); loosen the bounds' tolerance or "
                                  f"split the box")
            heapq.heappop(heap)
            for half in halves:
                examined += 1
                consider(mid(half))
                iv = _enclose(expr, half, switches)
                heapq.heappush(heap, (iv.lo if sign > 0 else -iv.hi, count, half, False))
                count += 1

    if not used:
        return RangeBound(whole.lo, whole.hi, low[0], high[0], 0)
    lower = refine(1.0)
    upper = -refine(-1.0)
    names = [str(s) for s in used]
    return RangeBound(lower, upper, low[0], high[0], examined, tuple(zip(names, low[1])), tuple(zip(names, high[1])),
                      converged=not stopped, stopped="; ".join(dict.fromkeys(stopped)))
