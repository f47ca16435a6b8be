"""Sound bounds of symbolic functions over a box: interval arithmetic with subdivision.

Used for the differential mean-value theorem (Nguyen et al. 2021, Assumption 1): the Jacobian entries of
an unmeasured nonlinearity phi(x) are bounded over the compact state set D_x. The bounds are
*guaranteed*: every operation is evaluated in interval arithmetic with outward rounding
(``math.nextafter`` after each floating-point operation), so the true range is always inside.
They are made *tight* by branch and bound: the box piece holding the current worst bound is
bisected along its widest side until that bound is within ``rel_tol`` of a value the function
actually takes (evaluated at a point), which proves the bound is both sound and near-exact.
"""
from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import sympy as sp

from ..errors import BoundsError

_INF = math.inf


def _down(x: float) -> float:
    return math.nextafter(x, -_INF)


def _up(x: float) -> float:
    return math.nextafter(x, _INF)


@dataclass(frozen=True)
class Interval:
    """Closed interval [lo, hi] with outward-rounded arithmetic."""

    lo: float
    hi: float

    def __add__(self, other: "Interval") -> "Interval":
        return Interval(_down(self.lo + other.lo), _up(self.hi + other.hi))

    def __neg__(self) -> "Interval":
        return Interval(-self.hi, -self.lo)

    def __mul__(self, other: "Interval") -> "Interval":
        p = [self.lo * other.lo, self.lo * other.hi, self.hi * other.lo, self.hi * other.hi]
        return Interval(_down(min(p)), _up(max(p)))

    def contains_zero(self) -> bool:
        return self.lo <= 0.0 <= self.hi

    def reciprocal(self) -> "Interval":
        if self.contains_zero():
            raise BoundsError(f"division by an interval containing 0: [{self.lo}, {self.hi}]")
        return Interval(_down(1.0 / self.hi), _up(1.0 / self.lo))

    def power(self, n: int) -> "Interval":
        if n == 0:
            return Interval(1.0, 1.0)
        if n < 0:
            return self.power(-n).reciprocal()
        lo, hi = self.lo, self.hi
        a, b = abs(lo) ** n, abs(hi) ** n
        if n % 2 == 1:
            return Interval(_down(math.copysign(a, lo)), _up(math.copysign(b, hi)))
        low = 0.0 if self.contains_zero() else min(a, b)
        return Interval(_down(low), _up(max(a, b)))

    def monotone(self, fn, increasing: bool = True) -> "Interval":
        a, b = fn(self.lo), fn(self.hi)
        return Interval(_down(a), _up(b)) if increasing else Interval(_down(b), _up(a))


def _sin_cos(iv: Interval, phase: float) -> Interval:
    """Range of sin(x + phase) over iv, with the extremes at interior critical points."""
    if iv.hi - iv.lo >= 2 * math.pi:
        return Interval(-1.0, 1.0)
    lo_v, hi_v = math.sin(iv.lo + phase), math.sin(iv.hi + phase)
    lo, hi = min(lo_v, hi_v), max(lo_v, hi_v)
    # maxima of sin at pi/2 + 2k pi, minima at -pi/2 + 2k pi
    k = math.ceil((iv.lo + phase - math.pi / 2) / (2 * math.pi))
    if math.pi / 2 + 2 * k * math.pi <= iv.hi + phase:
        hi = 1.0
    k = math.ceil((iv.lo + phase + math.pi / 2) / (2 * math.pi))
    if -math.pi / 2 + 2 * k * math.pi <= iv.hi + phase:
        lo = -1.0
    return Interval(max(-1.0, _down(lo)), min(1.0, _up(hi)))


def evaluate(expr: sp.Expr, box: dict) -> Interval:
    """Interval enclosure of ``expr`` for symbol values in ``box`` ({symbol: (lo, hi)})."""
    if expr.is_Number:
        v = float(expr)
        return Interval(_down(v), _up(v)) if not float(v).is_integer() else Interval(v, v)
    if expr.is_Symbol:
        if expr not in box:
            raise BoundsError(f"symbol {expr} has no range in the box")
        lo, hi = box[expr]
        return Interval(float(lo), float(hi))
    args = expr.args
    if expr.is_Add:
        out = evaluate(args[0], box)
        for a in args[1:]:
            out = out + evaluate(a, box)
        return out
    if expr.is_Mul:
        out = evaluate(args[0], box)
        for a in args[1:]:
            out = out * evaluate(a, box)
        return out
    if expr.is_Pow:
        base, exp = args
        b = evaluate(base, box)
        if exp.is_Integer:
            return b.power(int(exp))
        if exp.is_Rational or exp.is_Float:
            e = float(exp)
            if b.lo < 0 or (e < 0 and b.lo <= 0):
                raise BoundsError(f"{expr}: base range [{b.lo}, {b.hi}] is not positive")
            return b.monotone(lambda t: t ** e, increasing=e > 0)
        raise BoundsError(f"{expr}: only constant exponents are supported")
    fn = expr.func
    if fn in (sp.Max, sp.Min):
        # both monotone in every argument: the extreme of the ends (exact, no rounding)
        ivs = [evaluate(a, box) for a in args]
        pick = max if fn is sp.Max else min
        return Interval(pick(iv.lo for iv in ivs), pick(iv.hi for iv in ivs))
    if len(args) == 1:
        a = evaluate(args[0], box)
        if fn is sp.sin:
            return _sin_cos(a, 0.0)
        if fn is sp.cos:
            return _sin_cos(a, math.pi / 2)
        if fn is sp.atan:
            return a.monotone(math.atan)
        if fn is sp.tanh:
            return a.monotone(math.tanh)
        if fn is sp.exp:
            return a.monotone(math.exp)
        if fn is sp.log:
            if a.lo <= 0:
                raise BoundsError(f"{expr}: log of a range reaching {a.lo}")
            return a.monotone(math.log)
        if fn is sp.Abs:
            if a.contains_zero():
                return Interval(0.0, max(-a.lo, a.hi))
            return Interval(min(abs(a.lo), abs(a.hi)), max(abs(a.lo), abs(a.hi)))
    raise BoundsError(f"no interval rule for {fn.__name__} in {expr}")


