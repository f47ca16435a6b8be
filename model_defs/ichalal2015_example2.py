"""Ichalal and Mammar (IEEE T-IE 62(9), 2015), Example 2: eq. (40) with D = [0, 1 + rho]'.

    x' = [[0, 1 + rho], [-rho, -2]] x + [0, 1 + rho]' d,   y = [1 0] x,   rho in [1, 5].

C D = 0, so the classical rank condition fails; the output has relative degree 2
(M_1 D = (1 + rho)^2), and observer (59) needs y'' and rho' (HOSMD differentiators).
"""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal

x1, x2, d = sp.symbols("x1 x2 d")
rho = sp.Symbol("rho", positive=True)

MODEL = ModelDefinition(
    name="ichalal2015_example2",
    states=(x1, x2),
    known_inputs=(),
    unknown_inputs=(d,),
    dynamics=sp.Matrix([(1 + rho) * x2, -rho * x1 - 2 * x2 + (1 + rho) * d]),
    outputs=(("x1", x1),),
    scheduling=(SchedulingSignal(rho, "-"),),
    parameters=(),
    # an academic example in normalized time: its states declare no unit (x' = -2 x2 would make x2 a
    # rate if x1, x2 were dimensionless in seconds), so no equation is checked against one
    units={"d": "-", "rho": "-"},
    doc=__doc__,
)
