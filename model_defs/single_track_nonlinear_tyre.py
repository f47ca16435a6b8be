"""Nonlinear single-track model with a Fiala (brush) tyre per axle, combined slip from the measured a_x.

One model for the observer ``stanford_sideslip_nonlinear_tyre`` (family
``nonlinear_tyre_observer``), for its Kalman peers (EKF and UKF generated from ``MODEL`` by
:mod:`codegen.validation.kalman`) and for any plant that simulates it: the tyre laws are
``model_defs.tyres``, written once.

States x = (v_y, r) (lateral speed at the CoG, yaw rate); known inputs delta (road-wheel angle)
and a_x (measured longitudinal acceleration at the CoG); measured scheduling v_x; outputs a_y
(lateral acceleration at the CoG) and r. Exact kinematics: the slip variable t = tan(alpha) of
each axle in the wheel frame,

    t_f = (v_x sin(delta) - (v_y + l_f r) cos(delta)) / (v_x cos(delta) + (v_y + l_f r) sin(delta))
        = tan(delta - atan((v_y + l_f r) / v_x)),
    t_r = -(v_y - l_r r) / v_x,

static axle loads F_zf = m g l_r / l, F_zr = m g l_f / l; axle forces F_k = Fiala(t_k; C_k, F_k,max),
the front one projected by cos(delta). Combined slip: the longitudinal force m a_x is split over
the axles (braking by ``brake_front``, traction by ``drive_front``, the shares of the front axle)
and reduces each axle's lateral capacity by the friction circle,
F_k,max = sqrt((mu_k F_zk)^2 - F_xk^2) (never below ``lateral_floor`` mu_k F_zk): at the corner
exit of a rear-driven car the rear axle has less lateral grip, and under braking both have.
The unknown inputs w_f, w_r are *process noise* for the Kalman peers (the unmodelled lateral force
per axle as a fraction of its static load); the observer does not estimate them (they are 0 in
its step).

``AXLES`` tells the observer family how each axle force depends on the unmeasured v_y: its slip
variable, the inverse map v_y(t) (which turns the Jacobian of the force into a function of (t,
delta) alone, so it can be bounded over a set of slip values), its lateral capacity and its
full-sliding slip, written in a symbol of that capacity.
"""
import sympy as sp

from codegen.model import Axle, ModelDefinition, SchedulingSignal
from model_defs import tyres

v_y, r = sp.symbols("v_y r")
delta, a_x = sp.symbols("delta a_x")
w_f, w_r = sp.symbols("w_f w_r")
v_x = sp.Symbol("v_x", positive=True)
m, l_f, l_r, I_z, C_f, C_r, mu_f, mu_r, g = sp.symbols("m l_f l_r I_z C_f C_r mu_f mu_r g", positive=True)
brake_front, drive_front, lateral_floor = sp.symbols("brake_front drive_front lateral_floor", nonnegative=True)
t_sym = sp.Symbol("t", real=True)
F_PEAK = sp.symbols("F_peak_f F_peak_r", positive=True)
"""Symbols of the axles' lateral capacities in ``AXLES`` (the laws are written in them)."""

_l = l_f + l_r
F_zf = m * g * l_r / _l
F_zr = m * g * l_f / _l
_braking, _traction = m * sp.Min(a_x, 0), m * sp.Max(a_x, 0)
F_xf = brake_front * _braking + drive_front * _traction
F_xr = (1 - brake_front) * _braking + (1 - drive_front) * _traction
F_maxf = tyres.friction_circle_capacity(mu_f * F_zf, F_xf, lateral_floor)
F_maxr = tyres.friction_circle_capacity(mu_r * F_zr, F_xr, lateral_floor)
_wf = v_y + l_f * r
t_f = (v_x * sp.sin(delta) - _wf * sp.cos(delta)) / (v_x * sp.cos(delta) + _wf * sp.sin(delta))
t_r = -(v_y - l_r * r) / v_x
F_yf = tyres.fiala_slip_force(t_f, C_f, F_maxf)                # axle forces in the wheel frame
F_yr = tyres.fiala_slip_force(t_r, C_r, F_maxr)
Phi_f = F_yf * sp.cos(delta) + F_zf * w_f                      # body-frame lateral forces
Phi_r = F_yr + F_zr * w_r

FORCES = sp.symbols("Phi_f Phi_r")
"""Symbols of the body-frame axle forces in ``DYNAMICS_IN_FORCES`` and ``A_Y_IN_FORCES``."""
A_Y_IN_FORCES = (FORCES[0] + FORCES[1]) / m
DYNAMICS_IN_FORCES = sp.Matrix([A_Y_IN_FORCES - r * v_x, (l_f * FORCES[0] - l_r * FORCES[1]) / I_z])
"""The single-track equations written in the axle forces (the observer family reads their
coefficients d f/d Phi; ``MODEL`` is these with the Fiala forces substituted)."""
_forces = {FORCES[0]: Phi_f, FORCES[1]: Phi_r}
a_y = A_Y_IN_FORCES.subs(_forces)


# each axle as the nonlinear-tyre observer reads it (codegen.model.Axle says what each field is)
AXLES = (
    Axle("front", tyres.fiala_slip_force(t_sym, C_f, F_PEAK[0], clamp=False), sp.cos(delta), t_f,
         v_x * (sp.sin(delta) - t_sym * sp.cos(delta)) / (sp.cos(delta) + t_sym * sp.sin(delta)) - l_f * r,
         tyres.fiala_sliding_slip(C_f, F_PEAK[0]), F_PEAK[0], F_maxf, C_f, mu_f),
    Axle("rear", tyres.fiala_slip_force(t_sym, C_r, F_PEAK[1], clamp=False), sp.Integer(1), t_r,
         l_r * r - v_x * t_sym, tyres.fiala_sliding_slip(C_r, F_PEAK[1]), F_PEAK[1], F_maxr, C_r, mu_r),
)
"""Front and rear axle, in the order of ``FORCES``."""

MODEL = ModelDefinition(
    name="single_track_nonlinear_tyre",
    states=(v_y, r),
    known_inputs=(delta, a_x),
    unknown_inputs=(w_f, w_r),
    dynamics=DYNAMICS_IN_FORCES.subs(_forces),
    outputs=(("a_y", a_y), ("r", r)),
    scheduling=(SchedulingSignal(v_x, "m/s"),),
    parameters=(m, l_f, l_r, I_z, C_f, C_r, mu_f, mu_r, g, brake_front, drive_front, lateral_floor),
    units={"v_y": "m/s", "r": "rad/s", "delta": "rad", "a_x": "m/s^2", "w_f": "-", "w_r": "-", "a_y": "m/s^2",
           "v_x": "m/s",
           # the parameters' units: a value in kN/rad or t where N/rad or kg is meant is refused (dimensions)
           "m": "kg", "l_f": "m", "l_r": "m", "I_z": "kg m^2", "C_f": "N/rad", "C_r": "N/rad", "mu_f": "-",
           "mu_r": "-", "g": "m/s^2", "brake_front": "-", "drive_front": "-", "lateral_floor": "-"},
    parameter_ranges={"brake_front": (0.0, 1.0), "drive_front": (0.0, 1.0), "lateral_floor": (0.0, 1.0, "(]")},
    doc=__doc__,
)
