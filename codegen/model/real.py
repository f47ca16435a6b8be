"""Every signal and parameter of a vehicle model is real.

sympy's symbols are complex unless declared ``real=True``: ``sp.Abs`` of an expression whose sign sympy
cannot decide (a capacity ``sqrt(Max(...))`` over a load that moves with ``a_x``, say) then evaluates to
``sqrt(x*conjugate(x))``, and ``re``/``im`` can appear the same way. No stage evaluates those (there is no
``conjugate`` in C), and for real values they are exact identities: ``conjugate(x) = x``, ``re(x) = x``,
``im(x) = 0``. The model's expressions are read with them applied, so a user need not declare every
symbol real.
"""
from __future__ import annotations

import sympy as sp

__all__ = ["real_valued"]


def real_valued(expr):
    """``expr`` with conjugate(x) -> x, re(x) -> x and im(x) -> 0 (exact for real values); ``expr``
    itself when none of them occurs (so a model without them keeps its expressions object for object)."""
    if not isinstance(expr, sp.Basic) or not expr.has(sp.conjugate, sp.re, sp.im):
        return expr
    return expr.replace(sp.conjugate, lambda x: x).replace(sp.re, lambda x: x).replace(sp.im, lambda x: sp.S.Zero)
