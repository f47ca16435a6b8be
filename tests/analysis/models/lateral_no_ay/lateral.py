"""Single-track lateral dynamics with an unknown lateral disturbance force F (the tutorial's model)
with the yaw rate as the only sensor: the accelerometer a_y is missing."""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal

v_y, r, delta, F = sp.symbols("v_y r delta F")
v_x = sp.Symbol("v_x", positive=True)
M, I_z, l_f, l_r, C_f, C_r = sp.symbols("M I_z l_f l_r C_f C_r", positive=True)
F_yf = C_f * (delta - (v_y + l_f * r) / v_x)
F_yr = C_r * (l_r * r - v_y) / v_x
MODEL = ModelDefinition(
    name="lateral_no_ay", states=(v_y, r), known_inputs=(delta,), unknown_inputs=(F,),
    dynamics=sp.Matrix([(F_yf + F_yr + F) / M - v_x * r, (l_f * F_yf - l_r * F_yr) / I_z]),
    outputs=(("r", r),),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(M, I_z, l_f, l_r, C_f, C_r),
    units={"v_y": "m/s", "r": "rad/s", "delta": "rad", "F": "N", "v_x": "m/s"})
