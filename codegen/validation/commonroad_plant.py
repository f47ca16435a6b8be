"""CommonRoad multi-body plant (``vehicle_dynamics_mb``, PAC2002 tyres) driven by steering torques.

The plant is independent of every uiogen model: 29-state multi-body vehicle of
``commonroad-vehicle-models`` (Althoff & Würsching, "CommonRoad: Vehicle Models", 2020) with its
PAC2002 magic-formula tyres (pure and combined slip). Its inputs are the front-wheel steering
*velocity* and a longitudinal acceleration demand; we close both:

* **steering column** of the form of Nguyen et al. 2019 eq. (2), written for the road-wheel angle δ
  (δ_d = R_s δ)::

      I_s R_s δ̈ = T_d + T_a - B_s R_s δ̇ + T_al,     T_al = -K_p M_z / R_s

  where M_z = Σ_{front tyres} t_p(α_i) F_y,i is the kingpin aligning moment computed from the
  **plant's own** front slip angles α_i and the PAC2002 pure-slip lateral force at the plant's
  vertical load, times a pneumatic trail that falls linearly with slip (brush-model
  approximation, Hsu, Laws & Gerdes, IEEE T-CST 18(6), 2010, eq. (5))::

      t_p(α) = η_t (1 - |tan α| / tan α_sl)  for |tan α| < tan α_sl,  else 0
      tan α_sl = 3 μ_y F_z / C_α = 3 μ_y / |p_ky1|

  With t_p ≡ η_t and a linear tyre this is exactly the -T_sβ/R_s (δ - β - l_f r / v_x) term of
  eq. (2). δ̇ of the column is the plant's steering-velocity input (one shared δ: the plant's
  state x[2] *is* the column angle). The package's steering-rate limit (±0.4 rad/s) is lifted,
  since the column dynamics are the physical limit; the angle limit is kept and hitting it
  raises :class:`PlantError`.
* **speed controller**: a_cmd = dv_ref/dt + k_v (v_ref - v_x), clipped by the package's own
  acceleration constraints.

Inputs come from a :class:`codegen.validation.scenarios.Scenario` (driver torque either an array
or a closed-loop driver model, assistance torque, speed profile, road friction). Integration:
classical RK4 at ``dt_internal`` (1 ms default) with the torques held over each output sample.

CommonRoad API facts used here (commonroad-vehicle-models 3.0.2):
``vehicle_dynamics_mb(x, u, p)`` returns the 29 derivatives for
``x = [X, Y, δ, v_x, ψ, r, φ, φ̇, θ, θ̇, v_y, z, ż, φ_f, φ̇_f, v_y,f, z_f, ż_f, φ_r, φ̇_r, v_y,r,
z_r, ż_r, ω_LF, ω_RF, ω_LR, ω_RR, Δy_f, Δy_r]`` (v_x, v_y in the body frame, CoG of the sprung
mass) and ``u = [δ̇, a_x]``; ``init_mb([X, Y, δ, v, ψ, r, β], p)`` gives a static-equilibrium
state. Parameters are plain dataclasses (``parameters_vehicle1/2/3()``: Ford Escort, BMW 320i,
VW Vanagon) with fields ``m, m_s, m_uf, m_ur, a`` (CoG-front axle), ``b`` (CoG-rear), ``I_z,
R_w, T_f, T_r, K_zt, ...``, sub-structures ``steering`` (min, max, v_min, v_max),
``longitudinal`` (a_max, v_switch, v_min, v_max) and ``tire`` (PAC2002 coefficients ``p_ky1,
p_dy1, p_cy1, ...``). Note its slip angle sign: α_CR = atan(...) - δ = -α (conventional).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ModelDefinitionError, PlantError, SampleError
from .simulate import rk4_step

VEHICLE_NAMES = {1: "Ford Escort", 2: "BMW 320i", 3: "VW Vanagon"}   # CommonRoad parameter sets

__all__ = [
    "PlantError", "ColumnParams", "TABLE1_COLUMN", "PlantConfig", "GroundTruth", "vehicle_parameters",
    "tyre_cornering_stiffness", "params_toml", "simulate", "pneumatic_trail", "RollCamber", "roll_camber",
    "camber_force_coefficients",
]

G = 9.81


@dataclass(frozen=True)
class ColumnParams:
    """Steering-column parameters of Nguyen et al. 2019 Table I (eq. (2)).

    Attributes
    ----------
    R_s : float
        Steering gear ratio [-].
    B_s : float
        Column damping [N m s/rad] (handwheel side).
    K_p : float
        Manual steering column coefficient [-].
    I_s : float
        Column inertia [kg m²] (handwheel side).
    eta_t : float
        Pneumatic trail at zero slip (Table I "tyre contact length") [m].
    """

    R_s: float = 16.0
    B_s: float = 5.73
    K_p: float = 0.5
    I_s: float = 0.05
    eta_t: float = 0.13

    def __post_init__(self):
        for k in ("R_s", "B_s", "K_p", "I_s", "eta_t"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ModelDefinitionError(f"column parameter {k} must be finite and > 0, got {v!r}")


TABLE1_COLUMN = ColumnParams()
"""Nguyen et al. 2019 Table I column values."""


@dataclass(frozen=True)
class PlantConfig:
    """Plant settings.

    Attributes
    ----------
    vehicle : int
        CommonRoad parameter set 1, 2 or 3 (Ford Escort, BMW 320i, VW Vanagon).
    column : ColumnParams
        Steering column.
    sample_rate : float
        Ground-truth output rate [Hz] (torques and driver model are held over one sample).
    dt_internal : float
        RK4 step [s]; must divide 1/sample_rate.
    speed_gain : float
        k_v of the speed controller [1/s].
    """

    vehicle: int = 2
    column: ColumnParams = field(default_factory=ColumnParams)
    sample_rate: float = 100.0
    dt_internal: float = 1e-3
    speed_gain: float = 1.0

    def __post_init__(self):
        if self.vehicle not in (1, 2, 3):
            raise ModelDefinitionError(f"CommonRoad vehicle must be 1, 2 or 3, got {self.vehicle!r}")
        if not (self.sample_rate > 0 and self.dt_internal > 0 and self.speed_gain >= 0):
            raise ModelDefinitionError("sample_rate, dt_internal must be > 0, speed_gain >= 0")
        ratio = 1.0 / (self.sample_rate * self.dt_internal)
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ModelDefinitionError(
                f"dt_internal={self.dt_internal} does not divide the sample period {1 / self.sample_rate}")


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Plant ground truth per output sample (SI units, road-wheel angles, body frame at the CoG).

    Attributes
    ----------
    t, v_x, v_y, beta, r, delta, delta_dot, a_x, a_y, T_d, T_a : ndarray
        Time, speeds, sideslip atan(v_y/v_x), yaw rate, road-wheel angle and rate, accelerations
        (a_x = v̇_x - r v_y, a_y = v̇_y + r v_x), driver and assistance torque [N m].
    T_al : ndarray
        Aligning torque at the handwheel [N m] (the column's tyre feedback).
    alpha_f : ndarray
        Mean conventional front slip angle [rad].
    camber_f : ndarray
        Mean front wheel camber, the package's signs [rad].
    X, Y, psi : ndarray
        Global position [m] and yaw angle [rad].
    mu : ndarray
        Friction scale applied to the tyres (1 = the tyre's nominal coefficients).
    roll, roll_rate : ndarray
        Sprung-mass roll angle x[6] [rad] and rate x[7] [rad/s] of ``vehicle_dynamics_mb``, in the
        package's sign convention (negative in a left turn: its roll moment from the lateral joint
        forces is -F_RA (h_s - h_ra)).
    """

    t: np.ndarray
    v_x: np.ndarray
    v_y: np.ndarray
    beta: np.ndarray
    r: np.ndarray
    delta: np.ndarray
    delta_dot: np.ndarray
    a_x: np.ndarray
    a_y: np.ndarray
    T_d: np.ndarray
    T_a: np.ndarray
    T_al: np.ndarray
    alpha_f: np.ndarray
    camber_f: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    psi: np.ndarray
    mu: np.ndarray
    roll: np.ndarray
    roll_rate: np.ndarray


