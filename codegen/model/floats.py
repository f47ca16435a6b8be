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
        # every Min and Max held as one symbol while the expression is expanded and grouped: sympy rebuilds
        # them on every construction with a search for equal arguments (factor_terms over each pair), tens of
        # seconds on a tyre law; their arguments are not expanded into the sum, so nothing is lost. One that
        # reads a signal counts as a signal.
        held = {f: sp.Dummy(f"m{k}") for k, f in enumerate(sorted(e.atoms(sp.Min, sp.Max), key=sp.default_sort_key))}
        back = {d: f for f, d in held.items()}
        flat = e.xreplace(held)
        factors = signals + tuple(d for f, d in held.items() if f.free_symbols & set(signals))
        expanded = sp.expand(flat)
        n_terms = sum(len(sp.Add.make_args(sp.expand(t))) for t in sp.Add.make_args(flat))
        groups: dict = {}                 # {the term's factor in the signals: the sum of its coefficients}
        for t in sp.Add.make_args(expanded):
            c, m = t.as_independent(*factors, as_Add=False) if factors else (t, sp.S.One)
            groups[m] = groups.get(m, sp.S.Zero) + c
        keep = {m: c for m, c in groups.items() if not _is_zero(c.xreplace(back))}
        if len(keep) < len(groups) or len(sp.Add.make_args(expanded)) < n_terms:
            e = sp.Add(*(m * c for m, c in keep.items())).xreplace(back)
        out.append(e)
    return out
