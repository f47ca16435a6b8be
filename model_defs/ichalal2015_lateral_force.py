"""Ichalal and Mammar (IEEE T-IE 62(9), 2015), Example 3: rear lateral force, eqs. (76)-(81).

Observer model (78)/(81): the bicycle model (76) with the front force eliminated through the
measured lateral acceleration a_y = (F_yf + F_yr)/M, and the rear force's relaxation dynamics
sigma_r/v_x F_yr' + F_yr = F_yr^S (the paper writes tau_r for the relaxation *length*: its A has
-v_x/tau_r):

    v_y'  = a_y - v_x r
    r'    = (l_f M / I_z) a_y - (l / I_z) F_yr,                       l = l_f + l_r
    F_yr' = (v_x / sigma_r) (c_r alpha_r - F_yr + xi),  alpha_r = (l_r r - v_y) / v_x

x = (v_y, r, F_yr), known input u = a_y, unknown input xi = F_yr^S - c_r alpha_r (the tyre's
departure from its linear law), scheduling v_x, output y = v_y (measured with noise). The
relative degree of y w.r.t. xi is 3. (Seed symbols: a_f, a_r = l_f, l_r; psi' = r.)

Truth plant (validation only, ``PLANT``): the bicycle model (76) with magic-formula front and rear
tyres (79) (standard form (1 - E) B alpha + E atan(B alpha); the paper's print drops the E of the
atan term), exact slip angles alpha_f = delta - atan((v_y + l_f r)/v_x), alpha_r =
atan((l_r r - v_y)/v_x) (eq. (80) with beta = atan(v_y/v_x)), the same relaxation of the rear force,
steering angle delta and speed v_x as inputs. ``PLANT_SIGNALS`` gives a_y and the UI truth xi.
"""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal
from model_defs.tyres import magic_formula_axle

v_y, r, F_yr = sp.symbols("v_y r F_yr")
a_y, xi, delta = sp.symbols("a_y xi delta")
v_x = sp.Symbol("v_x", positive=True)
M, I_z, l_f, l_r, c_r, sigma_r = sp.symbols("M I_z l_f l_r c_r sigma_r", positive=True)

UNITS = {"v_y": "m/s", "r": "rad/s", "F_yr": "N", "a_y": "m/s^2", "xi": "N", "v_x": "m/s", "delta": "rad"}

_alpha_r_lin = (l_r * r - v_y) / v_x

MODEL = ModelDefinition(
    name="ichalal2015_lateral_force",
    states=(v_y, r, F_yr),
    known_inputs=(a_y,),
    unknown_inputs=(xi,),
    dynamics=sp.Matrix([
        a_y - v_x * r,
        l_f * M / I_z * a_y - (l_f + l_r) / I_z * F_yr,
        v_x / sigma_r * (c_r * _alpha_r_lin - F_yr + xi),
    ]),
    outputs=(("v_y", v_y),),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(M, I_z, l_f, l_r, c_r, sigma_r),
    units=UNITS,
    doc=__doc__,
)

# --- Truth plant (validation only) ----------------------------------------------------------------
mu, g, C_pac, E_pac, c_f = sp.symbols("mu g C_pac E_pac c_f")
_alpha_f = delta - sp.atan((v_y + l_f * r) / v_x)
_alpha_r = sp.atan((l_r * r - v_y) / v_x)
_Fz_f = M * g * l_r / (l_f + l_r)
_Fz_r = M * g * l_f / (l_f + l_r)
_F_yf = magic_formula_axle(_alpha_f, c_f, _Fz_f, mu, C_pac, E_pac)
_F_yr_steady = magic_formula_axle(_alpha_r, c_r, _Fz_r, mu, C_pac, E_pac)

PLANT = ModelDefinition(
    name="ichalal2015_bicycle_pacejka_plant",
    states=(v_y, r, F_yr),
    known_inputs=(delta,),
    unknown_inputs=(),
    dynamics=sp.Matrix([
        (_F_yf + F_yr) / M - v_x * r,
        (l_f * _F_yf - l_r * F_yr) / I_z,
        v_x / sigma_r * (_F_yr_steady - F_yr),
    ]),
    outputs=(("v_y", v_y),),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(M, I_z, l_f, l_r, c_r, sigma_r, c_f, mu, g, C_pac, E_pac),
    parameter_ranges={"c_f": (0, None, "()"), "mu": (0, None, "()"), "g": (0, None, "()"),
                      "C_pac": (0, None, "()"), "E_pac": (None, 1)},
    units=UNITS,
    doc="Truth plant: bicycle model (76) with magic-formula tyres (79) and rear relaxation (78).",
)

# measured lateral acceleration and the unknown input's truth, as functions of the plant's signals
PLANT_SIGNALS = {
    "a_y": (_F_yf + F_yr) / M,
    "xi": _F_yr_steady - c_r * _alpha_r_lin,
}
