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
