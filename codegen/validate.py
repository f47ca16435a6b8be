"""``uiogen validate``: an observer's errors on a plant it was not derived from, beside baselines.

Plants:

* ``nominal``: our own symbolic truth plant (the model module's ``PLANT``: Pacejka tyres,
  load transfer, trail-based aligning torque) in closed loop with the scenario's driver;
  where a model has no truth plant (or its parameter file no ``[plant]`` values), the
  observer's own model integrated exactly; ``model`` forces the latter (no model mismatch);
* ``commonroad``: the CommonRoad 29-state multi-body model with PAC2002 tyres
  (:mod:`codegen.validation.commonroad_plant`), steered through the seed-000 column whose
  aligning torque comes from the plant's own front slip; the observer must have been
  designed for that car (``lpv_linf_driver_torque_bmw320i`` for parameter set 2).

Measurements carry seeded white sensor noise (:data:`SENSOR_NOISE`); the baselines (the
source repository's linear KF on (beta, r) with (a_y, r), and the Fiala EKF, both generated
from the symbolic models of ``model_defs/baselines.py`` by :mod:`codegen.validation.kalman`)
see the same noisy measurements, so every figure is a ratio measured in one run.
"""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np

from . import observers, pipeline, simulate
from .errors import ModelDefinitionError, SampleError
from .validation import metrics, scenarios

SENSOR_NOISE = {"r": np.deg2rad(0.05), "delta": np.deg2rad(0.02), "delta_dot": np.deg2rad(0.2),
                "a_y": 0.05}
SETTLE_TIME = 2.0


def _stats(truth, est, t=None, angle: bool = False) -> dict:
    """Error statistics in the seeds' formats (seed 000 E_mean/E_max/Std/RMS, seed 004 MAE,
    seed 003 eq. (32) RMSE% and NMSE%), after SETTLE_TIME when sample times ``t`` are given."""
    mask = slice(None) if t is None else np.asarray(t) >= SETTLE_TIME
    y, yh = np.asarray(truth)[mask], np.asarray(est)[mask]
    s = metrics.error_stats(y, yh, degrees=angle)
    try:
        nmse = metrics.nmse_percent(y, yh)
    except metrics.MetricInputError:   # constant reference: NMSE undefined
        nmse = None
    return {"mae": s.e_mean, "max": s.e_max, "std": s.std, "rms": s.rms,
            "rmse_percent": metrics.rmse_percent(y, yh, degrees=angle), "nmse_percent": nmse}


def progress_bar(label: str):
    """A progress callback (fraction done) drawing on stderr, or None when stderr is not a terminal."""
    import sys
    if not sys.stderr.isatty():
        return None

    def show(fraction: float) -> None:
        filled = int(30 * fraction)
        sys.stderr.write(f"\r{label} [{'#' * filled}{'.' * (30 - filled)}] {100 * fraction:3.0f}%")
        if fraction >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()
    return show


def _truncate(scn, duration: float | None):
    if duration is None or duration >= scn.duration:
        return scn
    n = int(round(duration * scn.sample_rate)) + 1
    cut = {k: getattr(scn, k)[:n] for k in ("t", "v_ref", "a_ref", "T_a", "T_d_open")}
    if scn.kappa_ref is not None:
        cut["kappa_ref"] = scn.kappa_ref[:n]
    return replace(scn, **cut)


def _commonroad_vehicle(config) -> int:
    """The CommonRoad parameter set an observer was designed for ([meta] commonroad_vehicle)."""
    from .model import load_parameters
    vehicle = load_parameters(config.parameter_path).meta.get("commonroad_vehicle")
    if vehicle not in ("1", "2", "3"):
        raise ModelDefinitionError(
            f"observer {config.name!r} was designed for {config.parameters}, not for a CommonRoad car; "
            f"validate on the CommonRoad plant with an observer designed for its parameters, e.g. "
            f"lpv_linf_driver_torque_bmw320i or ts_fuzzy_uio_bmw320i")
    return int(vehicle)


def _truth_commonroad(config, scn, progress=None):
    from .validation import commonroad_plant
    gt = commonroad_plant.simulate(scn, commonroad_plant.PlantConfig(vehicle=_commonroad_vehicle(config)),
                                   progress=progress)
    return {"t": gt.t, "v_x": gt.v_x, "beta": gt.beta, "r": gt.r, "delta": gt.delta,
            "delta_dot": gt.delta_dot, "T_d": gt.T_d, "T_a": gt.T_a, "a_y": gt.a_y, "a_x": gt.a_x,
            "v_y": gt.v_y}


