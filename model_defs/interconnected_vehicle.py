"""Interlinked road-vehicle longitudinal and lateral dynamics of Sentouh et al. 2023, eqs. (1)-(7).

Sentouh, Fouka, Popieul, "Virtual Sensor: Simultaneous State and Input Estimation for Nonlinear
Interconnected Ground Vehicle System Dynamics", Sensors 23, 4236, 2023.

One vehicle model, written once. What belongs to which subsystem of eq. (8) is declared by the
state partition only; :mod:`codegen.families.interconnected_uio.representation` finds everything else from these equations:
which unknown inputs and outputs belong to each subsystem, the coupling signals zeta_F (terms of
one subsystem's equations that are not a premise times one of its own states or inputs), the
premise variables (11) and the 2^q-vertex T-S matrices (9)-(13).

Equations, with the paper's small-steering-angle assumption ("we assume a small variation in the
steering angle under normal driving conditions", Sec. 2: cos(delta) = 1, sin(delta) = 0 in (1)):

    m v_x'      = F_xf + F_xr + m v_y r - F_a - F_rr,           F_a = c_a v_x^2       (1)
    m v_y'      = F_yf + F_yr - m v_x r + F_w                                          (1)
    I_z r'      = l_f F_yf - l_r F_yr + l_w F_w                                        (1)
    I_wf w_f'   = -R F_xf + T_Bf,   I_wr w_r' = -R F_xr + B_r                          (2)
    psi_L'      = r - kappa v_x                                                        (3)
    y_L'        = v_y + l_s r + psi_L v_x - l_s kappa v_x                              (3)*
    delta''     = T_s/(R_s I_s) - t_sb/(R_s I_s) alpha_f - (B_s/I_s) delta'            (4)*
    (sigma/v_x) F_yi' = -F_yi + C_i alpha_i,  (sigma/v_x) F_xi' = -F_xi + C_li lambda_i  (5)
    alpha_f = delta - (v_y + l_f r)/v_x,  alpha_r = -(v_y - l_r r)/v_x                 (6)
    lambda_i = (R w_i - v_x) q_i,  q_i = 1/max(v_x, R w_i)  (traction / braking)       (6)-(7)

Outputs (8): w_f, w_r, a_x (longitudinal); r, psi_L, y_L, a_y, delta (lateral) with the
accelerometer signals m a_x = F_xf + F_xr - F_a - F_rr and m a_y = F_yf + F_yr + F_w, plus
delta_dot, which the observer takes from the HOSMD of delta (see the observer configuration).

(*) Where we depart from the printed equations (also in the README's Sentouh et al. 2023 section):

* (3): the printed y_L' has no -l_s kappa v_x. With y_L the lateral offset seen at the look-ahead
  distance l_s (y_L = y_cg + l_s psi_L), y_L' = (v_y + v_x psi_L) + l_s psi_L', and psi_L' carries
  -kappa v_x; without the term a 100 m bend at 20 m/s biases v_y by l_s kappa v_x = 1 m/s.
* (4): the printed r term, t_sr r/(R_s I_s), has no 1/v_x, which makes it dimensionally a
  different quantity from the v_y/v_x term beside it. We write the aligning torque of the front
  tyre as t_sb alpha_f (the -t_sb delta + t_sb v_y/v_x terms of (4) are exactly that with the
  yaw part -t_sb l_f r/v_x), t_sb = K_p eta_t C_f / R_s as in Nguyen et al. 2019's column.
"""
import sympy as sp

from codegen.families.interconnected_uio.representation import InterconnectedModelDefinition, SwitchedSignal

# longitudinal subsystem (Sigma_x)
v_x, omega_f, omega_r, F_xf, F_xr = sp.symbols("v_x omega_f omega_r F_xf F_xr")
# lateral subsystem (Sigma_y)
v_y, r, psi_L, y_L, F_yf, F_yr, delta, delta_dot = sp.symbols("v_y r psi_L y_L F_yf F_yr delta delta_dot")
# unknown inputs u = [T_Bf, B_r, T_s, kappa]
T_Bf, B_r, T_s, kappa = sp.symbols("T_Bf B_r T_s kappa")
# exogenous forces (rolling resistance, lateral wind): nominal values in the parameter file
F_rr, F_w = sp.symbols("F_rr F_w")
# switched slip signals of eq. (7)
q_f, q_r = sp.symbols("q_f q_r", positive=True)

