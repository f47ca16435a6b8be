"""Validation of the TS fuzzy UIO family: the closed-loop angle/torque plant (the model module's
truth plant, the exact model, or the angle-steered CommonRoad plant), the compiled step, and the
rows of every validation (:func:`codegen.validation.metrics.signal_report`) and the paper's
Table II format beside them (``paper_format``: MAE, RMSD in SI units and rad, the paper's
figures beside ours)."""
from __future__ import annotations

import numpy as np

from ...validation import metrics, simulate
from ...errors import ModelDefinitionError
from ...validation.common import commonroad_vehicle, scenario_for, signal_stats, truth_plant


# Nguyen et al. 2021 Table II (HiL on a 15-DOF AMESim vehicle): MAE and RMSD per scenario. The paper's scenarios
# 2 and 3 are circular_path_normal and time_varying_grip_normal (its 'normal driving' range);
# circular_path and time_varying_grip are harder stress readings, compared with the same figures.
PAPER_TABLE_II = {
    "random_trajectory_accel": {"v_y": (0.0025, 3.81e-4), "delta": (0.0018, 2.53e-4), "T_eng": (0.9002, 5.164)},
    "circular_path": {"v_y": (5.66e-4, 2.19e-4), "delta": (9.71e-5, 2.91e-6), "T_eng": (0.7329, 5.212)},
    "circular_path_normal": {"v_y": (5.66e-4, 2.19e-4), "delta": (9.71e-5, 2.91e-6), "T_eng": (0.7329, 5.212)},
    "time_varying_grip": {"v_y": (3.81e-4, 2.96e-6), "delta": (0.0023, 2.14e-4), "T_eng": (0.7553, 5.319)},
    "time_varying_grip_normal": {"v_y": (3.81e-4, 2.96e-6), "delta": (0.0023, 2.14e-4), "T_eng": (0.7553, 5.319)},
}


# T_eng truths on the multi-body plant (codegen.validation.commonroad_angle): the paper's effective
# torque T_eng = T_drive - T_wheels - T_steer (the headline), and the same with one modelling
# difference of (1) put back at a time: what the T_eng error would be against each.
TORQUE_TRUTHS = {
    "drive torque m R_w a_x (wheel spin-up and steered-wheel projection included)": ("T_drive",),
    "drive torque less wheel spin-up (F_y,f sin(delta) projection included)": ("T_drive", "-T_wheels"),
    "drive torque less steered-wheel projection (wheel spin-up included)": ("T_drive", "-T_steer"),
}


def run(config, scenario, plant: str = "nominal", duration: float | None = None,
        progress=None, roll_stiffness_scale: float = 1.0, camber_force: bool = True, observer=None) -> dict:
    """Nguyen et al. 2021 observers: closed-loop angle/torque plant, compiled step, Table II metrics.

    ``scenario`` is a library name or a built Scenario (see :func:`scenario_for`); the paper's
    Table II figures are looked up by its name. The step returns x_hat_k and d_hat_{k-1}
    (one-sample lag of (16c)); the unknown inputs are compared with the truth of the sample they
    estimate. Noise-free, as the paper's Table II.
    """
    from ...extension.build import load
    from ...model import load_parameters
    params = load_parameters(config.parameter_path)
    model_def = config.load_model()
    scn = scenario_for(config, scenario, duration)
    if plant == "commonroad":
        from ...validation import commonroad_angle
        truth = commonroad_angle.simulate(scn, commonroad_vehicle(config), 1.0 / config.sample_time,
                                          progress=progress, roll_stiffness_scale=roll_stiffness_scale,
                                          camber_force=camber_force)
        plant_model = "CommonRoad multi-body (vehiclemodels), angle-steered"
        if roll_stiffness_scale != 1.0:
            plant_model += f", anti-roll bars x{roll_stiffness_scale:g}"
        if not camber_force:
            plant_model += ", no camber force"
    elif roll_stiffness_scale != 1.0 or not camber_force:
        raise ModelDefinitionError("roll_stiffness_scale and camber_force apply to the commonroad plant only")
    elif plant in ("nominal", "model"):
        definition = (truth_plant(config, params) if plant == "nominal" else None) or model_def
        truth = simulate.angle_torque_plant(config, definition, params, scn, progress=progress)
        plant_model = definition.name + (" (exact model)" if definition is model_def else "")
    else:
        raise ModelDefinitionError(f"plant must be 'nominal', 'model' or 'commonroad', got {plant!r}")
    obs = observer if observer is not None else load(config)
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
            table[sig] = signal_stats(truth[sig][keep], est[keep], truth["t"][keep], unit=units.get(sig))
    torque_truths = {}
    if plant == "commonroad" and "T_eng" in estimates:
        keep = slice(0, len(estimates["T_eng"]) - 1)
        for label, terms in TORQUE_TRUTHS.items():
            ref = sum((-1.0 if t[0] == "-" else 1.0) * truth[t.lstrip("-")] for t in terms)
            torque_truths[label] = signal_stats(ref[keep], estimates["T_eng"][keep], truth["t"][keep],
                                                unit=units.get("T_eng"))
    return {"torque_truths": torque_truths, "observer": table, "baselines": {}, "status_flags": int(np.count_nonzero(status[1:])),
            "samples": int(len(status)), "max_abs_ay": float(np.abs(truth["a_y"]).max()), "plant": plant,
            "plant_model": plant_model, "scenario": scn.name,
            "paper_format": paper_format(table, PAPER_TABLE_II.get(scn.name) or {}),
            "signals": {"t": truth["t"], "truth": truth, "estimate": estimates, "status": status}, "units": units}