def _baselines(config, truth, noisy) -> dict:
    """The source repository's linear KF and the Fiala EKF (generated from ``model_defs/baselines.py``
    with the observer's car: axle stiffness = 2 x tyre stiffness, mu = 1), on the same noisy measurements."""
    from .validation import stanford
    car = _car(config)
    run = stanford.StanfordRun(t=truth["t"], vx=truth["v_x"], vy=np.tan(truth["beta"]) * truth["v_x"],
                               beta_true=truth["beta"], ax=np.zeros_like(truth["t"]), ay=noisy["a_y"],
                               yaw_rate=noisy["r"], yaw_acc=np.gradient(truth["r"], truth["t"]),
                               delta=noisy["delta"], delta_fl=noisy["delta"], delta_fr=noisy["delta"],
                               source="simulation")
    out = {}
    for name, res in (("linear_kf", stanford.linear_kf(run, car)),
                      ("ekf", stanford.ekf(run, car, stanford.EKFConfig(mu=1.0)))):
        out[name] = {"beta": _stats(truth["beta"], res.beta, truth["t"], angle=True),
                     "r": _stats(truth["r"], res.r, truth["t"], angle=True)}
    return out


def _car(config):
    from .model import load_parameters
    from .validation import stanford
    v = load_parameters(config.parameter_path).values
    # axle cornering stiffness of the single-track baselines: two tyres per axle
    return stanford.VehicleParams(m=v["M"], lf=v["l_f"], lr=v["l_r"], iz=v["I_z"], cf=2 * v["C_f"], cr=2 * v["C_r"])


def truth_plant(config, params):
    """The model module's truth plant (``PLANT``: e.g. Pacejka tyres) when the parameter set has the
    ``[plant]`` values it needs (``mu`` may follow the scenario), else None (the observer's own
    exact model is integrated)."""
    import importlib
    plant = getattr(importlib.import_module(f"model_defs.{config.model}"), "PLANT", None)
    if plant is None:
        return None
    values = {**params.values, **params.plant}
    return plant if all(str(p) in values or str(p) == "mu" for p in plant.parameters) else None


def scenario_for(config, scenario, duration: float | None = None):
    """A library scenario (by name) at the observer's sample rate, or a built
    :class:`~codegen.validation.scenarios.Scenario` (e.g. a variant made with ``dataclasses.replace``)
    whose rate must be the observer's; optionally truncated."""
    if isinstance(scenario, scenarios.Scenario):
        if abs(scenario.sample_rate * config.sample_time - 1.0) > 1e-9:
            raise SampleError(f"scenario {scenario.name!r} is sampled at {scenario.sample_rate} Hz; observer "
                              f"{config.name!r} runs at {1.0 / config.sample_time} Hz")
        return _truncate(scenario, duration)
    return _truncate(scenarios.make(scenario, sample_rate=1.0 / config.sample_time), duration)


# Seed 004 Table II (HiL on a 15-DOF AMESim vehicle): MAE and RMSD per scenario. The seed's scenarios
# 2 and 3 are circular_path_normal and time_varying_grip_normal (its 'normal driving' range);
# circular_path and time_varying_grip are harder stress readings, compared with the same figures.
SEED004_TABLE_II = {
    "random_trajectory_accel": {"v_y": (0.0025, 3.81e-4), "delta": (0.0018, 2.53e-4), "T_eng": (0.9002, 5.164)},
    "circular_path": {"v_y": (5.66e-4, 2.19e-4), "delta": (9.71e-5, 2.91e-6), "T_eng": (0.7329, 5.212)},
    "circular_path_normal": {"v_y": (5.66e-4, 2.19e-4), "delta": (9.71e-5, 2.91e-6), "T_eng": (0.7329, 5.212)},
    "time_varying_grip": {"v_y": (3.81e-4, 2.96e-6), "delta": (0.0023, 2.14e-4), "T_eng": (0.7553, 5.319)},
    "time_varying_grip_normal": {"v_y": (3.81e-4, 2.96e-6), "delta": (0.0023, 2.14e-4), "T_eng": (0.7553, 5.319)},
}


