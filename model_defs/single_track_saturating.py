"""Single-track lateral dynamics with axle stiffness scheduled on the measured tyre utilization.

Linear single-track model (Nguyen et al. 2019 eq. (4), axle forces F_y = s C alpha) whose axle cornering
stiffnesses C_f, C_r are scaled by the Fiala (brush) tyre's *secant* ratio s at the force
utilization eta = |a_y|/(mu g): at a static load split both axles use the same fraction of their
grip, and for the Fiala tyre F/(mu F_z) = z - z^2/3 + z^3/27 with z = C|alpha|/(mu F_z), whose
inverse gives the closed form

    s = F/(C alpha) = (1 + c + c^2)/3,   c = (1 - eta)^(1/3),   s in [1/3, 1]

(no cancellation at small eta). s is computed from the measured a_y inside the observer step,
so the model stays linear in the states with measured scheduling signals (v_x, s), as in the
papers' LPV method. States x = [beta, r], known input delta (road-wheel angle), unknown input M_z
(yaw-moment disturbance: load transfer, drive torque split, aero), outputs y = [r, a_y].
"""
import sympy as sp

from codegen.model import ModelDefinition, SchedulingSignal

beta, r = sp.symbols("beta r")
delta, M_z = sp.symbols("delta M_z")
v_x = sp.Symbol("v_x", positive=True)
s = sp.Symbol("s", positive=True)
m, l_f, l_r, I_z, C_f, C_r, mu, g = sp.symbols("m l_f l_r I_z C_f C_r mu g", positive=True)
y_a_y = sp.Symbol("y_a_y")

alpha_f = delta - beta - l_f * r / v_x
alpha_r = l_r * r / v_x - beta
F_f = s * C_f * alpha_f            # axle forces, F_y = C alpha per axle (data README convention)
F_r = s * C_r * alpha_r

utilization = sp.Min(sp.Abs(y_a_y) / (mu * g), 1)
cube_root = (1 - utilization) ** sp.Rational(1, 3)
secant = (1 + cube_root + cube_root ** 2) / 3

MODEL = ModelDefinition(
    name="single_track_saturating",
    states=(beta, r),
    known_inputs=(delta,),
    unknown_inputs=(M_z,),
    dynamics=sp.Matrix([
        (F_f + F_r) / (m * v_x) - r,
        (l_f * F_f - l_r * F_r + M_z) / I_z,
    ]),
    outputs=(("r", r), ("a_y", (F_f + F_r) / m)),
    scheduling=(SchedulingSignal(v_x, "m/s"), SchedulingSignal(s, "-", derived=secant)),
    parameters=(m, l_f, l_r, I_z, C_f, C_r, mu, g),
    units={"beta": "rad", "r": "rad/s", "delta": "rad", "M_z": "N m", "a_y": "m/s^2", "v_x": "m/s", "s": "-"},
    doc=__doc__,
)
