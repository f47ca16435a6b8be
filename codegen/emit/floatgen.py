"""CasADi's kernel in ``float``: the kernel's code generated with ``casadi_real`` = float and
fixed up so that nothing in it is computed in double (:func:`casadi_float_sources`).

Kept apart from :mod:`codegen.emit.toolchain` (which designs import): the float variant changes no
design and no committed byte of the double C.
"""
from __future__ import annotations

import re
import tempfile
from pathlib import Path

import casadi as ca

from .toolchain import CASADI_OPTIONS, _fix_float_conditions, _fix_unused_parameters

# libm functions CasADi's kernels call; their float versions (C99 <math.h>) carry an f.
FLOAT_MATH = ("sqrt", "exp", "log", "sin", "cos", "tan", "asin", "acos", "atan2", "atan", "sinh", "cosh", "tanh",
              "fabs", "floor", "ceil", "fmin", "fmax", "pow")
_FLOAT_LITERAL = re.compile(r"(?<![\w.])((?:\d+\.\d*|\.\d+)(?:e[+-]?\d+)?|\d+e[+-]?\d+)(?![\w.])")
_FLOAT_CALL = re.compile(r"\b(" + "|".join(FLOAT_MATH) + r")\(")


def fix_float_kernel(code: str) -> str:
    """CasADi's kernel with ``casadi_real`` = float still writes double literals and calls the
    double libm functions: a float suffix on every floating literal (rounded once, decimal to
    float, by the compiler) and the float functions (sqrtf, expf, ...), so that nothing is
    computed in double (-Wdouble-promotion refuses it; a Cortex-M4F has no double unit)."""
    lines = []
    for line in code.split("\n"):
        if not line.lstrip().startswith(("#", "/*", "*")):
            line = _FLOAT_CALL.sub(r"\1f(", _FLOAT_LITERAL.sub(r"\1f", line))
        lines.append(line)
    return "\n".join(lines)


def casadi_float_sources(f: ca.Function) -> tuple:
    """(C, header) of CasADi's float code for ``f``, fixed up for the project's strict flags."""
    kernel = f.name()
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{kernel}.c", {**CASADI_OPTIONS, "casadi_real": "float"})
        cg.add(f)
        cg.generate(tmp + "/")
        c_code = Path(tmp, f"{kernel}.c").read_text()
        h_code = Path(tmp, f"{kernel}.h").read_text()
    return fix_float_kernel(_fix_float_conditions(_fix_unused_parameters(c_code, kernel))), h_code