def vehicle_parameters(vehicle: int = 2):
    """Fresh CommonRoad parameter object of set 1, 2 or 3 (a private copy, safe to modify)."""
    if vehicle not in (1, 2, 3):
        raise ModelDefinitionError(f"CommonRoad vehicle must be 1, 2 or 3, got {vehicle!r}")
    import importlib
    mod = importlib.import_module(f"vehiclemodels.parameters_vehicle{vehicle}")
    return copy.deepcopy(getattr(mod, f"parameters_vehicle{vehicle}")())


def _static_loads(p):
    """Static vertical load per tyre, front and rear [N] (as ``init_mb``)."""
    fzf = (p.m_s * G * p.b / (p.a + p.b) + p.m_uf * G) / 2.0
    fzr = (p.m_s * G * p.a / (p.a + p.b) + p.m_ur * G) / 2.0
    return fzf, fzr


def tyre_cornering_stiffness(p, fz: float, h: float = 1e-5) -> float:
    """Linear slope dF_y/dα of the PAC2002 pure-slip lateral force at α = 0, γ = 0 [N/rad].

    Central difference of ``tire_model.formula_lateral`` (positive number, conventional sign);
    equals |p_ky1| F_z for these tyres.
    """
    from vehiclemodels.utils import tire_model
    fp = tire_model.formula_lateral(h, 0.0, fz, p.tire)[0]
    fm = tire_model.formula_lateral(-h, 0.0, fz, p.tire)[0]
    return abs((fp - fm) / (2 * h))