def run_ts_scenario(config, scenario, plant: str = "nominal", duration: float | None = None,
                    progress=None) -> dict:
    """Seed-004 observers: closed-loop angle/torque plant, compiled step, Table II metrics.

    ``scenario`` is a library name or a built Scenario (see :func:`scenario_for`); the seed's
    Table II figures are looked up by its name. The step returns x_hat_k and d_hat_{k-1}
    (one-sample lag of (16c)); the unknown inputs are compared with the truth of the sample they
    estimate. Noise-free, as the seed's Table II.
    """
    from python_bindings import load
    from .model import load_parameters
    params = load_parameters(config.parameter_path)
    model_def = config.load_model()
    scn = scenario_for(config, scenario, duration)
    if plant == "commonroad":
        from .validation import commonroad_angle
        truth = commonroad_angle.simulate(scn, _commonroad_vehicle(config), 1.0 / config.sample_time,
                                          progress=progress)
        plant_model = "CommonRoad multi-body (vehiclemodels), angle-steered"
    elif plant in ("nominal", "model"):
        definition = (truth_plant(config, params) if plant == "nominal" else None) or model_def
        truth = simulate.angle_torque_plant(config, definition, params, scn, progress=progress)
        plant_model = definition.name + (" (exact model)" if definition is model_def else "")
    else:
        raise ModelDefinitionError(f"plant must be 'nominal', 'model' or 'commonroad', got {plant!r}")
    obs = load(config.name)
    out, status, _ = obs.run(simulate.observer_input_matrix(obs.input_names, truth, {}))
    units = dict(model_def.units)
    table, estimates = {}, {}
    for sig in obs.output_names:
        col = out[:, obs.output_index(sig)]
        lag = 1 if sig in {str(s) for s in model_def.unknown_inputs} else 0
        est = np.concatenate([col[lag:], np.full(lag, np.nan)])       # align d_hat_{k} with sample k
        estimates[sig] = est
        if sig in truth:
            keep = slice(0, len(est) - lag)
            table[sig] = _stats(truth[sig][keep], est[keep], truth["t"][keep], angle=False)
    return {"observer": table, "baselines": {}, "status_flags": int(np.count_nonzero(status[1:])),
            "samples": int(len(status)), "max_abs_ay": float(np.abs(truth["a_y"]).max()), "plant": plant,
            "plant_model": plant_model, "scenario": scn.name,
            "seed_table": SEED004_TABLE_II.get(scn.name),
            "signals": {"t": truth["t"], "truth": truth, "estimate": estimates}, "units": units}


def run_scenario(name: str, scenario: str, plant: str = "nominal", duration: float | None = None,
                 seed: int = 0, progress=None) -> dict:
    """Simulate, run the compiled observer and the baselines, return the tables and signals."""
    from python_bindings import load
    config = observers.get(name)
    if config.family == "ts_fuzzy_uio":
        return run_ts_scenario(config, scenario, plant, duration, progress=progress)
    if config.family == "interconnected_uio":
        from .validation import satory
        return satory.run_scenario(name, scenario, plant, duration, progress=progress)
    if config.family == "switched_pi":
        from .validation import banked_road
        return banked_road.run_scenario(config, scenario, plant, duration, seed, progress=progress)
    if config.family == "algebraic_uio":
        from .validation import algebraic
        return algebraic.run(config, scenario, plant, duration, seed, progress=progress)
    lpv = pipeline.representation(config)[0]
    scn = scenario_for(config, scenario, duration)
    if plant == "commonroad":
        truth = _truth_commonroad(config, scn, progress)
        plant_model = "CommonRoad multi-body (vehiclemodels)"
    elif plant in ("nominal", "model"):
        definition = truth_plant(config, lpv.parameters) if plant == "nominal" else None
        truth = simulate.nominal_plant(config, lpv, scn, definition, progress=progress)
        plant_model = definition.name if definition is not None else lpv.definition.name + " (exact model)"
    else:
        raise ModelDefinitionError(f"plant must be 'nominal', 'model' or 'commonroad', got {plant!r}")
    noisy = simulate.add_sensor_noise(truth, SENSOR_NOISE, seed)
    obs = load(name)
    d = lpv.definition
    inputs = simulate.observer_input_matrix(obs.input_names, truth, noisy)
    out, status, _ = obs.run(inputs)
    table = {}
    for i, sig in enumerate(obs.state_names):
        if sig in truth:
            table[sig] = _stats(truth[sig], out[:, i], truth["t"], angle=d.units.get(sig, "").startswith("rad"))
    return {"observer": table, "baselines": _baselines(config, truth, noisy),
            "status_flags": int(np.count_nonzero(status)), "samples": int(len(status)),
            "max_abs_ay": float(np.abs(truth["a_y"]).max()), "plant": plant, "plant_model": plant_model,
            "scenario": scenario,
            "signals": {"t": truth["t"], "truth": truth, "estimate": {s: out[:, i] for i, s in enumerate(obs.state_names)}},
            "units": dict(d.units)}


