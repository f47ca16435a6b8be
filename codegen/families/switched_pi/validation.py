"""Menhour et al. 2014 validation: the roll/bank Pacejka truth plant and the CommonRoad roll signals.

* :func:`roll_params_toml` derives the parameter file of the roll-augmented single-track model
  (``model_defs/params/commonroad_bmw320i_roll.toml``) from a CommonRoad parameter set, number by
  number (formulas in the file's comments and below);
* :func:`banked_plant` integrates the truth plant ``PLANT`` of ``model_defs/roll_single_track.py``
  (roll and road bank with their gravity components in the lateral force and roll moment
  balances, magic-formula axles with load-proportional stiffness, load transfer, friction ellipse)
  in closed loop with a path-following driver that sets the road-wheel angle, on a scenario's
  speed, curvature and bank profiles;
* :func:`commonroad_truth` runs the CommonRoad multi-body plant (flat roads: it has roll, no bank)
  at the observer's rate and returns the same signals, with roll in the paper's sign convention.
"""
from __future__ import annotations

import math

import numpy as np
import sympy as sp

from ...errors import ModelDefinitionError, SampleError
from ...validation.common import SETTLE_TIME, signal_stats, truncate

G = 9.81


def roll_equivalents(p) -> dict:
    """Linear roll parameters of the CommonRoad multi-body model ``vehicle_dynamics_mb``.

    * K_r: per axle, the suspension springs at +-T/2 (K_s T^2 / 2) and the auxiliary torsion
      spring (-K_ts, the package's sign) in series with the tyres' vertical stiffness at +-T/2
      (K_zt T^2 / 2), the two axles in parallel;
    * b_r: the suspension dampers at +-T/2, K_sd T^2 / 2 per axle;
    * h_r: sprung-mass CoG above the roll axis, h_s - h_ra (front and rear roll axis heights are equal);
    * I_x: the sprung mass's roll inertia I_Phi_s.
    """
    if p.h_raf != p.h_rar:
        raise ModelDefinitionError("roll axis heights differ front/rear; one h_r does not describe the car")
    susp_f = 0.5 * p.K_sf * p.T_f ** 2 - p.K_tsf
    susp_r = 0.5 * p.K_sr * p.T_r ** 2 - p.K_tsr
    tyre_f, tyre_r = 0.5 * p.K_zt * p.T_f ** 2, 0.5 * p.K_zt * p.T_r ** 2
    K_r = 1.0 / (1.0 / susp_f + 1.0 / tyre_f) + 1.0 / (1.0 / susp_r + 1.0 / tyre_r)
    b_r = 0.5 * (p.K_sdf * p.T_f ** 2 + p.K_sdr * p.T_r ** 2)
    return {"K_r": K_r, "b_r": b_r, "h_r": p.h_s - p.h_raf, "I_x": p.I_Phi_s}


def secant_axle_stiffness(vehicle: int, slip: float) -> tuple:
    """(C_f, C_r) secant axle stiffnesses F_y(slip)/slip of the CommonRoad PAC2002 tyre at the static
    loads [N/rad] (two tyres per axle; pure slip, no camber)."""
    from vehiclemodels.utils import tire_model
    from ...validation.commonroad_plant import _static_loads, vehicle_parameters
    p = vehicle_parameters(vehicle)
    out = []
    for fz in _static_loads(p):
        fy = -tire_model.formula_lateral(-slip, 0.0, fz, p.tire)[0]      # CommonRoad's alpha is -alpha
        out.append(2.0 * abs(fy) / slip)
    return tuple(out)


