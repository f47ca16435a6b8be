"""Nguyen et al. 2019 single track and steering column, with roll camber and the tyres' nonlinear remainders.

The model of :mod:`model_defs.steering_single_track` (Nguyen et al. 2019 eqs. (1)-(5): states
x = [beta, r, delta, delta_dot], known input T_a, unknown input T_d, outputs r, delta, delta_dot,
scheduling v_x), written for a car whose tyre model is a magic formula with camber terms and whose
body rolls, such as the CommonRoad multi-body vehicles (PAC2002 tyres). Three additions, each
derived from the car's parameter file, none fitted to a trajectory:

* **Roll camber.** A lateral acceleration a_y rolls the body by phi = -(d phi/d a_y) a_y and
  cambers the wheels by gamma = g phi (suspension kinematics); camber thrust adds k a_y to each
  axle force. With a_y = (F_yf + F_yr)/M this stays linear in the states (quasi-static roll):
  a_y = (F_f0 + F_r0)/(M - k_f - k_r), F_yf = F_f0 + k_f a_y, F_yr = F_r0 + k_r a_y.
* **Camber offset.** The commonroad-vehicle-models PAC2002 applies its horizontal and vertical
  shifts with the sign of the camber, S_Hy = sgn(gamma)(p_hy1 + p_hy3 |gamma|) and
  S_Vy = sgn(gamma) F_z (p_vy1 + p_vy3 |gamma|): besides the thrust above, every cornering
  wheel gets a constant force F_c sgn(a_y) (about 0.02 F_z). Its sign is a function of the
  measured signals (s_c below, a ramp of width a_s).
* **Nonlinear remainders** (Nguyen et al. 2021's "measured nonlinear consequents"). The pure-slip axle force
  F(alpha) = mu F_z sin(C atan(B alpha - E (B alpha - atan(B alpha)))) is 2 C alpha plus a
  remainder, and the aligning torque K_p t_p(alpha) F(alpha) / R_s with the brush-model trail
  t_p = eta_t (1 - tan|alpha| / tan alpha_sl), tan alpha_sl = 3 mu F_z / (2 C) (the plant's own
  documented trail model) is the paper's linear term K_p eta_t 2 C alpha / R_s plus a remainder.
  The linear parts stay in the LPV matrices (the states carry them); the remainders are
  evaluated at the slip angle the *measured* lateral acceleration implies (q = v_x y_r, the
  quasi-steady a_y; the axle's pure-slip share (M l / L - k) |q| - F_c |s_c| of it, the magic
  formula inverted in closed form) and enter as known inputs computed inside the step. They
  are zero at small slip, so the model is the paper's there apart from the camber terms.

Derived inputs w = [s_c, F_nf, F_nr, T_nl] (:class:`codegen.model.DerivedInput`); they use
only y_r, v_x and parameters, so the generated step takes the same inputs as the paper's.
"""
import sympy as sp

from codegen.model import DerivedInput, ModelDefinition, SchedulingSignal

beta, r, delta, delta_dot = sp.symbols("beta r delta delta_dot")
T_a, T_d = sp.symbols("T_a T_d")
v_x = sp.Symbol("v_x", positive=True)
y_r = sp.Symbol("y_r")
l_f, l_r, eta_t, R_s, B_s, K_p, M, I_z, I_s, C_f, C_r = sp.symbols(
    "l_f l_r eta_t R_s B_s K_p M I_z I_s C_f C_r", positive=True)
F_zf, F_zr, mu_y, C_y, a_s = sp.symbols("F_zf F_zr mu_y C_y a_s", positive=True)
k_f, k_r, F_cf, F_cr, E_y = sp.symbols("k_f k_r F_cf F_cr E_y", real=True)   # any sign
s_c, F_nf, F_nr, T_nl = sp.symbols("s_c F_nf F_nr T_nl")

U_MAX = sp.Rational(99, 100)     # utilization clamp of the inversion (the trail is ~0 there anyway)
Q_EPS = sp.Float(1e-9)           # m/s^2, ramp of sgn(q) (finite for any q, including overflow)

# --- measured-signal functions (derived inputs) ------------------------------------------------
q = v_x * y_r                                            # quasi-steady lateral acceleration
q_abs = sp.Abs(q)
q_sign = sp.Max(-1, sp.Min(1, q / Q_EPS))
s_c_expr = sp.Max(-1, sp.Min(1, q / a_s))                # camber-offset sign, ramp of width a_s
_wheelbase = l_f + l_r