m, I_z, l_f, l_r, l_s, l_w, R, I_wf, I_wr = sp.symbols("m I_z l_f l_r l_s l_w R I_wf I_wr", positive=True)
C_f, C_r, C_lf, C_lr, sigma, I_s, R_s, B_s, t_sb = sp.symbols("C_f C_r C_lf C_lr sigma I_s R_s B_s t_sb",
                                                            positive=True)
c_a = sp.Symbol("c_a", nonnegative=True)

alpha_f = delta - (v_y + l_f * r) / v_x
alpha_r = -(v_y - l_r * r) / v_x
lambda_f = (R * omega_f - v_x) * q_f
lambda_r = (R * omega_r - v_x) * q_r
F_a = c_a * v_x ** 2

DYNAMICS = {
    v_x: (F_xf + F_xr + m * v_y * r - F_a - F_rr) / m,
    omega_f: (-R * F_xf + T_Bf) / I_wf,
    omega_r: (-R * F_xr + B_r) / I_wr,
    F_xf: (v_x / sigma) * (-F_xf + C_lf * lambda_f),
    F_xr: (v_x / sigma) * (-F_xr + C_lr * lambda_r),
    v_y: (F_yf + F_yr + F_w) / m - v_x * r,
    r: (l_f * F_yf - l_r * F_yr + l_w * F_w) / I_z,
    psi_L: r - kappa * v_x,
    y_L: v_y + l_s * r + psi_L * v_x - l_s * kappa * v_x,
    F_yf: (v_x / sigma) * (-F_yf + C_f * alpha_f),
    F_yr: (v_x / sigma) * (-F_yr + C_r * alpha_r),
    delta: delta_dot,
    delta_dot: T_s / (R_s * I_s) - t_sb / (R_s * I_s) * alpha_f - (B_s / I_s) * delta_dot,
}

UNITS = {"v_x": "m/s", "omega_f": "rad/s", "omega_r": "rad/s", "F_xf": "N", "F_xr": "N", "v_y": "m/s",
         "r": "rad/s", "psi_L": "rad", "y_L": "m", "F_yf": "N", "F_yr": "N", "delta": "rad",
         "delta_dot": "rad/s", "T_Bf": "N m", "B_r": "N m", "T_s": "N m", "kappa": "1/m",
         "a_x": "m/s^2", "a_y": "m/s^2", "F_rr": "N", "F_w": "N",
         # the parameters' units: a value in t, kN/rad or mm where kg, N/rad or m is meant is refused (dimensions)
         "m": "kg", "I_z": "kg m^2", "l_f": "m", "l_r": "m", "l_s": "m", "l_w": "m", "R": "m",
         "I_wf": "kg m^2", "I_wr": "kg m^2", "C_f": "N/rad", "C_r": "N/rad", "C_lf": "N", "C_lr": "N",
         "sigma": "m", "I_s": "kg m^2", "R_s": "-", "B_s": "N m s/rad", "t_sb": "N m/rad", "c_a": "kg/m"}

MODEL = InterconnectedModelDefinition(
    name="interconnected_vehicle",
    subsystems=(("longitudinal", (v_x, omega_f, omega_r, F_xf, F_xr)),
                ("lateral", (v_y, r, psi_L, y_L, F_yf, F_yr, delta, delta_dot))),
    unknown_inputs=(T_Bf, B_r, T_s, kappa),
    exogenous=(F_rr, F_w),
    switched=(SwitchedSignal(q_f, 1 / sp.Max(v_x, R * omega_f),
                             "eq. (7): 1/(R omega_f) in traction (R omega_f > v_x), 1/v_x in braking"),
              SwitchedSignal(q_r, 1 / sp.Max(v_x, R * omega_r),
                             "eq. (7): 1/(R omega_r) in traction, 1/v_x in braking")),
    scheduling_states=(v_x,),
    dynamics=tuple(DYNAMICS.items()),
    outputs=(("omega_f", omega_f), ("omega_r", omega_r), ("a_x", (F_xf + F_xr - F_a - F_rr) / m),
             ("r", r), ("psi_L", psi_L), ("y_L", y_L), ("a_y", (F_yf + F_yr + F_w) / m), ("delta", delta),
             ("delta_dot", delta_dot)),
    parameters=(m, I_z, l_f, l_r, l_s, l_w, R, I_wf, I_wr, C_f, C_r, C_lf, C_lr, sigma, I_s, R_s, B_s, t_sb, c_a),
    units=UNITS,
    doc=__doc__,
)