def roll_params_toml(vehicle: int = 2) -> str:
    """The parameter file of ``roll_single_track`` for a CommonRoad car, as a string."""
    from ...validation.commonroad_plant import VEHICLE_NAMES, _static_loads, tyre_cornering_stiffness, vehicle_parameters
    p = vehicle_parameters(vehicle)
    fzf, fzr = _static_loads(p)
    cf, cr = tyre_cornering_stiffness(p, fzf), tyre_cornering_stiffness(p, fzr)
    eq = roll_equivalents(p)
    return f"""# Roll-augmented single-track model (Menhour et al. 2014) of CommonRoad parameter set {vehicle} ({VEHICLE_NAMES[vehicle]}),
# derived number by number by codegen.families.switched_pi.validation.roll_params_toml (a test re-derives it).

[meta]
source = "commonroad-vehicle-models parameters_vehicle{vehicle} (vehicle_dynamics_mb), linear roll equivalents"
commonroad_vehicle = "{vehicle}"
car = "{VEHICLE_NAMES[vehicle]} (CommonRoad vehicle {vehicle})"

[parameters]
m = {p.m!r}        # kg, total mass (p.m)
m_s = {p.m_s!r}        # kg, sprung mass (p.m_s)
I_x = {eq['I_x']!r}        # kg m^2, sprung-mass roll inertia about its CoG (p.I_Phi_s)
I_z = {p.I_z!r}        # kg m^2, yaw inertia (p.I_z)
l_f = {p.a!r}        # m, CoG to front axle (p.a)
l_r = {p.b!r}        # m, CoG to rear axle (p.b)
h_r = {eq['h_r']!r}        # m, sprung CoG above the roll axis (p.h_s - p.h_raf)
K_r = {eq['K_r']!r}        # N m/rad, per axle (K_s T^2/2 - K_ts) in series with K_zt T^2/2, axles summed
b_r = {eq['b_r']!r}        # N m s/rad, (K_sdf T_f^2 + K_sdr T_r^2)/2
C_f = {2 * cf!r}        # N/rad, front axle: 2 x PAC2002 slope at zero slip, static tyre load {fzf:.1f} N
C_r = {2 * cr!r}        # N/rad, rear axle: 2 x PAC2002 slope at zero slip, static tyre load {fzr:.1f} N
g = {G!r}        # m/s^2

[scheduling.v_x]
min = 5.0        # m/s
max = 35.0       # m/s
rate_min = -8.0  # m/s^2 (unused by the switched design: its modes are fixed operating points)
rate_max = 4.0

[plant]
# Truth-plant values (validation only; the observer never sees them): the PAC2002 tyre's own numbers.
mu = {p.tire.p_dy1!r}        # -, peak lateral friction coefficient (p_dy1)
h_cg = {p.h_cg!r}        # m, CoG height for the longitudinal load transfer (p.h_cg)
C_pac = {p.tire.p_cy1!r}        # -, magic-formula shape factor (p_cy1)
E_pac = {p.tire.p_ey1!r}        # -, curvature factor (p_ey1)

[inputs]
# Ranges of the generic excitation scenario (uiogen validate NAME --scenario excitation), not of the design:
v_x = {{ min = 8.0, max = 27.0 }}                       # m/s, the sweep: the span of the three modes' bands
delta = {{ min = -0.02, max = 0.02, bandwidth = 0.5 }}   # rad, road-wheel angle
phi_r = {{ min = -0.1, max = 0.1, bandwidth = 0.2 }}     # rad, road bank angle (about +-6 deg, slowly varying)
"""


# --- the truth plant of a banked road ------------------------------------------------------------

def _plant_function(params, exact_model: bool = False):
    """(rhs(v_y, r, phi, phi_dot, delta, phi_r, v_x, a_x), lateral acceleration, values).

    ``exact_model``: the observer's own linear model (1)-(2) with the true, time-varying speed
    (v_y = v_x beta, so v_y' = v_x beta' + beta a_x): no tyre, roll or bank nonlinearity, only the
    switched model's fixed operating points differ from it."""
    from ...project.observer_file import builtin_model
    mod = builtin_model("roll_single_track")
    values = {**params.values, **params.plant}
    if exact_model:
        d = mod.MODEL
        subs = {p: values[str(p)] for p in d.parameters}
        beta, r, phi, phi_dot = d.states
        v_x = d.scheduling[0].symbol
        v_y, a_x = sp.symbols("v_y a_x")
        fb = sp.Matrix(d.dynamics).subs(subs).subs(beta, v_y / v_x)
        dyn = [v_x * fb[0] + v_y / v_x * a_x, fb[1], fb[2], fb[3]]
        acc_expr = v_x * (fb[0] + r)
        args = [v_y, r, phi, phi_dot, *d.known_inputs, *d.unknown_inputs, v_x, a_x]
    else:
        d = mod.PLANT
        missing = [str(p) for p in d.parameters if str(p) not in values]
        if missing:
            raise ModelDefinitionError(f"plant {d.name!r} needs {', '.join(missing)} in {params.source}")
        subs = {p: values[str(p)] for p in d.parameters}
        dyn = list(sp.Matrix(d.dynamics).subs(subs))
        acc_expr = mod.PLANT_LATERAL_ACCELERATION.subs(subs)
        args = [*d.states, *d.known_inputs, *d.unknown_inputs, *(s.symbol for s in d.scheduling)]
    return sp.lambdify(args, dyn, "math"), sp.lambdify(args, acc_expr, "math"), values