def plot(result: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sig = result["signals"]
    names = [n for n in sig["estimate"] if n in sig["truth"]]
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 2.2 * len(names)), sharex=True)
    for ax, n in zip(np.atleast_1d(axes), names):
        scale = 180 / np.pi if result["units"].get(n, "").startswith("rad") else 1.0
        ax.plot(sig["t"], sig["truth"][n] * scale, "k", lw=1.0, label="truth")
        ax.plot(sig["t"], sig["estimate"][n] * scale, "r--", lw=1.0, label="observer")
        ax.set_ylabel(n + (" [deg]" if scale != 1.0 else ""))
    np.atleast_1d(axes)[0].legend(loc="upper right")
    np.atleast_1d(axes)[-1].set_xlabel("t [s]")
    fig.suptitle(f"{result['scenario']} on the {result['plant']} plant")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_seed004_table(result: dict) -> str:
    """Seed 004 Table II format: MAE and RMSD per estimated signal, ours beside the seed's."""
    seed = result.get("seed_table") or {}
    lines = [f"{'index':16s} {'ours':>11s} {'seed 004':>11s}"]
    for metric, k in (("MAE", "mae"), ("RMSD", "std")):
        for sig in ("v_y", "delta", "T_eng"):
            if sig in result["observer"]:
                ref = seed.get(sig, (None, None))[0 if metric == "MAE" else 1]
                unit = {"v_y": "m/s", "delta": "rad", "T_eng": "Nm"}[sig]
                lines.append(f"{sig + ' ' + metric + ' [' + unit + ']':16s} {result['observer'][sig][k]:11.3g} "
                             f"{(f'{ref:11.3g}' if ref is not None else '          -')}")
    lines.append(f"(RMSD: standard deviation of the error, as the seed's Table II values imply; "
                 f"RMS v_y {result['observer']['v_y']['rms']:.3g} m/s; max |a_y| {result['max_abs_ay']:.2f} m/s²)")
    return "\n".join(lines)


def format_table(result: dict) -> str:
    if result.get("family") == "algebraic_uio":
        from .validation import algebraic
        return algebraic.format_table(result)
    if "seed_table" in result:
        return format_seed004_table(result)
    if "seed003" in result:
        from .validation import satory
        return satory.format_result(result)
    if result.get("seed001"):
        from .validation import banked_road
        return banked_road.format_table(result)
    lines = [f"{'signal':14s} {'E_mean':>9s} {'E_max':>9s} {'Std':>9s} {'RMS':>9s}"]
    units = result["units"]
    for sig, row in result["observer"].items():
        u = units.get(sig, "")
        u = ("deg" + ("/s" if u.endswith("/s") else "")) if u.startswith("rad") else u
        lines.append(f"{sig + ' [' + u + ']':14s} {row['mae']:9.4f} {row['max']:9.4f} {row['std']:9.4f} {row['rms']:9.4f}")
    for base, rows in result["baselines"].items():
        b = rows["beta"]
        lines.append(f"{'beta [deg] ' + base:14s} {b['mae']:9.4f} {b['max']:9.4f} {b['std']:9.4f} {b['rms']:9.4f}")
    return "\n".join(lines)


def to_json(result: dict) -> str:
    return json.dumps({k: result[k] for k in ("observer", "baselines", "plant", "plant_model", "scenario",
                                              "status_flags", "samples", "max_abs_ay")}, indent=1, sort_keys=True)


DATA_COLUMNS = {"delta": "delta", "y_r": "yaw_rate", "y_a_y": "ay", "v_x": "vx", "y_delta": "delta",
                "y_v_x": "vx"}


