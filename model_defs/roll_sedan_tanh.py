"""A rolling sedan with saturating (tanh) axle tyres, observed from its lateral acceleration.

Single-track lateral and yaw dynamics with a roll degree of freedom of the sprung mass, and axle
forces that saturate smoothly at the axle's grip (a tanh law: slope C at zero slip, limit mu F_z)::

    F_yk = mu F_zk tanh(C_k alpha_k / (mu F_zk)),   F_zf = m g l_r / (l_f + l_r),  F_zr = m g l_f / (l_f + l_r)
    alpha_f = delta - (v_y + l_f r) / v_x,          alpha_r = (l_r r - v_y) / v_x

    v_y'   = (F_yf + F_yr) / m - r v_x
    r'     = (l_f F_yf - l_r F_yr) / I_z
    phi'   = phi_dot
    phi''  = (m_s h_r a_y + m_s g h_r phi - K_r phi - b_r phi_dot) / (I_x + m_s h_r^2),   a_y = (F_yf + F_yr) / m

The lateral accelerometer reads a_y, a nonlinear function of the unmeasured lateral speed v_y (through
both tyre laws): y = h(x). The yaw-rate and roll-rate gyros read r and phi_dot. The speed v_x is a
measured scheduling signal, the road-wheel angle delta a known input. The roll angle phi and the lateral
speed v_y are estimated (the sideslip is v_y / v_x).

The parameters are the CommonRoad BMW 320i's (vehicle 2, ``commonroad_bmw320i_roll.toml``) with a
peak friction mu; the family ``dmvt_observer`` takes the nonlinear output as it stands.
"""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal

v_y, r, phi, phi_dot = sp.symbols("v_y r phi phi_dot")
delta = sp.Symbol("delta")
v_x = sp.Symbol("v_x", positive=True)
m, m_s, I_x, I_z, l_f, l_r, h_r, K_r, b_r, C_f, C_r, mu, g = sp.symbols(
    "m m_s I_x I_z l_f l_r h_r K_r b_r C_f C_r mu g", positive=True)

F_zf = m * g * l_r / (l_f + l_r)
F_zr = m * g * l_f / (l_f + l_r)
alpha_f = delta - (v_y + l_f * r) / v_x
alpha_r = (l_r * r - v_y) / v_x
F_yf = mu * F_zf * sp.tanh(C_f * alpha_f / (mu * F_zf))
F_yr = mu * F_zr * sp.tanh(C_r * alpha_r / (mu * F_zr))
a_y = (F_yf + F_yr) / m

MODEL = ModelDefinition(
    name="roll_sedan_tanh",
    states=(v_y, r, phi, phi_dot),
    known_inputs=(delta,),
    unknown_inputs=(),
    dynamics=sp.Matrix([
        a_y - r * v_x,
        (l_f * F_yf - l_r * F_yr) / I_z,
        phi_dot,
        (m_s * h_r * a_y + m_s * g * h_r * phi - K_r * phi - b_r * phi_dot) / (I_x + m_s * h_r ** 2),
    ]),
    outputs=(("r", r), ("phi_dot", phi_dot), ("a_y", a_y)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(m, m_s, I_x, I_z, l_f, l_r, h_r, K_r, b_r, C_f, C_r, mu, g),
    units={"v_y": "m/s", "r": "rad/s", "phi": "rad", "phi_dot": "rad/s", "delta": "rad", "v_x": "m/s",
           "a_y": "m/s^2",
           "m": "kg", "m_s": "kg", "I_x": "kg m^2", "I_z": "kg m^2", "l_f": "m", "l_r": "m", "h_r": "m",
           "K_r": "N m/rad", "b_r": "N m s/rad", "C_f": "N/rad", "C_r": "N/rad", "mu": "-", "g": "m/s^2"},
    doc=__doc__,
)