@dataclass(frozen=True)
class RollCamber:
    """Quasi-static roll and camber of a CommonRoad multi-body parameter set.

    Attributes
    ----------
    roll_gradient : float
        |body roll| per lateral acceleration [rad/(m/s²)] (the body rolls out of the turn).
    camber_per_roll_f, camber_per_roll_r : float
        Wheel camber per body roll, front and rear axle [-] (same sign as the roll when > 0).
    """

    roll_gradient: float
    camber_per_roll_f: float
    camber_per_roll_r: float


def roll_camber(p) -> RollCamber:
    """Steady roll of ``vehicle_dynamics_mb`` under a lateral acceleration, from its parameters.

    The sprung mass m_s (CoG at h_s, roll axes at the ground: h_raf = h_rar = 0 in all three
    sets) rolls against each axle's suspension roll stiffness (springs K_s at ±T/2 and the
    torsion term K_ts of the package's F_S equations: k_s = K_s T²/2 - K_ts) in series with the
    tyres' vertical stiffness (K_zt T²/2), less the gravity moment m_s g h_s:

        |φ| / a_y = m_s h_s / (k_f + k_r - m_s g h_s),   k = (1/k_s + 1/k_t)^-1.

    Camber (``gamma = φ ± D z_S``, z_S = ±T/2 times the suspension's share k/k_s of the roll)
    per body roll: g = 1 + D T k / (2 k_s).
    """
    if p.h_raf != 0 or p.h_rar != 0 or p.E_f != 0 or p.E_r != 0:
        raise ModelDefinitionError("roll_camber assumes roll axes at the ground and linear camber "
                                   "kinematics (h_raf = h_rar = E_f = E_r = 0, as in sets 1-3)")
    k_sf = 0.5 * p.T_f ** 2 * p.K_sf - p.K_tsf
    k_sr = 0.5 * p.T_r ** 2 * p.K_sr - p.K_tsr
    k_f = 1.0 / (1.0 / k_sf + 1.0 / (0.5 * p.T_f ** 2 * p.K_zt))
    k_r = 1.0 / (1.0 / k_sr + 1.0 / (0.5 * p.T_r ** 2 * p.K_zt))
    gradient = p.m_s * p.h_s / (k_f + k_r - p.m_s * G * p.h_s)
    return RollCamber(gradient, 1.0 + 0.5 * p.D_f * p.T_f * k_f / k_sf, 1.0 + 0.5 * p.D_r * p.T_r * k_r / k_sr)


def camber_force_coefficients(tire) -> tuple:
    """(c0, c1) of the package's PAC2002 at zero slip: a wheel cambered against the turn
    (gamma of sign opposite to a_y) adds F_z (c0 + c1 |gamma|) to the cornering force.

    From ``formula_lateral``: S_Hy = sgn(γ)(p_hy1 + p_hy3|γ|), S_Vy = sgn(γ) F_z (p_vy1 +
    p_vy3|γ|), K_y = p_ky1 F_z, so F_y(0, γ) = sgn(γ) F_z [(p_ky1 p_hy1 + p_vy1) +
    (p_ky1 p_hy3 + p_vy3)|γ|] (small slip).
    """
    return -(tire.p_ky1 * tire.p_hy1 + tire.p_vy1), -(tire.p_ky1 * tire.p_hy3 + tire.p_vy3)


