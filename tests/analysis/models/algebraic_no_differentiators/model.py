"""Ichalal and Mammar 2015, Example 2 (eq. (40) with D = [0, 1 + rho]'): relative degree 2."""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal

x1, x2, d = sp.symbols("x1 x2 d")
rho = sp.Symbol("rho", positive=True)
MODEL = ModelDefinition(
    name="relative_degree_two", states=(x1, x2), known_inputs=(), unknown_inputs=(d,),
    dynamics=sp.Matrix([(1 + rho) * x2, -rho * x1 - 2 * x2 + (1 + rho) * d]),
    outputs=(("x1", x1),), scheduling=(SchedulingSignal(rho, "-"),), parameters=(),
    units={"d": "-", "rho": "-"})     # normalized time: the states declare no unit
