"""Roll-augmented single-track model with road bank angle (Menhour et al. 2014, eqs. (1)-(2)).

Menhour, Koenig, d'Andréa-Novel, ECC 2014. Three balances, written once and shared by the
observer's model and the truth plant (the road plane is banked by phi_r; phi is the sprung
mass's roll relative to the road, positive for the outward roll of a left turn; h_r is the height
of the sprung mass's CoG above the roll axis)::

    lateral force (whole car):  m a - m_s h_r phi''                    = F_yf + F_yr - m g sin(phi_r)
    roll moment (roll axis):    (I_x + m_s h_r^2) phi'' - m_s h_r a    = m_s g h_r sin(phi + phi_r) - K_r phi - b_r phi'
    yaw moment:                 I_z r'                                  = l_f F_yf - l_r F_yr

with a = v_y' + v_x r the lateral acceleration of the roll axis and I_x the sprung mass's roll
inertia about its own CoG. The bank enters both the lateral force balance (gravity component
-m g sin phi_r) and the roll moment balance (gravity moment m_s g h_r sin phi_r); solving the two
for (a, phi'') the bank cancels from phi'' exactly in the small-angle model, and what remains is
the paper's F = [-g/V_x, 0, 0, 0]^T.

Observer model (``MODEL``): small angles, beta = v_y / V_x at constant V_x (the paper's (1)),
linear axle forces (2) F_yf = C_f (delta - beta - l_f r / V_x), F_yr = C_r (l_r r / V_x - beta)
(axle cornering stiffnesses), states x = [beta, r, phi, phi_dot], known input u = delta (road-wheel
angle), unknown input omega = phi_r, outputs y = [r, phi, phi_dot], scheduling signal V_x.
With m_s = m the toolchain's matrices equal the paper's (1) term by term, after three misprints of
the paper are corrected (``tests/families/switched_pi/test_switched_pi.py`` checks it): A_22 = -C_a2/(I_z V_x) (printed
I_x), A_14 = -h_r b_r/(I_x V_x) (printed h_r L_r) and H_4 = h_r C_f / I_x (printed C_f / I_x).
We keep the sprung mass m_s separate from the total mass m because the validation car has heavy
unsprung masses (the CommonRoad BMW 320i: m_s / m = 0.88).
"""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal
from model_defs.tyres import magic_formula_axle

beta, r, phi, phi_dot = sp.symbols("beta r phi phi_dot")
delta, phi_r = sp.symbols("delta phi_r")
v_x = sp.Symbol("v_x", positive=True)
m, m_s, I_x, I_z, l_f, l_r, h_r, K_r, b_r, C_f, C_r, g = sp.symbols(
    "m m_s I_x I_z l_f l_r h_r K_r b_r C_f C_r g", positive=True)

UNITS = {"beta": "rad", "r": "rad/s", "phi": "rad", "phi_dot": "rad/s", "delta": "rad", "phi_r": "rad",
         "v_x": "m/s", "v_y": "m/s", "a_x": "m/s^2",
         # the parameters' units: a value in t, kN/rad or mm where kg, N/rad or m is meant is refused (dimensions)
         "m": "kg", "m_s": "kg", "I_x": "kg m^2", "I_z": "kg m^2", "l_f": "m", "l_r": "m", "h_r": "m",
         "K_r": "N m/rad", "b_r": "N m s/rad", "C_f": "N/rad", "C_r": "N/rad", "g": "m/s^2",
         "mu": "-", "h_cg": "m", "C_pac": "-", "E_pac": "-"}


def balances(a, phi_dd, F_yf, F_yr, sin_bank, gravity_moment, cos_phi=1, centripetal=0):
    """Residuals of the lateral force, roll moment and yaw moment balances (zero on motion).

    ``a`` is the roll axis's lateral acceleration, ``sin_bank`` the factor of the bank's gravity
    component, ``gravity_moment`` = sin(phi + phi_r) (or its small-angle form), ``cos_phi`` and
    ``centripetal`` the exact kinematics of the rolling sprung mass (1 and 0 for small angles)."""
    lateral = m * a - m_s * h_r * (phi_dd * cos_phi - centripetal) - (F_yf + F_yr - m * g * sin_bank)
    roll = ((I_x + m_s * h_r ** 2) * phi_dd - m_s * h_r * cos_phi * a
            - (m_s * g * h_r * gravity_moment - K_r * phi - b_r * phi_dot))
    return lateral, roll


def _solve(lateral, roll, a_sym, phi_dd_sym):
    """(a, phi'') from the two balances, which are linear in them (Cramer's rule, no simplification)."""
    (M, rhs) = sp.linear_eq_to_matrix([lateral, roll], [a_sym, phi_dd_sym])
    det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
    return ((rhs[0] * M[1, 1] - M[0, 1] * rhs[1]) / det, (M[0, 0] * rhs[1] - M[1, 0] * rhs[0]) / det)