@dataclass(frozen=True)
class RangeBound:
    """Sound bounds [lower, upper] and the attained values proving their tightness."""

    lower: float
    upper: float
    attained_min: float
    attained_max: float
    boxes_examined: int

    @property
    def constant(self) -> bool:
        return self.lower == self.upper


def _bisect(box: dict, scale: dict | None = None) -> tuple:
    """The box halved along its widest side: absolute width, or relative to ``scale`` (the root box's
    widths) when given, so that a variable in large units (a stiffness in N/rad beside a slip) does
    not take every cut."""
    sym = max(box, key=lambda s: (box[s][1] - box[s][0]) / (scale[s] if scale else 1.0))
    lo, hi = box[sym]
    mid = 0.5 * (lo + hi)
    return {**box, sym: (lo, mid)}, {**box, sym: (mid, hi)}


def range_bound(expr: sp.Expr, box: dict, rel_tol: float = 1e-3, max_boxes: int = 20000,
                relative_cuts: bool = False) -> RangeBound:
    """Guaranteed [lower, upper] of ``expr`` over ``box``, within ``rel_tol`` of attained values.

    ``relative_cuts``: bisect the side widest relative to the root box (variables of very
    different units); default: the widest in absolute terms.

    Raises
    ------
    BoundsError
        if the expression cannot be enclosed, or the refinement budget runs out before the
        bounds are within tolerance (the message gives the gap reached).
    """
    expr = sp.sympify(expr)
    stray = expr.free_symbols - set(box)
    if stray:
        raise BoundsError(f"{expr} depends on {', '.join(sorted(map(str, stray)))}, which has no range")
    used = sorted(expr.free_symbols, key=str)
    if not used:
        v = float(expr)
        return RangeBound(v, v, v, v, 0)
    fn = sp.lambdify(used, expr, "math")
    sub = {s: box[s] for s in used}

    def point(b):
        return float(fn(*[0.5 * (b[s][0] + b[s][1]) for s in used]))

    def corners_and_mid(b):
        vals = [point(b)]
        for bits in range(2 ** len(used)):
            vals.append(float(fn(*[b[s][(bits >> k) & 1] for k, s in enumerate(used)])))
        return vals

    widths = {s: (sub[s][1] - sub[s][0]) or 1.0 for s in used} if relative_cuts else None
    vals = corners_and_mid(sub)
    att_min, att_max = min(vals), max(vals)
    examined = 1

    def refine(sign: float) -> float:
        # minimize sign * expr: heap of (enclosure lower bound of sign*expr, tiebreak, box)
        nonlocal att_min, att_max, examined
        best = min(sign * v for v in (att_min, att_max))
        iv = evaluate(expr, sub)
        lb = iv.lo if sign > 0 else -iv.hi
        heap, count = [(lb, 0, sub)], 1
        while True:
            lb, _, b = heap[0]
            scale = max(abs(att_min), abs(att_max), 1e-300)
            if best - lb <= rel_tol * scale:
                return lb
            if examined >= max_boxes:
                raise BoundsError(f"bounding {expr}: gap {best - lb:.3g} after {examined} boxes "
                                  f"(tolerance {rel_tol * scale:.3g}); widen rel_tol or split the box")
            heapq.heappop(heap)
            for half in _bisect(b, widths):
                examined += 1
                v = point(half)
                att_min, att_max = min(att_min, v), max(att_max, v)
                best = min(best, sign * v)
                iv = evaluate(expr, half)
                heapq.heappush(heap, (iv.lo if sign > 0 else -iv.hi, count, half))
                count += 1

    lower = refine(1.0)
    upper = -refine(-1.0)
    return RangeBound(lower, upper, att_min, att_max, examined)
