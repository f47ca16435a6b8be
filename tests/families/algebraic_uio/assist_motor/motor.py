"""A user's electric assist motor (the stiff case of test_left_inverse.py): shaft angle th and
current i measured, a load torque T_d unknown. Two outputs, one unknown input: Gamma is 2 x 1, and
the electric pole -R/L (-500 1/s at L = 0.2 mH) sits beside the mechanical chain."""
import sympy as sp

from codegen.model import ModelDefinition

th, w, i, u, T_d = sp.symbols("th w i u T_d")
J, c, k_t, k_e, R, L = sp.symbols("J c k_t k_e R L", positive=True)
MODEL = ModelDefinition(
    name="assist_motor", states=(th, w, i), known_inputs=(u,), unknown_inputs=(T_d,),
    dynamics=sp.Matrix([w, (k_t * i + T_d - c * w) / J, (u - R * i - k_e * w) / L]),
    outputs=(("th", th), ("i", i)), scheduling=(), parameters=(J, c, k_t, k_e, R, L),
    units={"th": "rad", "w": "rad/s", "i": "A", "u": "V", "T_d": "N m", "J": "kg m^2", "c": "N m s/rad",
           "k_t": "N m/A", "k_e": "V s/rad", "R": "Ohm", "L": "H"})