def params_toml(vehicle: int = 2, column: ColumnParams = TABLE1_COLUMN, a_s: float = 0.1) -> str:
    """The parameter file of ``model_defs/steering_single_track_camber.py`` for a CommonRoad car.

    Mass, yaw inertia and axle distances from the CommonRoad set; per-tyre cornering stiffness
    C_f, C_r from the PAC2002 linear slope at zero slip and the static tyre load; steering-column
    values from ``column`` (Table I by default). Yaw inertia: ``p.I_z`` (sprung-mass yaw inertia,
    the one ``vehicle_dynamics_mb`` uses). Roll camber: :func:`roll_camber` and
    :func:`camber_force_coefficients` give the camber thrust per lateral acceleration of each
    axle, k = 2 F_z c1 g |φ|/a_y, and its camber offset F_c = 2 F_z c0 (sign of g); the tyre's
    shape factors are the PAC2002 p_dy1, p_cy1, p_ey1. ``a_s`` is the width of the ramp that
    stands for sgn(a_y) [m/s²]. The [scheduling] block is that of Table I's file.
    """
    p = vehicle_parameters(vehicle)
    fzf, fzr = _static_loads(p)
    cf, cr = tyre_cornering_stiffness(p, fzf), tyre_cornering_stiffness(p, fzr)
    rc = roll_camber(p)
    c0, c1 = camber_force_coefficients(p.tire)
    k_f = 2 * fzf * c1 * rc.camber_per_roll_f * rc.roll_gradient
    k_r = 2 * fzr * c1 * rc.camber_per_roll_r * rc.roll_gradient
    F_cf = 2 * fzf * c0 * math.copysign(1.0, rc.camber_per_roll_f)
    F_cr = 2 * fzr * c0 * math.copysign(1.0, rc.camber_per_roll_r)
    return f"""# CommonRoad parameter set {vehicle} ({VEHICLE_NAMES[vehicle]}), derived by codegen.validation.commonroad_plant.
# Steering column: Nguyen et al. 2019 Table I. Cornering stiffness: PAC2002 slope at zero slip, static load.
# Roll camber: quasi-static roll of the multi-body model ({math.degrees(rc.roll_gradient):.3f} deg per m/s^2),
# camber per roll {rc.camber_per_roll_f:.4f} (front) / {rc.camber_per_roll_r:.4f} (rear), PAC2002 camber terms.

[meta]
source = "commonroad-vehicle-models parameters_vehicle{vehicle} + Nguyen et al. 2019 Table I column"
commonroad_vehicle = "{vehicle}"
car = "{VEHICLE_NAMES[vehicle]} (CommonRoad vehicle {vehicle})"

[parameters]
l_f = {p.a!r}        # m, CoG to front axle
l_r = {p.b!r}        # m, CoG to rear axle
eta_t = {column.eta_t!r}        # m, tyre contact length (pneumatic trail)
R_s = {column.R_s!r}        # -, steering gear ratio
B_s = {column.B_s!r}        # N m s/rad, steering system damping
K_p = {column.K_p!r}        # -, manual steering column coefficient
M = {p.m!r}        # kg, vehicle mass
I_z = {p.I_z!r}        # kg m^2, yaw inertia
I_s = {column.I_s!r}        # kg m^2, steering system inertia
C_f = {cf!r}        # N/rad, front cornering stiffness (per tyre; F_z = {fzf:.1f} N)
C_r = {cr!r}        # N/rad, rear cornering stiffness (per tyre; F_z = {fzr:.1f} N)
k_f = {k_f!r}        # N/(m/s^2), front camber thrust per lateral acceleration
k_r = {k_r!r}        # N/(m/s^2), rear camber thrust per lateral acceleration
F_cf = {F_cf!r}        # N, front camber offset (PAC2002 sgn(gamma) shifts)
F_cr = {F_cr!r}        # N, rear camber offset
F_zf = {2 * fzf!r}        # N, static front axle load
F_zr = {2 * fzr!r}        # N, static rear axle load
mu_y = {p.tire.p_dy1!r}        # -, PAC2002 p_dy1 (peak friction)
C_y = {p.tire.p_cy1!r}        # -, PAC2002 p_cy1 (shape factor)
E_y = {p.tire.p_ey1!r}        # -, PAC2002 p_ey1 (curvature factor)
a_s = {a_s!r}        # m/s^2, width of the ramp standing for sgn(a_y) (a few times the v_x y_r noise)

[scheduling.v_x]
min = 5.0        # m/s
max = 35.0       # m/s
rate_min = -4.0  # m/s^2
rate_max = 4.0
"""


