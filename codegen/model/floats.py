"""Numbers of a model's equations that differ only by rounding (:func:`merge_float_noise`)."""
from __future__ import annotations

import sympy as sp


FLOAT_NOISE = 1e-12
"""Relative difference below which two numbers of a model's equations are one number (:func:`merge_float_noise`).

``sp.solve`` on equations written with floats returns coefficients computed in a different order in
each row (0.3 in one, 0.30000000000000004 in the next): a few rounding steps of 2^-53 (1.1e-16) each,
so a few ulps; 1e-12 is several thousand ulps above that noise and six orders below any difference a
parameter written with up to ten significant digits can make."""


def merge_float_noise(exprs) -> list:
    """``exprs`` with every two floats that differ by at most :data:`FLOAT_NOISE` (relative) made the
    same float, the smallest of its cluster (each cluster spans at most FLOAT_NOISE, measured from
    its first float): the same tyre law written twice by ``sp.solve`` with coefficients that differ
    in the last digit is then one nonlinearity, one premise, one unmeasured consequent, not two."""
    exprs = [sp.sympify(e) for e in exprs]
    floats = sorted({f for e in exprs for f in e.atoms(sp.Float)}, key=float)
    merge, anchor = {}, None
    for f in floats:
        a, b = float(f), None if anchor is None else float(anchor)
        if b is not None and abs(a - b) <= FLOAT_NOISE * max(abs(a), abs(b)):
            merge[f] = anchor
        else:
            anchor = f
    return [e.xreplace(merge) for e in exprs] if merge else exprs


def _is_zero(c) -> bool:
    """Whether ``c`` is 0 once simplified; a number away from 0 at one point of its free symbols (each
    set to a fixed value in [0.6, 1.4]) decides "not zero" without simplifying."""
    if c == 0:
        return True
    point = {s: sp.Float(0.6 + 0.8 * ((7 * k + 3) % 11) / 10) for k, s in enumerate(sorted(c.free_symbols, key=str))}
    try:
        value = complex(c.xreplace(point).evalf())
        if abs(value) > 1e-9:
            return False
    except (TypeError, ValueError, ZeroDivisionError):
        pass
    return sp.simplify(c) == 0


def drop_zero_terms(exprs, signals) -> list:
    """``exprs`` without their terms that are 0: the coefficient of a product of ``signals`` that
    simplifies to 0 ((sin(th)^2 + cos(th)^2 - 1) k x), and terms that cancel once expanded ((a + b) x
    - a x - b x): decided exactly, with the parameters still symbols (substituted first, they leave a
    float residue of 1e-16, a term the design would carry: a coupling, a premise, a constant input).
    An expression with no such term is returned as it is (its form, so every design from it, unchanged)."""
    signals = tuple(signals)
    out = []
    for e in exprs:
        e = sp.sympify(e)
        expanded = sp.expand(e)
        n_terms = sum(len(sp.Add.make_args(sp.expand(t))) for t in sp.Add.make_args(e))
        groups: dict = {}                 # {the term's factor in the signals: the sum of its coefficients}
        for t in sp.Add.make_args(expanded):
            c, m = t.as_independent(*signals, as_Add=False) if signals else (t, sp.S.One)
            groups[m] = groups.get(m, sp.S.Zero) + c
        keep = {m: c for m, c in groups.items() if not _is_zero(c)}
        if len(keep) < len(groups) or len(sp.Add.make_args(expanded)) < n_terms:
            e = sp.Add(*(m * c for m, c in keep.items()))
        out.append(e)
    return out
