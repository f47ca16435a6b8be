"""``uiogen demo``: the README's main job, after design + generate + build.

For every generated observer: its design figures (from the artifact), then the compiled
C step on its family's library scenarios (two; seed 004: the seed's three) against its nominal
plant in closed loop with the scenario's driver (the model module's truth plant, e.g. Pacejka tyres,
where the parameter set has its values, else the exact symbolic model; the line names which), beside
the KF/EKF baselines, in the seed's table format (angles in degrees).
"""
from __future__ import annotations

import json

from . import observers, validate
from .emit import GENERATED_DIR

DEMO_SCENARIOS = {"linf_uio": ("track_varying_speed", "takeover_opposing_assist"),
                  "ts_fuzzy_uio": ("random_trajectory_accel", "circular_path_normal", "time_varying_grip_normal"),
                  "switched_pi": ("banked_road_braking", "braking_on_bend"),
                  "algebraic_uio": ("seed002",),
                  "interconnected_uio": ("satory",)}
REAL_DATA_OBSERVER = "stanford_sideslip"
REAL_DATA_OTHERS = ("ts_fuzzy_uio_stanford",)     # same log, other families
REAL_DATA_PLOT = GENERATED_DIR.parent / "build" / "stanford_sideslip_real_data.png"


def main(json_output: bool = False) -> int:
    report = {}
    for name in [n for n in observers.names() if n != REAL_DATA_OBSERVER and n not in REAL_DATA_OTHERS]:
        art = json.loads((GENERATED_DIR / name / f"{name}_design.json").read_text())
        family = observers.get(name).family
        scen = {s: validate.run_scenario(name, s, "nominal") for s in DEMO_SCENARIOS[family]}
        if family == "algebraic_uio":
            report[name] = {"family": family, "relative_degrees": art["decoupling"]["relative_degrees"],
                            "classical_uio_exists": art["classical_uio_11"]["exists"],
                            "worst_lmi_margin": art["certificate"]["recheck"]["worst_min_eig"],
                            "discrete": art["discrete"], "scenarios": scen}
            continue
        if family == "interconnected_uio":
            cert = art["certificate"]["recheck"]
            report[name] = {"family": family, "worst_lmi_margin": cert["worst_min_eig"],
                            "worst_lmi_block": cert["worst_block"], "discrete": art["certificate"]["discrete"],
                            "scenarios": scen}
            continue
        if family == "ts_fuzzy_uio":
            cert = art["certificate"]["recheck"]
            report[name] = {"family": family, "worst_lmi_margin": cert["worst_min_eig"],
                            "worst_lmi_block": cert["worst_block"], "lmi_blocks": cert["blocks"],
                            "lyapunov_decrease": art["certificate"]["lyapunov_decrease_33"], "scenarios": scen}
            continue
        if family == "switched_pi":
            report[name] = {"family": family, "gamma": art["gamma"], "hinf": art["certificate"]["hinf"],
                            "worst_lmi_margin": art["certificate"]["recheck"]["worst_min_eig"],
                            "discrete": {k: art["discrete"][k] for k in ("contraction_per_step", "spectral_radius_max")},
                            "modes": len(art["switched_model"]["points"]), "scenarios": scen}
            continue
        report[name] = {
            "family": family, "gamma": art["gamma"], "gamma_quadratic": art["quadratic"]["gamma"],
            "worst_lmi_margin": art["certificate"]["worst_min_eig"],
            "worst_lmi_block": art["certificate"]["worst_block"], "discrete": art["discrete"],
            "scenarios": scen}
    real = validate.run_data(REAL_DATA_OBSERVER, "stanford")
    others = {n: validate.run_data(n, "stanford") for n in REAL_DATA_OTHERS if n in observers.names()}
    REAL_DATA_PLOT.parent.mkdir(exist_ok=True)
    validate.plot_data(real, str(REAL_DATA_PLOT))
    if json_output:
        print(json.dumps({"real_data": {**{k: real[k] for k in ("observer", "baselines")},
                                        "other_observers": {n: r["observer"] for n, r in others.items()}}, **{n: {**{k: v for k, v in e.items() if k != "scenarios"},
                              "scenarios": {s: json.loads(validate.to_json(r)) for s, r in e["scenarios"].items()}}
                          for n, e in report.items()}}, indent=1, sort_keys=True))
        return 0
    for name, e in report.items():
        print(f"== {name}")
        if e["family"] == "algebraic_uio":
            from .validation import algebraic
            d = e["discrete"]
            print(f"   seed 002: relative degree {e['relative_degrees']}, classical UIO (11) "
                  f"{'exists' if e['classical_uio_exists'] else 'does not exist'}; LMI (39) worst margin "
                  f"{e['worst_lmi_margin']:.3g}; Gauss-Legendre step: sqrt(V) contracts by <= "
                  f"{d['contraction_bound_per_step']:.6f}/step")
            for r in e["scenarios"].values():
                print("   " + algebraic.header(name, r))
                print("     " + validate.format_table(r).replace("\n", "\n     "))
            continue
        if e["family"] == "interconnected_uio":
            d = e["discrete"]
            print(f"   seed-003 LMIs (27): worst margin {e['worst_lmi_margin']:.3g} in {e['worst_lmi_block']}; "
                  f"discrete step: sqrt(V) contracts by {d['longitudinal']['contraction_per_step']:.6f} "
                  f"(longitudinal), {d['lateral']['contraction_per_step']:.6f} (lateral) per step")
        elif e["family"] == "ts_fuzzy_uio":
            print(f"   seed-004 LMIs (27): {e['lmi_blocks']} blocks, worst margin {e['worst_lmi_margin']:.3g} in "
                  f"{e['worst_lmi_block']}; (33) on random samples: sqrt(V) contracts by "
                  f"{e['lyapunov_decrease']['contraction_per_step']:.6f}/step")
        elif e["family"] == "switched_pi":
            print(f"   seed-001 switched PI, {e['modes']} modes: gamma {e['gamma']:.6g} (seed: 2.1), max mode "
                  f"H-inf norm {e['hinf']['max_hinf']:.6g} (Hamiltonian bisection and sweep); discrete step: sqrt(V) "
                  f"contracts by {e['discrete']['contraction_per_step']:.6f}/step in every mode")
        else:
            d = e["discrete"]
            print(f"   gamma {e['gamma']:.6g} (quadratic {e['gamma_quadratic']:.6g}); worst LMI margin "
                  f"{e['worst_lmi_margin']:.3g} in {e['worst_lmi_block']}")
            print(f"   discrete step Ts={d['Ts']:g}s: sqrt(V) contracts by {d['contraction_per_step']:.6f}/step "
                  f"(certified), dense-grid spectral radius {d['dense_grid_augmented_spectral_radius_max']:.6f}")
        for scen, r in e["scenarios"].items():
            noise = {"ts_fuzzy_uio": "noise-free as the seed's Table II",
                     "interconnected_uio": "noise-free as the seed's simulator runs"}.get(e["family"], "sensor noise")
            print(f"   {scen}: plant {r.get('plant_model', r['plant'])}, {noise}, compiled C step, {r['samples']} samples, "
                  f"max |a_y| {r['max_abs_ay']:.1f} m/s^2, {r['status_flags']} flagged")
            print("     " + validate.format_table(r).replace("\n", "\n     "))
    print(f"== real data: {REAL_DATA_OBSERVER} on {real['data']} ({real['samples']} samples at 100 Hz, "
          f"optical-sensor sideslip truth; {real['status_flags']} flagged)")
    print("   " + validate.format_data_table(real).replace("\n", "\n   "))
    for n, r in others.items():
        t = r["observer"]
        print(f"   {n} (same log; linear tyres, delta estimated as an unknown input): beta RMSE "
              f"{t['beta']['rms']:.4f} deg, max {t['beta']['max']:.4f} deg; delta RMSE {t['delta']['rms']:.4f} deg")
    print(f"   plot: {REAL_DATA_PLOT}")
    return 0
