"""Where the L-infinity UIO's error on its own exact model comes from: one factor at a time.

``python -m codegen.families.linf_uio.ablation [NAME] [--json]`` runs the observer ``NAME``
(default ``lpv_linf_driver_torque``) on the ``track_varying_speed`` scenario, plant = the
observer's exact model (``uiogen validate NAME --plant model``), with the numpy reference step
(:func:`discrete.step_numpy`, the C step's twin), and changes one thing at a time:

* the measurement noise (off),
* the observer's model: the exact A(v_x) in the step instead of the Taylor-reduced polytope's
  (same gains M(theta): the 14.8 % error on a_12 alone), or the exact 4-vertex sector polytope
  (re-designed),
* the gain bound (re-designed), the UI filter constant T_f, the performance output z,
* the sample time (the step at T_s / 10 on a plant sampled at T_s / 10: the continuous limit),
* the published matrices (Sec. V) in place of ours.

Every re-design is a measurement (a fresh solve, nothing committed).
Not part of the pipeline: ``build.py`` does not import it, so it is no design input.
"""
from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np

from ... import pipeline
from ...design.solver import FreshSolver
from ...representation import polytope
from ...validation import metrics, simulate
from ...project.observer_file import get as get_observer
from ...validation.common import SENSOR_NOISE, scenario_for, signal_stats
from . import discrete

SCENARIO = "track_varying_speed"


def _variant(config, polytope_kind=None, gain_bound=None, performance=None, sample_time=None, tf=None):
    design = dict(config.design)
    ts = config.sample_time if sample_time is None else sample_time
    gb = (design.get("gain_bound_times_sample_time", 1.0) / config.sample_time) if gain_bound is None else gain_bound
    design["gain_bound_times_sample_time"] = gb * ts
    if performance is not None:
        design["performance"] = list(performance)
    ui = dict(config.ui_filter)
    if tf is not None:
        ui["time_constant"] = tf
    return dataclasses.replace(config, design=design, ui_filter=ui, sample_time=ts,
                               polytope=polytope_kind or config.polytope)


def _build(config):
    return pipeline.build(config, FreshSolver())       # a measurement: nothing goes to a design lock


def _exact_data(data, lpv):
    """``data`` with the exact A(v_x) in the step (one vertex per call, gains unchanged)."""
    exact_A = polytope.exact_matrix_function(lpv, "A")
    poly = data.poly

    class Exact:
        def step(self, z, u, y, rho):
            v = float(np.clip(rho[0], poly.lowers[0], poly.uppers[0]))
            theta = np.array(discrete.premise_of_signal(poly, [v]), float)
            Aa, Ba, By = discrete.augmented_matrices(data, theta)
            eta = poly.eta(v)
            A_poly = sum(e * a for e, a in zip(eta, poly.A))
            Aa = Aa.copy()
            Aa[:data.nx, :data.nx] += exact_A(v) - A_poly
            G = np.eye(data.nz) - data.Ts * Aa
            return np.linalg.solve(G, z + data.Ts * (Ba @ u + By @ y)), 0.0
    return Exact()


def _run(b, truth, measured, step=None):
    """The observer's estimate over the run (numpy step) and the Table II statistics."""
    names = b.input_names
    inputs = simulate.observer_input_matrix(names, truth, measured)
    nu, ny = b.nu, b.ny
    step = step or (lambda z, u, y, rho: discrete.step_numpy(b.data, z, u, y, rho))
    z = np.zeros(b.data.nz)
    out = np.empty((inputs.shape[0], b.data.nz))
    for k, row in enumerate(inputs):
        z, _ = step(z, row[:nu], row[nu:nu + ny], row[nu + ny:])
        out[k] = z
    states = b.state_names
    units = b.lpv.definition.units
    return {s: signal_stats(truth[s], out[:, i], truth["t"], unit=units.get(s))
            for i, s in enumerate(states) if s in truth}


def _truth(config, lpv, seed=0):
    scn = scenario_for(config, SCENARIO)
    truth = simulate.nominal_plant(config, lpv, scn)
    return truth, simulate.add_sensor_noise(truth, SENSOR_NOISE, seed)