def pneumatic_trail(alpha, eta_t: float, tan_alpha_sl: float):
    """Linear-falling pneumatic trail (Hsu, Laws & Gerdes 2010, eq. (5)) [m]."""
    ta = abs(math.tan(alpha))
    return eta_t * (1.0 - ta / tan_alpha_sl) if ta < tan_alpha_sl else 0.0


class _Plant:
    """Internal: the augmented state z = (x_mb[0:29], δ̇) and its right-hand side."""

    def __init__(self, cfg: PlantConfig):
        from vehiclemodels.vehicle_dynamics_mb import vehicle_dynamics_mb
        from vehiclemodels.utils import tire_model
        self._f = vehicle_dynamics_mb
        self._lat = tire_model.formula_lateral
        self.cfg = cfg
        self.p = vehicle_parameters(cfg.vehicle)
        self.p.steering.v_min, self.p.steering.v_max = -1e6, 1e6   # column is the rate limit
        self.p_dy1 = self.p.tire.p_dy1
        self.p_dx1 = self.p.tire.p_dx1
        self.mu = 1.0

    def set_mu(self, mu: float) -> None:
        self.mu = mu
        self.p.tire.p_dy1 = self.p_dy1 * mu
        self.p.tire.p_dx1 = self.p_dx1 * mu

    def aligning(self, x):
        """(T_al at handwheel [N m], mean conventional front slip angle [rad])."""
        p, col = self.p, self.cfg.column
        if abs(x[3]) < 0.1:
            return 0.0, 0.0
        tsl = 3.0 * abs(self.p.tire.p_dy1) / abs(p.tire.p_ky1)
        mz, al = 0.0, 0.0
        for side in (1.0, -1.0):
            a = x[2] - math.atan((x[10] + p.a * x[5] - x[14] * (p.R_w - x[16]))
                                 / (x[3] + side * 0.5 * p.T_f * x[5]))
            fz = (x[16] + p.R_w * (math.cos(x[13]) - 1) - side * 0.5 * p.T_f * math.sin(x[13])) * p.K_zt
            fy = self._lat(-a, 0.0, max(fz, 0.0), p.tire)[0]      # CommonRoad's α is -α
            mz += pneumatic_trail(a, col.eta_t, tsl) * fy
            al += 0.5 * a
        return -col.K_p * mz / col.R_s, al

    def front_camber(self, x) -> float:
        """Mean camber of the front wheels (``gamma_LF``, ``gamma_RF`` of ``vehicle_dynamics_mb``)."""
        p = self.p
        base = (p.h_s - p.R_w + x[16] - x[11]) / math.cos(x[6]) - p.h_s + p.R_w + p.a * x[8]
        z_l, z_r = base + 0.5 * (x[6] - x[13]) * p.T_f, base - 0.5 * (x[6] - x[13]) * p.T_f
        return 0.5 * ((x[6] + p.D_f * z_l + p.E_f * z_l ** 2) + (x[6] - p.D_f * z_r - p.E_f * z_r ** 2))

    def rhs(self, z, torque, a_cmd):
        x = list(z[:29])
        f = self._f(x, [z[29], a_cmd], self.p)
        col = self.cfg.column
        t_al, _ = self.aligning(z)
        dd = (torque + t_al - col.B_s * col.R_s * z[29]) / (col.I_s * col.R_s)
        return np.array(f + [dd])


def _measure(z):
    return {"X": z[0], "Y": z[1], "delta": z[2], "v_x": z[3], "psi": z[4], "r": z[5],
            "v_y": z[10], "delta_dot": z[29]}


