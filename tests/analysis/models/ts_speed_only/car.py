"""Longitudinal-lateral single-track model (Nguyen et al. 2021, eq. (1) with linear tyres) with
the speed as the only sensor: v_x measured, v_y and r not; engine torque and steering angle unknown."""
import sympy as sp

from codegen.model import ModelDefinition

v_y, r = sp.symbols("v_y r")
v_x = sp.Symbol("v_x", positive=True)
T_eng, delta = sp.symbols("T_eng delta")
M, l_f, l_r, I_e, I_z, C_f, C_r = sp.symbols("M l_f l_r I_e I_z C_f C_r", positive=True)
F_yf = 2 * C_f * (delta - (v_y + l_f * r) / v_x)
F_yr = 2 * C_r * (l_r * r - v_y) / v_x
MODEL = ModelDefinition(
    name="speed_only", states=(v_x, v_y, r), known_inputs=(), unknown_inputs=(T_eng, delta),
    dynamics=sp.Matrix([T_eng / I_e + v_y * r, (F_yf + F_yr) / M - v_x * r, (l_f * F_yf - l_r * F_yr) / I_z]),
    outputs=(("v_x", v_x),), scheduling=(),
    parameters=(M, l_f, l_r, I_e, I_z, C_f, C_r),
    units={"v_x": "m/s", "v_y": "m/s", "r": "rad/s", "T_eng": "N m", "delta": "rad"})