def run_data(name: str, path: str = "stanford") -> dict:
    """Run the compiled step over a logged run in the shared CSV format, beside the baselines.

    Returns ``{"observer": {SIGNAL: {"rms", "mae", "max", "std"}}, "baselines": {...}}`` with
    SIGNAL ``beta`` [deg] and ``vy`` [m/s] (v_y = v_x tan(beta)), plus the signals for plots.
    """
    from python_bindings import load
    from .validation import stanford
    obs = load(name)
    run = stanford.load(path, sample_time=obs.sample_time)   # a log at another rate is refused, not run
    missing = [c for c in obs.input_names if c not in DATA_COLUMNS]
    if missing:
        raise SampleError(f"observer {name!r} needs {', '.join(missing)}, which the log does not record "
                          f"(it has delta, r, a_y, v_x); use an observer designed for this data, e.g. "
                          f"stanford_sideslip")
    inputs = np.column_stack([getattr(run, DATA_COLUMNS[c]) for c in obs.input_names])
    out, status, _ = obs.run(inputs)
    outputs = obs.output_names
    extra = {}
    if "beta" in outputs:
        beta = out[:, outputs.index("beta")]
    else:   # observers of v_y (seed 004): beta = atan(v_y / v_x) with the log's v_x
        beta = np.arctan2(out[:, outputs.index("v_y")], run.vx)
    if "delta" in outputs and "y_delta" not in obs.input_names and "delta" not in obs.input_names:
        # delta is an unknown input of the observer (one sample late): the log's measured delta checks it
        delta_hat = np.concatenate([out[1:, outputs.index("delta")], [np.nan]])
        extra["delta"] = _stats(run.delta[:-1], delta_hat[:-1], angle=True)
    t = run.t - run.t[0]

    def table(b):
        return {"beta": _stats(run.beta_true, b, angle=True),
                "vy": _stats(run.vx * np.tan(run.beta_true), run.vx * np.tan(b))}

    kf, ekf = stanford.linear_kf(run), stanford.ekf(run)
    return {"observer": {**table(beta), **extra}, "baselines": {"linear_kf": table(kf.beta), "ekf": table(ekf.beta)},
            "status_flags": int(np.count_nonzero(status)), "samples": int(len(status)), "data": run.source,
            "signals": {"t": t, "beta_true": run.beta_true, "beta": beta, "linear_kf": kf.beta, "ekf": ekf.beta}}


def plot_data(result: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sig = result["signals"]
    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    deg = 180 / np.pi
    ax[0].plot(sig["t"], sig["beta_true"] * deg, "k", lw=0.8, label="optical sensor (truth)")
    ax[0].plot(sig["t"], sig["beta"] * deg, "r", lw=0.8, label="observer (C step)")
    ax[0].plot(sig["t"], sig["linear_kf"] * deg, "b", lw=0.6, alpha=0.6, label="linear KF")
    ax[0].set_ylabel("beta [deg]")
    ax[0].legend(loc="upper right", fontsize=8)
    for key, color in (("beta", "r"), ("linear_kf", "b"), ("ekf", "g")):
        ax[1].plot(sig["t"], (sig[key] - sig["beta_true"]) * deg, color, lw=0.6, label=key)
    ax[1].set_ylabel("error [deg]")
    ax[1].set_xlabel("t [s]")
    ax[1].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_data_table(result: dict) -> str:
    rows = [("observer", result["observer"])] + list(result["baselines"].items())
    lines = [f"{'estimator':12s} {'beta RMSE':>10s} {'beta max':>9s} {'beta MAE':>9s} {'vy RMSE':>9s}   [deg, m/s]"]
    for name, t in rows:
        lines.append(f"{name:12s} {t['beta']['rms']:10.4f} {t['beta']['max']:9.4f} {t['beta']['mae']:9.4f} "
                     f"{t['vy']['rms']:9.4f}")
    if "delta" in result["observer"]:
        d = result["observer"]["delta"]
        lines.append(f"steering angle delta (an unknown input of this observer) vs the log's measured delta: "
                     f"RMSE {d['rms']:.4f} deg, max {d['max']:.4f} deg, MAE {d['mae']:.4f} deg")
    return "\n".join(lines)