def pure_slip_utilization(share, k, F_c, F_z):
    """Pure-slip force / (mu F_z) of one axle at the measured lateral acceleration."""
    force = sp.Max(0, (share - k) * q_abs - F_c * sp.Min(1, q_abs / a_s))
    return sp.Min(U_MAX, force / (mu_y * F_z))


def slip_of_utilization(u, C_axle, F_z):
    """|alpha| with mu F_z sin(C atan(B a - E (B a - atan(B a)))) = u mu F_z (closed form; two
    fixed-point steps for the small E), B = 2 C_axle / (C mu F_z)."""
    phi = sp.tan(sp.asin(u) / C_y)
    ba = (phi - E_y * sp.atan(phi)) / (1 - E_y)
    ba = (phi - E_y * sp.atan(ba)) / (1 - E_y)
    return ba * C_y * mu_y * F_z / (2 * C_axle)


u_f = pure_slip_utilization(M * l_r / _wheelbase, k_f, F_cf, F_zf)
u_r = pure_slip_utilization(M * l_f / _wheelbase, k_r, F_cr, F_zr)
alpha_f_hat = slip_of_utilization(u_f, C_f, F_zf)
alpha_r_hat = slip_of_utilization(u_r, C_r, F_zr)
tan_alpha_sl = 3 * mu_y * F_zf / (2 * C_f)               # brush-model full-slide angle, front axle
trail = eta_t * sp.Max(0, 1 - sp.tan(alpha_f_hat) / tan_alpha_sl)
F_nf_expr = q_sign * (mu_y * F_zf * u_f - 2 * C_f * alpha_f_hat)
F_nr_expr = q_sign * (mu_y * F_zr * u_r - 2 * C_r * alpha_r_hat)
T_nl_expr = q_sign * K_p / R_s * (eta_t * 2 * C_f * alpha_f_hat - trail * mu_y * F_zf * u_f)

# --- dynamics -------------------------------------------------------------------------------
alpha_f = delta - beta - l_f * r / v_x
alpha_r = (l_r * r) / v_x - beta
F_f0 = 2 * C_f * alpha_f + F_nf + F_cf * s_c              # pure slip + camber offset
F_r0 = 2 * C_r * alpha_r + F_nr + F_cr * s_c
a_y = (F_f0 + F_r0) / (M - k_f - k_r)                    # quasi-static roll camber thrust
F_yf = F_f0 + k_f * a_y
F_yr = F_r0 + k_r * a_y

# Self-aligning torque of the column (2): the paper's linear term in the pure-slip front slip
# (the camber terms do not reach the kingpin moment) plus its measured nonlinear remainder.
T_s_beta = 2 * K_p * C_f * eta_t / R_s
T_s_r = 2 * K_p * C_f * eta_t * l_f / (R_s * v_x)

dynamics = sp.Matrix([
    (F_yf + F_yr) / (M * v_x) - r,
    (l_f * F_yf - l_r * F_yr) / I_z,
    delta_dot,
    (T_s_beta * beta + T_s_r * r - T_s_beta * delta - B_s * R_s * delta_dot + T_nl + T_a + T_d)
    / (R_s * I_s),
])

MODEL = ModelDefinition(
    name="steering_single_track_camber",
    states=(beta, r, delta, delta_dot),
    known_inputs=(T_a,),
    unknown_inputs=(T_d,),
    dynamics=dynamics,
    outputs=(("r", r), ("delta", delta), ("delta_dot", delta_dot)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(l_f, l_r, eta_t, R_s, B_s, K_p, M, I_z, I_s, C_f, C_r,
                k_f, k_r, F_cf, F_cr, F_zf, F_zr, mu_y, C_y, E_y, a_s),
    units={"beta": "rad", "r": "rad/s", "delta": "rad", "delta_dot": "rad/s",
           "T_a": "N m", "T_d": "N m", "v_x": "m/s",
           "s_c": "-", "F_nf": "N", "F_nr": "N", "T_nl": "N m"},
    doc=__doc__,
    parameter_ranges={"E_y": (None, 1, "[)")},        # the inversion divides by 1 - E_y
    derived_inputs=(DerivedInput(s_c, s_c_expr, "-"), DerivedInput(F_nf, F_nf_expr, "N"),
                    DerivedInput(F_nr, F_nr_expr, "N"), DerivedInput(T_nl, T_nl_expr, "N m")),
)