_a, _pdd = sp.symbols("_a _phi_dd")

# --- observer model (seed (1)-(2)) -----------------------------------------------------------------
_F_yf = C_f * (delta - beta - l_f * r / v_x)
_F_yr = C_r * (l_r * r / v_x - beta)
_lat, _roll = balances(_a, _pdd, _F_yf, _F_yr, phi_r, phi + phi_r)
_a_sol, _pdd_sol = _solve(_lat, _roll, _a, _pdd)

MODEL = ModelDefinition(
    name="roll_single_track",
    states=(beta, r, phi, phi_dot),
    known_inputs=(delta,),
    unknown_inputs=(phi_r,),
    dynamics=sp.Matrix([
        sp.expand(_a_sol / v_x - r),                      # beta' = a / V_x - r  (v_y = V_x beta, V_x const.)
        (l_f * _F_yf - l_r * _F_yr) / I_z,
        phi_dot,
        sp.expand(_pdd_sol),
    ]),
    outputs=(("r", r), ("phi", phi), ("phi_dot", phi_dot)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(m, m_s, I_x, I_z, l_f, l_r, h_r, K_r, b_r, C_f, C_r, g),
    units=UNITS,
    doc=__doc__,
)


# --- truth plant (validation only; the observer is designed from MODEL) ----------------------------
# Lateral speed v_y instead of beta (so the speed may vary: beta = atan(v_y / v_x)), exact slip
# angles, magic-formula axle forces whose cornering stiffness follows the axle load (C_f F_z / F_z0:
# the PAC2002 form K_y = |p_ky1| F_z of the CommonRoad tyres, equal to the model's C_f, C_r at the
# static loads F_z0) with longitudinal load transfer and the bank's cos(phi_r) on the loads, a
# friction-ellipse reduction sqrt(1 - (a_x / (mu g))^2) of the lateral force while braking or
# accelerating (longitudinal force shared in proportion to the axle loads), sin/cos of the exact
# roll kinematics and of the bank's gravity terms.
v_y, a_x = sp.symbols("v_y a_x")
mu, h_cg, C_pac = sp.symbols("mu h_cg C_pac", positive=True)
E_pac = sp.Symbol("E_pac", real=True)                  # curvature factor, either sign, <= 1
_L = l_f + l_r
_Fz_f0, _Fz_r0 = m * g * l_r / _L, m * g * l_f / _L
_Fz_f = m * (g * sp.cos(phi_r) * l_r - h_cg * a_x) / _L
_Fz_r = m * (g * sp.cos(phi_r) * l_f + h_cg * a_x) / _L
_alpha_f = delta - sp.atan((v_y + l_f * r) / v_x)
_alpha_r = sp.atan((l_r * r - v_y) / v_x)
_ellipse = sp.sqrt(1 - (a_x / (mu * g)) ** 2)
_Fyf_p = _ellipse * magic_formula_axle(_alpha_f, C_f * _Fz_f / _Fz_f0, _Fz_f, mu, C_pac, E_pac) * sp.cos(delta)
_Fyr_p = _ellipse * magic_formula_axle(_alpha_r, C_r * _Fz_r / _Fz_r0, _Fz_r, mu, C_pac, E_pac)
_lat_p, _roll_p = balances(_a, _pdd, _Fyf_p, _Fyr_p, sp.sin(phi_r), sp.sin(phi + phi_r),
                           cos_phi=sp.cos(phi), centripetal=phi_dot ** 2 * sp.sin(phi))
_a_p, _pdd_p = _solve(_lat_p, _roll_p, _a, _pdd)

PLANT = ModelDefinition(
    name="roll_single_track_pacejka_bank_plant",
    states=(v_y, r, phi, phi_dot),
    known_inputs=(delta,),
    unknown_inputs=(phi_r,),
    dynamics=sp.Matrix([_a_p - v_x * r, (l_f * _Fyf_p - l_r * _Fyr_p) / I_z, phi_dot, _pdd_p]),
    outputs=(("r", r), ("phi", phi), ("phi_dot", phi_dot)),
    scheduling=(SchedulingSignal(v_x, "m/s"), SchedulingSignal(a_x, "m/s^2")),
    parameters=(m, m_s, I_x, I_z, l_f, l_r, h_r, K_r, b_r, C_f, C_r, g, mu, h_cg, C_pac, E_pac),
    parameter_ranges={"E_pac": (None, 1)},
    units=UNITS,
    doc="Truth plant: roll and bank with sin/cos, Pacejka axles with load-dependent stiffness, "
        "load transfer and friction ellipse.",
)

# lateral acceleration of the roll axis (what a body-fixed accelerometer on the axis, corrected for
# gravity, would read): a = v_y' + v_x r
PLANT_LATERAL_ACCELERATION = _a_p