# How each plant compares with the paper's column (its Table II is from a 15-DOF AMESim vehicle).
COMPARABILITY = {
    "commonroad": "(like for like: an independent multi-body plant, as the paper's 15-DOF simulator; "
                  "T_eng truth: the effective torque, the input of (1))",
    "nominal": "(NOT like for like: the observer's own equations (1) with magic-formula tyres of the same "
               "slope; the paper used a 15-DOF simulator, see --plant commonroad)",
    "model": "(NOT like for like: the observer's own model, exact; a consistency check, not the paper's test)",
}


PAPER_TABLE = ("Nguyen et al. 2021 Table II: MAE (mean |error|) and RMSD (the standard deviation of the error, as "
               "the paper's values imply), SI units, angles in rad; the paper's figures beside ours")
PAPER_UNITS = {"v_y": "m/s", "delta": "rad", "T_eng": "N m"}


def paper_format(table: dict, paper: dict) -> dict:
    """Table II's rows (v_y, delta, T_eng, those the observer estimates) in the paper's units, with
    the paper's (MAE, RMSD) of the same scenario where it has one."""
    rows = {}
    for sig, unit in PAPER_UNITS.items():
        if sig in table:
            row = table[sig]
            if row.get("converted_from") == unit:       # the paper gives angles in rad
                row = metrics.convert(row, unit)
            ref = paper.get(sig, (None, None)) if row["unit"] == unit else (None, None)
            rows[sig] = {"unit": row["unit"], "MAE": row["mae"], "RMSD": row["std"], "paper_MAE": ref[0], "paper_RMSD": ref[1]}
    return {"table": PAPER_TABLE, "rows": rows}


def format_table(result: dict) -> str:
    """Nguyen et al. 2021 Table II format: MAE and RMSD per estimated signal, ours beside the paper's;
    then the one definition of every validation (unit, the truth's RMS, the error in % of it)."""
    from ...validation.common import format_stats
    lines = [f"{'index':16s} {'ours':>11s} {'Nguyen et al. 2021':>11s}"]
    rows = result["paper_format"]["rows"]
    for metric in ("MAE", "RMSD"):
        for sig, row in rows.items():
            ref = row[f"paper_{metric}"]
            lines.append(f"{sig + ' ' + metric + ' [' + row['unit'] + ']':16s} {row[metric]:11.3g} "
                         f"{(f'{ref:11.3g}' if ref is not None else '          -')}")
    lines.append(COMPARABILITY.get(result["plant"], COMPARABILITY["nominal"]) if "(exact model)" not in
                 result.get("plant_model", "") else COMPARABILITY["model"])
    for label, st in (result.get("torque_truths") or {}).items():
        lines.append(f"T_eng against {label}: MAE {st['mae']:.3g} {st['unit']}, RMSD {st['std']:.3g} {st['unit']}")
    lines.append(f"(max |a_y| {result['max_abs_ay']:.2f} m/s²)")
    lines.append(format_stats(result["observer"]))
    return "\n".join(lines)
