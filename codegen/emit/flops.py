"""The floating-point operation count of a CasADi step: the floor every cost figure is set
against (``uiogen bench``, the Cortex-M4F cycle count of :mod:`codegen.tools.m4cycles`, a family's
own bench figures)."""
from __future__ import annotations

import casadi as ca

ARITHMETIC_OPS = ("OP_ADD", "OP_SUB", "OP_MUL", "OP_DIV", "OP_NEG", "OP_SQ", "OP_SQRT", "OP_FMIN",
                  "OP_FMAX", "OP_FABS", "OP_EXP", "OP_LOG", "OP_POW", "OP_CONSTPOW", "OP_INV",
                  "OP_TWICE", "OP_FMOD", "OP_ATAN2", "OP_SIN", "OP_COS", "OP_TAN")


def flop_count(f: ca.Function) -> dict:
    """Floating-point operations of a CasADi SX Function, by kind."""
    codes = {getattr(ca, n): n for n in ARITHMETIC_OPS if hasattr(ca, n)}
    counts: dict = {}
    for k in range(f.n_instructions()):
        name = codes.get(f.instruction_id(k))
        if name:
            counts[name] = counts.get(name, 0) + 1
    counts["total"] = sum(counts.values())
    return counts