def run(name: str = "lpv_linf_driver_torque", published: dict | None = None) -> list:
    """Rows (label, what changed, beta RMS deg, T_d RMS N m, r RMS deg/s, gamma, max ||M||)."""
    config = get_observer(name)
    base = _build(config)
    lpv = base.lpv
    truth, noisy = _truth(config, lpv)
    rows = []

    def add(label, b, stats, note=""):
        gains = [np.linalg.norm(np.linalg.solve(q, l), 2) for q, l in zip(b.data.Q, b.data.L)]
        rows.append({"variant": label, "note": note, "beta_rms_deg": stats["beta"]["rms"],
                     "T_d_rms_Nm": stats["T_d"]["rms"], "r_rms_degps": metrics.convert(stats["r"], "deg/s")["rms"],
                     "gamma": getattr(b, "gamma_override", None) or b.design.gamma,
                     "gain_norm_max": float(max(gains))})

    add("as committed", base, _run(base, truth, noisy),
        f"{base.poly.kind}, ||M|| <= {base.design.settings.gain_bound:g}, T_f {base.data.Tf:g} s, T_s {base.data.Ts:g} s")
    add("no measurement noise", base, _run(base, truth, {}))
    add("exact A(v_x) in the step", base, _run(base, truth, noisy, _exact_data(base.data, lpv).step),
        "same gains; removes the Taylor-reduction error only")
    add("exact A(v_x), no noise", base, _run(base, truth, {}, _exact_data(base.data, lpv).step))
    sector = _build(_variant(config, polytope_kind="sector"))
    add("sector polytope (4 vertices)", sector, _run(sector, truth, noisy), "re-designed")
    for gb in (300.0, 1000.0):
        b = _build(_variant(config, gain_bound=gb))
        add(f"gain bound {gb:g} 1/s", b, _run(b, truth, noisy), "re-designed")
        add(f"gain bound {gb:g} 1/s, no noise", b, _run(b, truth, {}))
    for tf in (0.001, 0.02):
        b = _build(_variant(config, tf=tf))
        add(f"T_f = {tf * 1e3:g} ms", b, _run(b, truth, noisy))
    beta = _build(_variant(config, performance=("beta",)))
    add("z = beta", beta, _run(beta, truth, noisy), "re-designed, same gain bound")
    fine = _build(_variant(config, sample_time=config.sample_time / 10))
    truth_f, _ = _truth(fine.config, lpv)
    add(f"T_s = {fine.data.Ts:g} s, no noise", fine, _run(fine, truth_f, {}),
        "step and plant at T_s/10, same gain bound: the continuous limit")
    if published is not None:
        X = np.array(published["X"], float)
        Q = tuple(np.array(published[f"P{i + 1}"], float) + X for i in range(2))
        L = tuple(np.array(published[f"L{i + 1}"], float) for i in range(2))
        pub = dataclasses.replace(base, data=dataclasses.replace(base.data, Q=Q, L=L))
        object.__setattr__(pub, "gamma_override", 0.009515)
        add("published P_i, X, L_i", pub, _run(pub, truth, noisy), "Sec. V, ||M|| up to 763 1/s")
        add("published, no noise", pub, _run(pub, truth, {}))
    td = truth["T_d"][truth["t"] >= 2.0]
    rows.append({"variant": "(truth) T_d RMS", "note": "the signal itself", "beta_rms_deg": float("nan"),
                 "T_d_rms_Nm": float(np.sqrt(np.mean(td ** 2))), "r_rms_degps": float("nan"),
                 "gamma": float("nan"), "gain_norm_max": float("nan")})
    return rows


def format_rows(rows: list) -> str:
    lines = ["| variant | β RMS [°] | T_d RMS [N·m] | r RMS [°/s] | γ | max ‖M_i‖ [1/s] | note |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        f = lambda x, fmt: "–" if x is None or (isinstance(x, float) and np.isnan(x)) else format(x, fmt)
        lines.append(f"| {r['variant']} | {f(r['beta_rms_deg'], '.4f')} | {f(r['T_d_rms_Nm'], '.3f')} | "
                     f"{f(r['r_rms_degps'], '.4f')} | {f(r['gamma'], '.4g')} | {f(r['gain_norm_max'], '.0f')} | "
                     f"{r['note']} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    as_json = "--json" in argv
    argv = [a for a in argv if a != "--json"]
    published = None
    if "--published" in argv:
        i = argv.index("--published")
        published = json.loads(open(argv[i + 1]).read())
        del argv[i:i + 2]
    rows = run(argv[0] if argv else "lpv_linf_driver_torque", published)
    print(json.dumps(rows, indent=1) if as_json else format_rows(rows))


if __name__ == "__main__":
    main()
