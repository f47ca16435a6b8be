"""Single-track lateral dynamics with an electric power steering column (Nguyen et al. 2019).

Nguyen, Guerra, Sentouh, Zhang, IEEE/ASME T-Mech 24(6), 2019, eqs. (1)-(5):
linear axle tyres F_yf = 2 C_f alpha_f, F_yr = 2 C_r alpha_r (eq. (3)), small angles,
beta = v_y / v_x, and the steering column (2) with delta_d = R_s delta.
States x = [beta, r, delta, delta_dot], known input u = T_a (assistance torque),
unknown input d = T_d (driver torque), outputs y = [r, delta, delta_dot],
scheduling signal v_x.
"""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal
from model_defs.tyres import magic_formula_axle

beta, r, delta, delta_dot = sp.symbols("beta r delta delta_dot")
T_a, T_d = sp.symbols("T_a T_d")
v_x = sp.Symbol("v_x", positive=True)
l_f, l_r, eta_t, R_s, B_s, K_p, M, I_z, I_s, C_f, C_r = sp.symbols(
    "l_f l_r eta_t R_s B_s K_p M I_z I_s C_f C_r", positive=True)

# Axle slip angles and linear lateral forces, eq. (3), with v_y = beta v_x.
alpha_f = delta - beta - l_f * r / v_x
alpha_r = (l_r * r) / v_x - beta
F_yf = 2 * C_f * alpha_f
F_yr = 2 * C_r * alpha_r

# Self-aligning torque gains of the column model (2).
T_s_beta = 2 * K_p * C_f * eta_t / R_s
T_s_r = 2 * K_p * C_f * eta_t * l_f / (R_s * v_x)
T_s = T_a + T_d

dynamics = sp.Matrix([
    (F_yf + F_yr) / (M * v_x) - r,                       # beta_dot (from M(v_y_dot + r v_x) = sum F_y)
    (l_f * F_yf - l_r * F_yr) / I_z,                     # r_dot
    delta_dot,
    # delta_d = R_s delta in (2), divided by R_s:
    (T_s_beta * beta + T_s_r * r - T_s_beta * delta - B_s * R_s * delta_dot + T_s) / (R_s * I_s),
])

MODEL = ModelDefinition(
    name="steering_single_track",
    states=(beta, r, delta, delta_dot),
    known_inputs=(T_a,),
    unknown_inputs=(T_d,),
    dynamics=dynamics,
    outputs=(("r", r), ("delta", delta), ("delta_dot", delta_dot)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(l_f, l_r, eta_t, R_s, B_s, K_p, M, I_z, I_s, C_f, C_r),
    units={"beta": "rad", "r": "rad/s", "delta": "rad", "delta_dot": "rad/s",
           "T_a": "N m", "T_d": "N m", "v_x": "m/s",
           # parameters: checked against plausible ranges (codegen.model.dimensions)
           "l_f": "m", "l_r": "m", "eta_t": "m", "R_s": "-", "B_s": "N m s/rad", "K_p": "-", "M": "kg",
           "I_z": "kg m^2", "I_s": "kg m^2", "C_f": "N/rad", "C_r": "N/rad"},
    doc=__doc__,
)


# --- Truth plant (validation only; the observer is designed from MODEL) ------------------------
# Same vehicle and column, but Pacejka magic-formula axle forces (Nguyen et al. 2021 eq. (2)) with
# longitudinal load transfer, and an aligning torque from the plant's own front slip with a
# pneumatic trail that falls linearly to zero at full sliding, instead of the linear eta_t term.
# Extra values come from the [plant] table of the parameter file.
mu, h_cg, g, C_pac, E_pac, a_x = sp.symbols("mu h_cg g C_pac E_pac a_x")
_wheelbase = l_f + l_r
_Fz_f = M * (g * l_r - h_cg * a_x) / _wheelbase          # axle loads with longitudinal transfer
_Fz_r = M * (g * l_f + h_cg * a_x) / _wheelbase


_Fyf_p = magic_formula_axle(alpha_f, 2 * C_f, _Fz_f, mu, C_pac, E_pac)
_Fyr_p = magic_formula_axle(alpha_r, 2 * C_r, _Fz_r, mu, C_pac, E_pac)
_alpha_slide = 3 * mu * _Fz_f / (2 * C_f)                 # brush-model full-slide angle (front axle)
_trail = eta_t * sp.Max(0, 1 - sp.Abs(alpha_f) / _alpha_slide)
_T_align = -K_p * _trail * _Fyf_p / R_s                  # equals the model's term for small slip

PLANT = ModelDefinition(
    name="steering_single_track_pacejka_plant",
    states=(beta, r, delta, delta_dot),
    known_inputs=(T_a,),
    unknown_inputs=(T_d,),
    dynamics=sp.Matrix([
        (_Fyf_p + _Fyr_p) / (M * v_x) - r,
        (l_f * _Fyf_p - l_r * _Fyr_p) / I_z,
        delta_dot,
        (_T_align - B_s * R_s * delta_dot + T_s) / (R_s * I_s),
    ]),
    outputs=(("r", r), ("delta", delta), ("delta_dot", delta_dot)),
    scheduling=(SchedulingSignal(v_x, "m/s"), SchedulingSignal(a_x, "m/s^2")),
    parameters=(l_f, l_r, eta_t, R_s, B_s, K_p, M, I_z, I_s, C_f, C_r, mu, h_cg, g, C_pac, E_pac),
    parameter_ranges={"mu": (0, None, "()"), "h_cg": (0, None, "()"), "g": (0, None, "()"),
                      "C_pac": (0, None, "()"), "E_pac": (None, 1)},
    units=MODEL.units,
    doc="Truth plant: Nguyen et al. 2019 vehicle with Pacejka tyres, load transfer and trail-based aligning torque.",
)
