"""Lateral + roll model on a banked road: v_y, r, roll angle phi; road bank phi_r unknown."""
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal

v_y, r, phi, delta, phi_r = sp.symbols("v_y r phi delta phi_r")
v_x = sp.Symbol("v_x", positive=True)
M, I_z, l_f, l_r, C_f, C_r, g, h_cg, K_phi, tau_phi = sp.symbols(
    "M I_z l_f l_r C_f C_r g h_cg K_phi tau_phi", positive=True)
F_yf = C_f * (delta - (v_y + l_f * r) / v_x)
F_yr = C_r * (l_r * r - v_y) / v_x
a_y = (F_yf + F_yr) / M                      # what the accelerometer measures
MODEL = ModelDefinition(
    name="roll_bank", states=(v_y, r, phi), known_inputs=(delta,), unknown_inputs=(phi_r,),
    dynamics=sp.Matrix([a_y - v_x * r + g * sp.sin(phi_r),
                        (l_f * F_yf - l_r * F_yr) / I_z,
                        (K_phi * h_cg * a_y / g - phi) / tau_phi]),
    outputs=(("r", r), ("a_y", a_y), ("phi", phi)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(M, I_z, l_f, l_r, C_f, C_r, g, h_cg, K_phi, tau_phi),
    units={"v_y": "m/s", "r": "rad/s", "phi": "rad", "delta": "rad", "phi_r": "rad", "a_y": "m/s^2",
           "v_x": "m/s", "M": "kg", "I_z": "kg m^2", "l_f": "m", "l_r": "m", "C_f": "N/rad", "C_r": "N/rad",
           "g": "m/s^2", "h_cg": "m", "K_phi": "rad/m", "tau_phi": "s"})