def banked_plant(config, params, scn, progress=None, substeps: int = 10, exact_model: bool = False) -> dict:
    """Closed-loop truth on the scenario's speed, curvature and bank profiles.

    The speed follows ``scn.v_ref`` exactly (v_x and a_x = ``scn.a_ref`` are the plant's
    scheduling signals, as in the nominal plants); a path-following driver sets the road-wheel
    angle delta = L kappa + k_r (v kappa - r) + k_ri int(v kappa - r) from the yaw-rate error,
    held over each sample; the plant is integrated with RK4 substeps. Returns per sample: t, v_x,
    a_x, v_y, beta = atan(v_y / v_x), r, phi, phi_dot, phi_r (bank), delta, a_y.
    ``exact_model`` integrates the observer's own model instead (see :func:`_plant_function`).
    """
    f, acc, values = _plant_function(params, exact_model)
    n, Ts = scn.t.size, config.sample_time
    h = Ts / substeps
    bank = np.zeros(n) if getattr(scn, "bank", None) is None else np.asarray(scn.bank, float)
    kap = np.zeros(n) if scn.kappa_ref is None else np.asarray(scn.kappa_ref, float)
    L = values["l_f"] + values["l_r"]
    k_r, k_ri = 0.5, 0.3
    x = np.zeros(4)                 # v_y, r, phi, phi_dot
    x[1] = float(scn.v_ref[0]) * kap[0]
    i_r = 0.0

    def rhs(z, delta, pr, vx, ax):
        return np.array(f(*z, delta, pr, vx, ax), dtype=float).ravel()

    out = {k: np.empty(n) for k in ("v_x", "a_x", "v_y", "beta", "r", "phi", "phi_dot", "phi_r", "delta", "a_y")}
    for k in range(n):
        if progress is not None and (k % max(n // 50, 1) == 0 or k == n - 1):
            progress((k + 1) / n)
        vx, ax, pr = float(scn.v_ref[k]), float(scn.a_ref[k]), float(bank[k])
        err = vx * kap[k] - x[1]
        i_r += err * Ts
        delta = L * kap[k] + k_r * err + k_ri * i_r
        out["v_x"][k], out["a_x"][k], out["phi_r"][k], out["delta"][k] = vx, ax, pr, delta
        out["v_y"][k], out["r"][k], out["phi"][k], out["phi_dot"][k] = x
        out["beta"][k] = math.atan2(x[0], vx)
        out["a_y"][k] = float(acc(*x, delta, pr, vx, ax))
        if k == n - 1:
            break
        vx1, ax1 = float(scn.v_ref[k + 1]), float(scn.a_ref[k + 1])
        pr1 = float(bank[k + 1])
        for s in range(substeps):
            # speed, acceleration and bank follow the road (linear between samples); delta is held
            c0, c1 = s / substeps, (s + 0.5) / substeps
            c2 = (s + 1) / substeps
            v0, vm, v1 = (vx + c * (vx1 - vx) for c in (c0, c1, c2))
            a0, am, a1 = (ax + c * (ax1 - ax) for c in (c0, c1, c2))
            p0, pm, p1 = (pr + c * (pr1 - pr) for c in (c0, c1, c2))
            k1 = rhs(x, delta, p0, v0, a0)
            k2 = rhs(x + 0.5 * h * k1, delta, pm, vm, am)
            k3 = rhs(x + 0.5 * h * k2, delta, pm, vm, am)
            k4 = rhs(x + h * k3, delta, p1, v1, a1)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)):
            raise SampleError(f"banked plant diverged at t = {scn.t[k]:.2f} s in scenario {scn.name!r}")
    out["t"] = np.asarray(scn.t, float)
    return out


