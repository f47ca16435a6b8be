"""The committed decay rates: numbers of a few significant digits, and the search for the largest one
a family's feasibility test holds at.

A design commits the largest decay rate its LMIs certify, rounded down in decimal arithmetic to a few
significant digits (the same number on every machine, written into the design lock). Such a rate is one
of finitely many numbers, so the search asks about those numbers only: a binary search over them gives
what a bisection of the real rate would round to, in about half the solves (a feasibility answer is
monotone: a common Lyapunov matrix that proves a decay rate proves every smaller one).
"""
from __future__ import annotations

import decimal
import math

__all__ = ["round_down", "committable_rates", "largest_holding"]


def round_down(x: float, digits: int) -> float:
    """``x`` rounded down to ``digits`` significant digits, in decimal arithmetic (the same on every
    machine); 0 for x <= 0."""
    if x <= 0:
        return 0.0
    d = decimal.Decimal(repr(float(x)))
    quantum = decimal.Decimal(1).scaleb(d.adjusted() - digits + 1)
    return float((d / quantum).to_integral_value(rounding=decimal.ROUND_FLOOR) * quantum)


def committable_rates(top: float, digits: int, resolution: float) -> list:
    """Every rate of ``digits`` significant digits (:func:`round_down`'s values) in [resolution top, top],
    ascending: what a design can commit below the ceiling ``top``, down to a bisection's resolution."""
    if top <= 0:
        return []
    low = resolution * top
    first, last = 10 ** (digits - 1), 10 ** digits
    out = []
    for exponent in range(math.floor(math.log10(low)) - digits + 1, math.floor(math.log10(top)) + 1):
        for mantissa in range(first, last):
            q = float(decimal.Decimal(mantissa).scaleb(exponent))
            if low <= q <= top:
                out.append(q)
    return out


def largest_holding(candidates: list, holds, near_top: bool = True) -> float | None:
    """The largest of the ascending ``candidates`` for which ``holds`` (true up to some point, false
    above it), or None.

    ``near_top``: the answer is expected close below the top (a ceiling from a dense grid): the search
    asks the top and the one below it (one or two solves where the ceiling is close), then steps down in
    growing steps and halves between the last that failed and the first that held; after two that fail it
    asks the smallest, so that where none holds three questions say so. Otherwise a plain binary search
    (about log2 of the count)."""
    lo, hi, step, failed = -1, len(candidates), 1, 0    # candidates[hi:] fail; candidates[lo] holds (-1: none known)
    while near_top and hi > 0 and lo < 0:
        i = max(hi - step, 0)
        if holds(candidates[i]):
            lo = i
            break
        hi, failed = i, failed + 1
        step = 1 if failed == 1 else 2 * step
        if failed == 2 and hi > 0:
            if not holds(candidates[0]):
                return None
            lo = 0
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if holds(candidates[mid]) else (lo, mid)
    return candidates[lo] if lo >= 0 else None
