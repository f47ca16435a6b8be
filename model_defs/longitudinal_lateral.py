"""Combined longitudinal-lateral single-track model of Nguyen et al. 2021.

Nguyen, Dinh, Guerra, Pan, IEEE/ASME T-Mech 26(3), 2021, eqs. (1) and (3):

    v_x' = (T_eng - C_x v_x^2)/I_e + v_y r
    v_y' = (F_yf + F_yr - C_y v_y^2)/M - v_x r
    r'   = (l_f F_yf - l_r F_yr)/I_z

with linear axle forces F_yf = 2 C_f (delta - (v_y + l_f r)/v_x), F_yr = 2 C_r (l_r r - v_y)/v_x.
States x = [v_x, v_y, r]; unknown inputs d = [T_eng, delta]; measured y = [v_x, r].
Nothing here says which terms are premises or consequents: :mod:`codegen.families.ts_fuzzy_uio.representation` finds
the measured premises (1/v_x, r) and the unmeasured consequent v_y^2 itself.

Note on the paper's eq. (8): its f_v(xi) second entry prints (2(C_r l_r - C_f l_f) r - v_x r)/(M v_x),
which is dimensionally wrong for the -v_x r term of (1); the derivation from (1) gives
(2(C_r l_r - C_f l_f)/(M v_x) - v_x) r, which is what the toolchain obtains.
"""
import sympy as sp

from codegen.model import ModelDefinition
from model_defs.tyres import magic_formula_axle

v_y, r = sp.symbols("v_y r")
v_x = sp.Symbol("v_x", positive=True)
T_eng, delta = sp.symbols("T_eng delta")
M, l_f, l_r, I_e, I_z, C_f, C_r = sp.symbols("M l_f l_r I_e I_z C_f C_r", positive=True)
C_x, C_y = sp.symbols("C_x C_y", nonnegative=True)      # drag coefficients: 0 for a model without drag


def _dynamics(F_yf, F_yr):
    return sp.Matrix([
        (T_eng - C_x * v_x ** 2) / I_e + v_y * r,
        (F_yf + F_yr - C_y * v_y ** 2) / M - v_x * r,
        (l_f * F_yf - l_r * F_yr) / I_z,
    ])


# eq. (3): small angles, linear tyres
_F_yf = 2 * C_f * (delta - (v_y + l_f * r) / v_x)
_F_yr = 2 * C_r * (l_r * r - v_y) / v_x

UNITS = {"v_x": "m/s", "v_y": "m/s", "r": "rad/s", "T_eng": "N m", "delta": "rad",
         # the parameters' units (a value in t or kN/rad where kg or N/rad is meant is refused): I_e is the
         # paper's equivalent inertia of the driveline at the wheel, T_eng / I_e an acceleration, so kg m;
         # the drag terms C_x v_x^2 (a torque, like T_eng) and C_y v_y^2 (a force)
         "M": "kg", "l_f": "m", "l_r": "m", "I_e": "kg m", "I_z": "kg m^2", "C_f": "N/rad", "C_r": "N/rad",
         "C_x": "N s^2/m", "C_y": "N s^2/m^2", "mu": "-", "g": "m/s^2", "C_pac": "-", "E_pac": "-"}

MODEL = ModelDefinition(
    name="longitudinal_lateral",
    states=(v_x, v_y, r),
    known_inputs=(),
    unknown_inputs=(T_eng, delta),
    dynamics=_dynamics(_F_yf, _F_yr),
    outputs=(("v_x", v_x), ("r", r)),
    scheduling=(),
    parameters=(M, l_f, l_r, I_e, I_z, C_f, C_r, C_x, C_y),
    units=UNITS,
    doc=__doc__,
)


# --- Truth plant (validation only) ----------------------------------------------------------------
# Same equations (1) with the magic-formula tyres of eq. (2) and the exact slip angles below (2);
# static axle loads (the paper's scenarios are gentle in a_x). B C D = 2 C_f (2 C_r), so the small
# slip slope equals the observer's linear tyre; friction mu scales the peak (scenario 3: time-varying grip).
mu, g, C_pac, E_pac = sp.symbols("mu g C_pac E_pac")
_alpha_f = delta - sp.atan((v_y + l_f * r) / v_x)
_alpha_r = sp.atan((l_r * r - v_y) / v_x)
_Fz_f = M * g * l_r / (l_f + l_r)
_Fz_r = M * g * l_f / (l_f + l_r)

PLANT = ModelDefinition(
    name="longitudinal_lateral_pacejka_plant",
    states=(v_x, v_y, r),
    known_inputs=(),
    unknown_inputs=(T_eng, delta),
    dynamics=_dynamics(magic_formula_axle(_alpha_f, 2 * C_f, _Fz_f, mu, C_pac, E_pac),
                       magic_formula_axle(_alpha_r, 2 * C_r, _Fz_r, mu, C_pac, E_pac)),
    outputs=(("v_x", v_x), ("r", r)),
    scheduling=(),
    parameters=(M, l_f, l_r, I_e, I_z, C_f, C_r, C_x, C_y, mu, g, C_pac, E_pac),
    parameter_ranges={"mu": (0, None, "()"), "g": (0, None, "()"), "C_pac": (0, None, "()"), "E_pac": (None, 1)},
    units=UNITS,
    doc="Truth plant: Nguyen et al. 2021 vehicle (1) with the magic-formula tyres (2).",
)