def simulate(scenario, cfg: PlantConfig = PlantConfig(), progress=None) -> GroundTruth:
    """Run a scenario on the CommonRoad multi-body plant.

    Parameters
    ----------
    scenario : codegen.validation.scenarios.Scenario
        Provides ``t`` (output grid), ``v_ref``, ``a_ref``, ``T_a``, ``make_driver()`` (a fresh
        callable ``(k, meas) -> T_d``) and ``friction(t, X, Y)``; its ``sample_rate`` must equal ``cfg.sample_rate``.
    cfg : PlantConfig, optional
    progress : callable, optional
        Called with the fraction done (0-1] about 50 times: a progress bar for long campaigns.

    Returns
    -------
    GroundTruth

    Raises
    ------
    SampleError
        Scenario sampled at another rate than the plant's output rate.
    PlantError
        Steering stop reached, speed below 1 m/s, or a non-finite state.
    """
    from vehiclemodels.init_mb import init_mb
    if abs(scenario.sample_rate - cfg.sample_rate) > 1e-9:
        raise SampleError(f"scenario sampled at {scenario.sample_rate} Hz, plant outputs at "
                          f"{cfg.sample_rate} Hz")
    plant = _Plant(cfg)
    n = scenario.t.size
    sub = int(round(1.0 / (cfg.sample_rate * cfg.dt_internal)))
    h = cfg.dt_internal
    v0 = float(scenario.v_ref[0])
    k0 = 0.0 if scenario.kappa_ref is None else float(scenario.kappa_ref[0])
    # start in (kinematic) steady cornering when the path starts curved: δ0 = L κ0, r0 = v0 κ0
    z = np.array(init_mb([0.0, 0.0, (plant.p.a + plant.p.b) * k0, v0, 0.0, v0 * k0, 0.0], plant.p)
                 + [0.0])
    out = {k: np.empty(n) for k in GroundTruth.__dataclass_fields__}
    dmax = min(abs(plant.p.steering.min), abs(plant.p.steering.max))
    driver = scenario.make_driver()
    if hasattr(driver, "preload"):          # driver already holds the wheel against T_al
        plant.set_mu(float(scenario.friction(0.0, z[0], z[1])))
        driver.preload(-plant.aligning(z)[0] - float(scenario.T_a[0]))
    for k in range(n):
        if progress is not None and (k % max(n // 50, 1) == 0 or k == n - 1):
            progress((k + 1) / n)
        tk = scenario.t[k]
        meas = _measure(z)
        plant.set_mu(float(scenario.friction(tk, z[0], z[1])))
        t_d = float(driver(k, meas))
        t_a = float(scenario.T_a[k])
        a_cmd = float(scenario.a_ref[k] + cfg.speed_gain * (scenario.v_ref[k] - z[3]))
        torque = t_d + t_a
        dz = plant.rhs(z, torque, a_cmd)
        t_al, alf = plant.aligning(z)
        out["t"][k] = tk
        out["v_x"][k], out["v_y"][k], out["r"][k] = z[3], z[10], z[5]
        out["beta"][k] = math.atan2(z[10], z[3])
        out["delta"][k], out["delta_dot"][k] = z[2], z[29]
        out["a_x"][k] = dz[3] - z[5] * z[10]
        out["a_y"][k] = dz[10] + z[5] * z[3]
        out["T_d"][k], out["T_a"][k], out["T_al"][k], out["alpha_f"][k] = t_d, t_a, t_al, alf
        out["X"][k], out["Y"][k], out["psi"][k], out["mu"][k] = z[0], z[1], z[4], plant.mu
        out["roll"][k], out["roll_rate"][k], out["camber_f"][k] = z[6], z[7], plant.front_camber(z)
        if k == n - 1:
            break
        for _ in range(sub):
            z = rk4_step(lambda zs: plant.rhs(zs, torque, a_cmd), z, h)
        if not np.all(np.isfinite(z)):
            raise PlantError(f"{scenario.name}: non-finite plant state at t = {tk:.3f} s")
        if abs(z[2]) >= dmax:
            raise PlantError(f"{scenario.name}: steering stop |δ| = {dmax} rad reached at t = {tk:.3f} s")
        if z[3] < 1.0:
            raise PlantError(f"{scenario.name}: speed fell below 1 m/s at t = {tk:.3f} s")
    for a in out.values():
        a.setflags(write=False)
    return GroundTruth(**out)
