"""CommonRoad multi-body plant driven by road-wheel angle and engine torque (Nguyen et al. 2021 observers).

The same independent 29-state ``vehicle_dynamics_mb`` with PAC2002 tyres as
:mod:`codegen.validation.commonroad_plant`, closed differently: Nguyen et al. 2021 treats the steering angle
and the engine torque as the (unknown) inputs, so an automated driver sets them directly:

* steering: :class:`codegen.validation.simulate.AngleDriver` commands δ; a steering servo turns it into the
  plant's steering-velocity input, δ̇ = k_servo (δ_cmd − δ) (first order, 20 rad/s by default);
* longitudinal: the driver's acceleration demand is the plant's a_x input, which the package
  itself converts into engine torque T_E = m R_w a_x (a_x > 0) or brake torque (a_x < 0).

Truth of the paper's "effective engine torque". Nguyen et al. 2021 define T_eng as "the torque input
for the vehicle longitudinal dynamics" (1), v̇_x = (T_eng − C_x v_x²)/I_e + v_y r, so the truth is
that input on this plant: T_eng = I_e (v̇_x − v_y r) (C_x = 0: the plant has no drag), averaged
over each sample interval (the interval the held inputs act on): I_e [(v_x,k+1 − v_x,k)/T_s −
mean(v_y r)], with I_e = m R_w of the same car (:func:`ts_params_toml`). The multi-body model's
own longitudinal balance, m (v̇_x − v_y r) = ΣF_x,rear + ΣF_x,front cos δ − ΣF_y,front sin δ, with
the wheel spin I_y,w ω̇ = T − R_w F_x, splits it exactly into

    T_eng = T_drive − T_wheels − T_steer,

T_drive = m R_w a_x the drive/brake torque the package applies at the wheels (the plant's input;
the earlier truth), T_wheels = I_y,w Σ ω̇ the torque that spins the four wheels up, and T_steer =
R_w [ΣF_y,front sin δ + ΣF_x,front (1 − cos δ)] the steered wheels' forces projected on the body x
axis; all three are returned (interval means, from the states: T_wheels = I_y,w Σ Δω / T_s).
Truth v_y, r, δ are the plant's states (body frame, sprung-mass CoG).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import SampleError
from .simulate import rk4_step
from .commonroad_plant import VEHICLE_NAMES, PlantError, _Plant, PlantConfig, _static_loads, \
    tyre_cornering_stiffness, vehicle_parameters

SERVO_GAIN = 20.0     # rad/s, steering servo bandwidth
CAMBER_TERMS = ("p_hy1", "p_hy3", "p_vy1", "p_vy3", "p_dy3", "r_vy3")   # PAC2002 lateral camber terms


def ts_params_toml(vehicle: int = 2) -> str:
    """Parameter file of the Nguyen et al. 2021 model (1)/(3) for CommonRoad vehicle ``vehicle``.

    Mass, yaw inertia, axle distances from the set; per-tyre cornering stiffness from the PAC2002
    slope at zero slip and static load; I_e = m R_w (the package's torque conversion); no drag;
    D_x of Nguyen et al. 2021 eq. (5).
    """
    p = vehicle_parameters(vehicle)
    fzf, fzr = _static_loads(p)
    cf, cr = tyre_cornering_stiffness(p, fzf), tyre_cornering_stiffness(p, fzr)
    return f"""# CommonRoad parameter set {vehicle} ({VEHICLE_NAMES[vehicle]}) for the Nguyen et al. 2021 model, derived by
# codegen.validation.commonroad_angle.ts_params_toml. Do not edit by hand (a test regenerates it).

[meta]
source = "commonroad-vehicle-models parameters_vehicle{vehicle}; D_x of Nguyen et al. 2021 eq. (5)"
commonroad_vehicle = "{vehicle}"
car = "{VEHICLE_NAMES[vehicle]} (CommonRoad vehicle {vehicle})"

[parameters]
M = {p.m!r}        # kg, vehicle mass
l_f = {p.a!r}        # m, CoG to front axle
l_r = {p.b!r}        # m, CoG to rear axle
I_e = {p.m * p.R_w!r}        # kg m, m R_w: the package converts a_x into torque as m R_w a_x
I_z = {p.I_z!r}        # kg m^2, yaw inertia (sprung mass, as vehicle_dynamics_mb)
C_f = {cf!r}        # N/rad per tyre, PAC2002 slope at F_z = {fzf:.1f} N
C_r = {cr!r}        # N/rad per tyre, PAC2002 slope at F_z = {fzr:.1f} N
C_x = 0.0        # the multi-body model has no aerodynamic drag
C_y = 0.0

[state_bounds]
v_x = [5.0, 30.0]     # m/s, Nguyen et al. 2021 eq. (5)
v_y = [-1.5, 1.5]     # m/s
r = [-0.55, 0.55]     # rad/s

[plausibility]
# C_x has the dimension of a mass (N m per (m/s)^2, a drag torque coefficient), not the value of one
accept = ["C_x"]
"""


def simulate(scenario, vehicle: int = 2, sample_rate: float = 100.0, dt_internal: float = 1e-3,
             progress=None, roll_stiffness_scale: float = 1.0, camber_force: bool = True) -> dict:
    """Run ``scenario`` on the multi-body plant with angle steering; truth per output sample.

    Returns a dict with t, v_x, v_y, r, delta, T_eng (the effective torque of the module
    docstring), T_drive, T_wheels, T_steer, a_y, mu, roll (sprung-mass roll angle) (SI units).
    ``roll_stiffness_scale`` multiplies the anti-roll bars' torsional stiffness (K_tsf, K_tsr):
    an ablation knob (100 leaves a stiffer body, same loads and tyres). ``camber_force=False`` is the
    other: the tyres' lateral force as at zero camber (PAC2002's camber terms p_hy1, p_hy3, p_vy1,
    p_vy3, p_dy3, r_vy3 set to 0; the package multiplies the offsets p_hy1, p_vy1 by sgn(γ), so
    any roll at all brings them in).

    Raises
    ------
    SampleError, PlantError
    """
    from vehiclemodels.init_mb import init_mb
    from .simulate import AngleDriver
    if abs(scenario.sample_rate - sample_rate) > 1e-9:
        raise SampleError(f"scenario sampled at {scenario.sample_rate} Hz, plant outputs at {sample_rate} Hz")
    if not roll_stiffness_scale > 0:
        raise PlantError(f"roll_stiffness_scale must be positive, got {roll_stiffness_scale!r}")
    plant = _Plant(PlantConfig(vehicle=vehicle, sample_rate=sample_rate, dt_internal=dt_internal))
    p = plant.p
    p.K_tsf, p.K_tsr = p.K_tsf * roll_stiffness_scale, p.K_tsr * roll_stiffness_scale
    if not camber_force:
        for key in CAMBER_TERMS:
            setattr(p.tire, key, 0.0)
    i_e = p.m * p.R_w
    n = scenario.t.size
    sub = int(round(1.0 / (sample_rate * dt_internal)))
    h = dt_internal
    v0 = float(scenario.v_ref[0])
    k0 = 0.0 if scenario.kappa_ref is None else float(scenario.kappa_ref[0])
    z = np.array(init_mb([0.0, 0.0, (p.a + p.b) * k0, v0, 0.0, v0 * k0, 0.0], p), dtype=float)
    driver = AngleDriver(scenario, p.a + p.b, 1.0 / sample_rate)
    driver.preload(z[2])
    dmax = min(abs(p.steering.min), abs(p.steering.max))
    from vehiclemodels.utils.acceleration_constraints import acceleration_constraints

    def rhs(x, rate, a_x):
        return np.array(plant._f(list(x), [rate, a_x], p))

    out = {k: np.empty(n) for k in ("t", "v_x", "v_y", "r", "delta", "T_eng", "T_drive", "T_wheels", "T_steer",
                                    "a_y", "mu", "roll")}
    for k in range(n):
        if progress is not None and (k % max(n // 50, 1) == 0 or k == n - 1):
            progress((k + 1) / n)
        plant.set_mu(float(scenario.friction(scenario.t[k], z[0], z[1])))
        delta_cmd, a_dem = driver(k, z[0], z[1], z[4], z[3], z[10], z[5])
        a_x = acceleration_constraints(z[3], a_dem, p.longitudinal)   # what the plant applies
        rate = SERVO_GAIN * (delta_cmd - z[2])
        dz = rhs(z, rate, a_x)
        out["t"][k] = scenario.t[k]
        out["v_x"][k], out["v_y"][k], out["r"][k], out["delta"][k] = z[3], z[10], z[5], z[2]
        out["T_drive"][k] = i_e * a_x
        out["a_y"][k] = dz[10] + z[5] * z[3]
        out["mu"][k] = plant.mu
        out["roll"][k] = z[6]
        if k == n - 1:      # no interval left: the instantaneous values
            out["T_eng"][k] = i_e * (dz[3] - z[10] * z[5])
            out["T_wheels"][k] = p.I_y_w * float(np.sum(dz[23:27]))
            out["T_steer"][k] = out["T_drive"][k] - out["T_wheels"][k] - out["T_eng"][k]
            break
        z0, vyr = z, 0.5 * z[10] * z[5]
        for j in range(sub):
            # the servo acts continuously on the held command; the torque demand is held
            z = rk4_step(lambda zs: rhs(zs, SERVO_GAIN * (delta_cmd - zs[2]), a_x), z, h)
            vyr += z[10] * z[5] * (0.5 if j == sub - 1 else 1.0)
        ts = sub * h
        out["T_eng"][k] = i_e * ((z[3] - z0[3]) / ts - vyr / sub)      # trapezoid mean of v_y r
        out["T_wheels"][k] = p.I_y_w * float(np.sum(z[23:27] - z0[23:27])) / ts
        out["T_steer"][k] = out["T_drive"][k] - out["T_wheels"][k] - out["T_eng"][k]
        if not np.all(np.isfinite(z)):
            raise PlantError(f"{scenario.name}: non-finite plant state at t = {scenario.t[k]:.3f} s")
        if abs(z[2]) >= dmax or z[3] < 1.0 or math.isnan(z[3]):
            raise PlantError(f"{scenario.name}: steering stop or speed below 1 m/s at t = {scenario.t[k]:.3f} s")
    return out