def commonroad_truth(config, scn, vehicle: int, progress=None) -> dict:
    """The CommonRoad multi-body plant at the observer's rate (flat road: phi_r = 0), signals as
    :func:`banked_plant`. Roll is reported in the paper's convention (positive for the outward roll
    of a left turn), the opposite of the package's x[6]."""
    from ...validation.commonroad_plant import PlantConfig, simulate
    gt = simulate(scn, PlantConfig(vehicle=vehicle, sample_rate=1.0 / config.sample_time), progress=progress)
    return {"t": gt.t, "v_x": gt.v_x, "a_x": gt.a_x, "v_y": gt.v_y, "beta": gt.beta, "r": gt.r,
            "phi": -gt.roll, "phi_dot": -gt.roll_rate, "phi_r": np.zeros_like(gt.t), "delta": gt.delta,
            "a_y": gt.a_y}


# --- validation runs --------------------------------------------------------------------------------

SENSOR_NOISE = {"delta": np.deg2rad(0.02), "r": np.deg2rad(0.05), "phi": np.deg2rad(0.05),
                "phi_dot": np.deg2rad(0.1), "v_x": 0.05}
"""Standard deviations of the seeded white sensor noise (steering angle, yaw rate, roll angle and
rate from an inertial unit, wheel-speed-based longitudinal speed)."""

# Menhour et al. 2014 eqs. (26) and (28): ||beta - beta_hat||_2 / ||phi_r||_2 on its experimental run.
PAPER_RATIO = {"speed": 9.538e-4, "slip": 8.8542e-3}
PAPER_GAMMA = 2.1

_TRUTH_CACHE: dict = {}


def truth(config, scenario: str, plant: str = "nominal", duration: float | None = None, progress=None) -> dict:
    """Truth of a scenario on a plant at the observer's rate (cached per parameter file and rate).

    ``nominal``: the Pacejka roll/bank plant; ``model``: the observer's linear model with the true
    speed; ``commonroad``: the CommonRoad multi-body plant of the car the parameter file names
    ([meta] commonroad_vehicle), flat road."""
    from ...model import load_parameters
    from ...validation import scenarios
    key = (str(config.parameter_path), scenario, config.sample_time, plant, duration)
    if key in _TRUTH_CACHE:
        return _TRUTH_CACHE[key]
    params = load_parameters(config.parameter_path)
    scn = truncate(scenarios.make(scenario, sample_rate=1.0 / config.sample_time), duration)
    if plant in ("nominal", "model"):
        out = dict(_kept_banked_plant(config, params, scn, progress, exact_model=plant == "model"))
        out["plant_model"] = ("roll_single_track (exact linear model, true speed)" if plant == "model"
                              else "roll_single_track_pacejka_bank_plant")
    elif plant == "commonroad":
        vehicle = params.meta.get("commonroad_vehicle")
        if vehicle not in ("1", "2", "3"):
            raise ModelDefinitionError(f"{config.parameters} names no CommonRoad car ([meta] commonroad_vehicle)")
        if getattr(scn, "bank", None) is not None and np.any(scn.bank != 0):
            scn = _flat(scn)
        out = commonroad_truth(config, scn, int(vehicle), progress=progress)
        out["plant_model"] = f"CommonRoad multi-body (vehiclemodels), vehicle {vehicle}, flat road"
    else:
        raise ModelDefinitionError(f"plant must be 'nominal', 'model' or 'commonroad', got {plant!r}")
    _TRUTH_CACHE[key] = out
    return out


BANKED = "switched_pi_banked_plant"
"""The kind of the kept closed-loop runs of :func:`banked_plant` (:func:`codegen.model.cache.remembered`)."""


def _kept_banked_plant(config, params, scn, progress, exact_model: bool) -> dict:
    """:func:`banked_plant`, kept across runs: keyed by the parameter values (and the plant's), the sample time,
    the scenario byte for byte, which model, and the code (this module, the roll model's and its tyres');
    ``progress`` is not called when it is kept."""
    import sys

    from ...model import cache
    from ...project.observer_file import builtin_model
    from ...validation.simulate import scenario_digest
    mod = builtin_model("roll_single_track")
    tyres = sys.modules[mod.magic_formula_axle.__module__]
    parts = {"values": dict(params.values), "plant": dict(params.plant), "sample_time": float(config.sample_time),
             "scenario": scenario_digest(scn), "exact_model": exact_model}
    return cache.remembered(BANKED, parts, lambda: banked_plant(config, params, scn, progress=progress,
                                                                exact_model=exact_model),
                            sys.modules[__name__], mod, tyres)


