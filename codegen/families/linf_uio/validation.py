"""Validation of the L-infinity UIO family: the compiled step on the nominal (Pacejka) plant,
the observer's exact model or the CommonRoad multi-body plant, beside the linear KF and the
Fiala EKF generated from ``model_defs/baselines.py``. Rows in the one definition of every
validation (:func:`codegen.validation.metrics.signal_report`), and the paper's Table II format
beside them (``paper_format``: E_mean, E_max, Std, RMS with angles in deg and their rates in deg/s)."""
from __future__ import annotations

import numpy as np

from ...validation import metrics, simulate
from ...errors import ModelDefinitionError
from ...validation.common import (SENSOR_NOISE, commonroad_vehicle, scenario_for, signal_stats,
                                  truth_plant)


def truth_commonroad(config, scn, progress=None):
    from ...validation import commonroad_plant
    gt = commonroad_plant.simulate(scn, commonroad_plant.PlantConfig(vehicle=commonroad_vehicle(config)),
                                   progress=progress)
    return {"t": gt.t, "v_x": gt.v_x, "beta": gt.beta, "r": gt.r, "delta": gt.delta,
            "delta_dot": gt.delta_dot, "T_d": gt.T_d, "T_a": gt.T_a, "a_y": gt.a_y, "a_x": gt.a_x,
            "v_y": gt.v_y}


def baselines(config, truth, noisy, units: dict, traces: dict | None = None) -> dict:
    """The source repository's linear KF and the Fiala EKF (generated from ``model_defs/baselines.py``
    with the observer's car: axle stiffness = 2 x tyre stiffness, mu = 1), on the same noisy measurements;
    ``units``: the model's declared units of beta and r. ``traces``: a dict that receives each
    baseline's estimates ({name: {"beta": ..., "r": ...}}), for plots."""
    from ...validation import peers, stanford
    car_ = car(config)
    run = stanford.StanfordRun(t=truth["t"], vx=truth["v_x"], vy=np.tan(truth["beta"]) * truth["v_x"],
                               beta_true=truth["beta"], ax=np.zeros_like(truth["t"]), ay=noisy["a_y"],
                               yaw_rate=noisy["r"], yaw_acc=np.gradient(truth["r"], truth["t"]),
                               delta=noisy["delta"], delta_fl=noisy["delta"], delta_fr=noisy["delta"],
                               source="simulation")
    out = {}
    for name, res in (("linear_kf", peers.linear_kf(run, car_)),
                      ("ekf", peers.ekf(run, car_, peers.EKFConfig(mu=1.0)))):
        out[name] = {"beta": signal_stats(truth["beta"], res.beta, truth["t"], unit=units.get("beta", "rad")),
                     "r": signal_stats(truth["r"], res.r, truth["t"], unit=units.get("r", "rad/s"))}
        if traces is not None:
            traces[name] = {"beta": res.beta, "r": res.r}
    return out


def car(config):
    from ...model import load_parameters
    from ...validation import peers
    v = load_parameters(config.parameter_path).values
    # axle cornering stiffness of the single-track baselines: two tyres per axle
    return peers.VehicleParams(m=v["M"], lf=v["l_f"], lr=v["l_r"], iz=v["I_z"], cf=2 * v["C_f"], cr=2 * v["C_r"])


def run(config, scenario, plant: str = "nominal", duration: float | None = None, seed: int = 0,
        progress=None, observer=None) -> dict:
    """Simulate, run the compiled observer and the baselines, return the tables and signals."""
    from ...extension.build import load
    from .build import representation
    lpv = representation(config)[0]
    scn = scenario_for(config, scenario, duration)
    if plant == "commonroad":
        truth = truth_commonroad(config, scn, progress)
        plant_model = "CommonRoad multi-body (vehiclemodels)"
    elif plant in ("nominal", "model"):
        definition = truth_plant(config, lpv.parameters) if plant == "nominal" else None
        truth = simulate.nominal_plant(config, lpv, scn, definition, progress=progress)
        plant_model = definition.name if definition is not None else lpv.definition.name + " (exact model)"
    else:
        raise ModelDefinitionError(f"plant must be 'nominal', 'model' or 'commonroad', got {plant!r}")
    noisy = simulate.add_sensor_noise(truth, SENSOR_NOISE, seed)
    obs = observer if observer is not None else load(config)
    d = lpv.definition
    inputs = simulate.observer_input_matrix(obs.input_names, truth, noisy)
    out, status, _ = obs.run(inputs)
    table = {}
    for i, sig in enumerate(obs.state_names):
        if sig in truth:
            table[sig] = signal_stats(truth[sig], out[:, i], truth["t"], unit=d.units.get(sig))
    peers = {}
    base = baselines(config, truth, noisy, dict(d.units), peers)
    return {"observer": table, "baselines": base, "paper_format": paper_format(table, base),
            "status_flags": int(np.count_nonzero(status)), "samples": int(len(status)),
            "max_abs_ay": float(np.abs(truth["a_y"]).max()), "plant": plant, "plant_model": plant_model,
            "scenario": scn.name,
            "signals": {"t": truth["t"], "truth": truth, "estimate": {s: out[:, i] for i, s in enumerate(obs.state_names)},
                        "status": status, "baselines": peers},
            "units": dict(d.units)}


PAPER_TABLE = "Nguyen et al. 2019 Table II: E_mean (mean |error|), E_max, Std, RMS; angles in deg, their rates in deg/s"


def _paper_row(row: dict) -> dict:
    """A row in Table II's terms: angular rates in deg/s as the paper gives them."""
    row = metrics.convert(row, "deg/s") if row.get("unit") == "rad/s" else row
    return {"unit": row["unit"], "E_mean": row["mae"], "E_max": row["max"], "Std": row["std"], "RMS": row["rms"]}


def paper_format(table: dict, base: dict) -> dict:
    """The paper's Table II format of the observer's rows and the baselines' sideslip rows."""
    rows = {sig: _paper_row(row) for sig, row in table.items()}
    rows.update({f"beta {name}": _paper_row(b["beta"]) for name, b in base.items()})
    return {"table": PAPER_TABLE, "rows": rows}


def format_table(result: dict) -> str:
    """The paper's Table II columns (E_mean, E_max, Std, RMS; angles in deg, rates in deg/s), baselines
    below, then the one definition of every validation (the truth's RMS, the error in % of it)."""
    from ...validation.common import format_stats
    lines = [f"{'Table II format':22s} {'E_mean':>9s} {'E_max':>9s} {'Std':>9s} {'RMS':>9s}"]
    for sig, row in result["paper_format"]["rows"].items():
        label = f"{sig} [{row['unit']}]" if not sig.startswith("beta ") else f"beta [{row['unit']}] {sig[5:]}"
        lines.append(f"{label:22s} {row['E_mean']:9.4f} {row['E_max']:9.4f} {row['Std']:9.4f} {row['RMS']:9.4f}")
    lines.append(format_stats(result["observer"]))
    return "\n".join(lines)
