"""Symbolic models of the Kalman-filter baselines that run beside our observers.

The baselines are generated from these definitions by :mod:`codegen.validation.kalman`
(sympy -> CasADi, Jacobians by CasADi differentiation); no filter matrix is typed in.

``LINEAR_SINGLE_TRACK``
    The linear single-track model of the linear Kalman filter used with the Stanford data by its
    authors (states beta, r; measurements a_y, r; input delta; scheduling v_x). It is *derived*
    from the observer's model ``single_track_saturating.MODEL`` with the tyres in their linear
    range (secant ratio s = 1) and no yaw-moment disturbance (M_z = 0), so it is the same
    equations: axle forces F_yf = C_f alpha_f, F_yr = C_r alpha_r (per axle, data README
    convention), small angles.

``FIALA_SINGLE_TRACK``
    The nonlinear single-track model of the EKF baseline: states (v_y, r), input delta,
    scheduling v_x (measured), exact kinematic slip angles, steering projection cos(delta),
    static axle loads and Fiala (brush, parabolic pressure) axle forces. Its unknown inputs
    w_f, w_r are the process noise: the unmodelled lateral force per axle (load transfer,
    banking, combined slip, aero) as a fraction of the static axle load.

Both use the parameter names of ``single_track_saturating`` (m, l_f, l_r, I_z, C_f, C_r, and
mu, g for the Fiala model); values come from the caller (the data README's car for the real
log, the observer's parameter file for the simulated plants).
"""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal
from model_defs import single_track_saturating as _st
from model_defs import tyres as _tyres

beta, r, delta, v_x = _st.beta, _st.r, _st.delta, _st.v_x
m, l_f, l_r, I_z, C_f, C_r, mu, g = _st.m, _st.l_f, _st.l_r, _st.I_z, _st.C_f, _st.C_r, _st.mu, _st.g


def fiala_axle_force(alpha, c_alpha, mu_fz):
    """Fiala (brush, parabolic pressure) lateral axle force, sign convention F = +C alpha.

    ``model_defs.tyres.fiala_slip_force`` at t = tan(alpha): ``F = C t - C^2/(3 mu F_z) |t| t +
    C^3/(27 mu^2 F_z^2) t^3`` with t clamped to the full-sliding value ``3 mu F_z / C``, where
    ``F = mu F_z sign(alpha)`` and dF/dalpha = 0; Pacejka, *Tire and Vehicle Dynamics*, 3rd ed.,
    Sec. 3.2 (brush model), as used by Hindiyeh & Gerdes (2014). The clamp keeps the expression
    smooth at alpha = 0 (slope C there).
    """
    return _tyres.fiala_slip_force(sp.tan(alpha), c_alpha, mu_fz)


# --- (a) linear KF model: the observer's single-track equations with linear tyres --------------
_linear = {_st.s: 1, _st.M_z: 0}
_linear_dynamics = _st.MODEL.dynamics.subs(_linear)
_linear_outputs = tuple((name, sp.sympify(expr).subs(_linear)) for name, expr in _st.MODEL.outputs)
_linear_used = set().union(*(sp.sympify(e).free_symbols for e in (*_linear_dynamics, *(e for _, e in _linear_outputs))))

LINEAR_SINGLE_TRACK = ModelDefinition(
    name="single_track_linear",
    states=_st.MODEL.states,
    known_inputs=_st.MODEL.known_inputs,
    unknown_inputs=(),
    dynamics=_linear_dynamics,
    outputs=_linear_outputs,
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=tuple(p for p in _st.MODEL.parameters if p in _linear_used),
    units={k: v for k, v in _st.MODEL.units.items() if k not in ("M_z", "s")},
    doc="single_track_saturating.MODEL with s = 1 (linear tyres) and M_z = 0: the linear single-track "
        "model of the source repository's Kalman filter (BetaStanfordLinear.m).",
)

# --- (b) EKF model: nonlinear single-track with Fiala axle forces ------------------------------
v_y = sp.Symbol("v_y")
w_f, w_r = sp.symbols("w_f w_r")
_wheelbase = l_f + l_r
F_zf = m * g * l_r / _wheelbase                        # static axle loads
F_zr = m * g * l_f / _wheelbase
alpha_f = delta - sp.atan((v_y + l_f * r) / v_x)      # kinematic slip angles, no small-angle step
alpha_r = -sp.atan((v_y - l_r * r) / v_x)
F_yf = fiala_axle_force(alpha_f, C_f, mu * F_zf) + F_zf * w_f
F_yr = fiala_axle_force(alpha_r, C_r, mu * F_zr) + F_zr * w_r
a_y = (F_yf * sp.cos(delta) + F_yr) / m

FIALA_SINGLE_TRACK = ModelDefinition(
    name="single_track_fiala",
    states=(v_y, r),
    known_inputs=(delta,),
    unknown_inputs=(w_f, w_r),
    dynamics=sp.Matrix([
        a_y - r * v_x,                                          # v_y_dot
        (l_f * F_yf * sp.cos(delta) - l_r * F_yr) / I_z,       # r_dot
    ]),
    outputs=(("a_y", a_y), ("r", r)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(m, l_f, l_r, I_z, C_f, C_r, mu, g),
    units={"v_y": "m/s", "r": "rad/s", "delta": "rad", "w_f": "-", "w_r": "-", "a_y": "m/s^2",
           "v_x": "m/s"},
    doc="Nonlinear single-track model with Fiala axle forces (EKF baseline); w_f, w_r: process noise, "
        "unmodelled axle force per static axle load.",
)