def _flat(scn):
    """The same scenario on a flat road (the CommonRoad plant has no bank)."""
    from dataclasses import replace
    return replace(scn, bank=None)


def run_scenario(config, scenario: str, plant: str = "nominal", duration: float | None = None,
                 seed: int = 0, progress=None, observer=None) -> dict:
    """The compiled step on a scenario: rows in the one definition of every validation
    (:func:`codegen.validation.metrics.signal_report`), the eq. (26)/(28) ratio beside the paper's
    (``paper_format``), mode occupancy."""
    from ...extension.build import load
    from ...validation import simulate
    tr = truth(config, scenario, plant, duration, progress)
    measured = simulate.add_sensor_noise(tr, SENSOR_NOISE, seed)
    obs = observer if observer is not None else load(config)
    out, status, _ = obs.run(simulate.observer_input_matrix(obs.input_names, tr, measured))
    model = config.load_model()
    units = dict(model.units)
    est = {s: out[:, i] for i, s in enumerate(obs.output_names)}
    table = {s: signal_stats(tr[s], est[s], tr["t"], unit=units.get(s)) for s in obs.output_names if s in tr}
    keep = tr["t"] >= SETTLE_TIME
    bank_norm = float(np.linalg.norm(tr["phi_r"][keep]))
    ratio = float(np.linalg.norm((est["beta"] - tr["beta"])[keep]) / bank_norm) if bank_norm > 0 else None
    modes = np.rint(est["mode"]).astype(int)
    occupancy = {int(m): float(np.mean(modes == m)) for m in np.unique(modes)}
    rule = "slip" if any(a.get("name") == "slip" for a in config.switching.get("axis", [])) else "speed"
    return {"observer": table, "baselines": {}, "status_flags": int(np.count_nonzero(status)),
            "samples": int(len(status)), "max_abs_ay": float(np.abs(tr["a_y"]).max()),
            "max_abs_ax": float(np.abs(tr["a_x"]).max()), "plant": plant, "plant_model": tr["plant_model"],
            "scenario": scenario, "ratio_beta_to_bank": ratio, "paper_ratio": PAPER_RATIO[rule],
            "mode_occupancy": occupancy, "Menhour et al. 2014": True,
            "paper_format": {"table": PAPER_TABLE, "ratio_beta_to_bank": ratio, "paper_ratio": PAPER_RATIO[rule],
                             "paper_gamma": PAPER_GAMMA, "mode_occupancy": occupancy},
            "signals": {"t": tr["t"], "truth": tr, "estimate": est, "status": status}, "units": units}


PAPER_TABLE = ("Menhour et al. 2014 eqs. (26)/(28): ||beta - beta_hat||_2 / ||phi_r||_2 after the settle time, "
               "beside the paper's on its experimental run (a bank-to-sideslip ratio, dimensionless)")


def format_table(result: dict) -> str:
    """Every estimated signal in the one definition of every validation, then the eq. (26)/(28)
    ratio beside the paper's and the modes' occupancy."""
    from ...validation.common import format_stats
    lines = [format_stats(result["observer"])]
    if result["ratio_beta_to_bank"] is not None:
        lines.append(f"||beta - beta_hat||_2 / ||phi_r||_2 = {result['ratio_beta_to_bank']:.4g} "
                     f"(Menhour et al. 2014: {result['paper_ratio']:.4g} on its run; gamma* = {PAPER_GAMMA})")
    else:
        lines.append("flat road: the bank row is |bank estimate| (truth 0)")
    occ = ", ".join(f"{m}: {100 * f:.0f}%" for m, f in result["mode_occupancy"].items())
    lines.append(f"mode occupancy {occ}; max |a_x| {result['max_abs_ax']:.2f} m/s²")
    return "\n".join(lines)
