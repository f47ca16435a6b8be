"""``uiogen validate``: an observer's errors on a plant it was not derived from, beside baselines.

Simulated runs (``--scenario``) belong to the observer's family (``Family.validate``: its
plants, its paper's table format); logged runs (``--data``) are common to every observer that
reads the log's signals. Measurements carry seeded white sensor noise where the family's paper
does (:data:`codegen.validation.common.SENSOR_NOISE`); baselines see the same measurements, so
every figure is a ratio measured in one run.
"""
from __future__ import annotations

import json

import numpy as np

from .. import families
from ..project import observer_file as observers
from ..errors import SampleError
from .common import SETTLE_TIME, signal_stats

__all__ = ["SETTLE_TIME", "run_scenario", "format_table", "header", "plot", "to_json", "run_data",
           "plot_data", "format_data_table", "progress_bar"]


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


def run_scenario(name, scenario, plant: str = "nominal", duration: float | None = None,
                 seed: int = 0, progress=None, observer=None) -> dict:
    """Simulate the observer's family plant, run the compiled step and the baselines; returns the
    tables (``observer``, ``baselines``), the signals and ``family`` (which formats the table).
    ``observer``: the compiled observer to run (default: the observer's extension), e.g. a
    :class:`python_bindings.Recorder` of it."""
    config = observers.get(name) if isinstance(name, str) else name
    if scenario == "excitation":            # every model: its own equations, swept and excited
        from . import excitation
        return {"family": config.family, **excitation.run(config, duration, seed, progress=progress,
                                                          observer=observer)}
    result = families.get(config.family).validate(config, scenario, plant, duration, seed, progress=progress,
                                                  observer=observer)
    return {"family": config.family, **result}


def format_table(result: dict) -> str:
    """The validation table in the format of the observer family's paper (or the generic one of
    the excitation scenario)."""
    if result.get("table_format") == "generic":
        from . import excitation
        return excitation.format_table(result)
    return families.get(result["family"]).format_validation(result)


def header(name: str, result: dict) -> str:
    """The line above the table: scenario, plant, samples, flagged samples."""
    if result.get("table_format") == "generic":
        return families.Family.validation_header(families.get(result["family"]), name, result)
    return families.get(result["family"]).validation_header(name, result)


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


def to_json(result: dict) -> str:
    return json.dumps({k: result[k] for k in ("observer", "baselines", "plant", "plant_model", "scenario",
                                              "status_flags", "samples", "max_abs_ay")}, indent=1, sort_keys=True)


DATA_COLUMNS = {"delta": "delta", "y_r": "yaw_rate", "y_a_y": "ay", "v_x": "vx", "y_delta": "delta",
                "y_v_x": "vx", "a_x": "ax"}


# the input sequence of an observer of the shared log, for tools that need one (codegen.tools.qemu,
# codegen.targets.float32): its validation is the logged run, not a simulated scenario
SHARED_LOG = "stanford log"


def reads_the_log(input_names) -> bool:
    """Whether every input of the observer is a column of the shared log (DATA_COLUMNS)."""
    return all(c in DATA_COLUMNS for c in input_names)


def shared_log_inputs(input_names) -> np.ndarray | None:
    """The shared Stanford log as the observer's input matrix, or None when the observer takes
    other signals than the log's (DatasetError, typed, where ../shared is absent)."""
    if not reads_the_log(input_names):
        return None
    from . import stanford
    run = stanford.load("stanford")
    return np.ascontiguousarray(np.column_stack([getattr(run, DATA_COLUMNS[c]) for c in input_names]),
                                dtype=np.float64)


def run_data(name, path: str = "stanford") -> dict:
    """Run the compiled step over a logged run, beside the baselines.

    An observer file with a ``[data]`` table maps the log's own columns (:mod:`codegen.validation.logs`);
    otherwise the log is in the shared (Stanford) CSV format.

    Returns ``{"observer": {SIGNAL: {"rms", "mae", "max", "std"}}, "baselines": {...}}`` with
    SIGNAL ``beta`` [deg] and ``vy`` [m/s] (v_y = v_x tan(beta)), plus the signals for plots.
    """
    from ..extension.build import load
    from ..project.observer_file import get
    from . import stanford
    config = get(name)
    if config.column_map is not None:
        from . import logs
        return logs.run(config, path)
    obs = load(config)
    run = stanford.load(path, sample_time=obs.sample_time)   # a log at another rate is refused, not run
    missing = [c for c in obs.input_names if c not in DATA_COLUMNS]
    if missing:
        raise SampleError(f"observer {config.name!r} needs {', '.join(missing)}, which the log does not record "
                          f"(it has delta, r, a_y, v_x); use an observer designed for this data, e.g. "
                          f"stanford_sideslip")
    inputs = np.column_stack([getattr(run, DATA_COLUMNS[c]) for c in obs.input_names])
    out, status, _ = obs.run(inputs)
    outputs = obs.output_names
    extra = {}
    if "beta" in outputs:
        beta = out[:, outputs.index("beta")]
    else:   # observers of v_y (Nguyen et al. 2021): beta = atan(v_y / v_x) with the log's v_x
        beta = np.arctan2(out[:, outputs.index("v_y")], run.vx)
    if "delta" in outputs and "y_delta" not in obs.input_names and "delta" not in obs.input_names:
        # delta is an unknown input of the observer (one sample late): the log's measured delta checks it
        delta_hat = np.concatenate([out[1:, outputs.index("delta")], [np.nan]])
        extra["delta"] = signal_stats(run.delta[:-1], delta_hat[:-1], angle=True)
    t = run.t - run.t[0]

    def table(b):
        return {"beta": signal_stats(run.beta_true, b, angle=True),
                "vy": signal_stats(run.vx * np.tan(run.beta_true), run.vx * np.tan(b))}

    kf, ekf = stanford.linear_kf(run), stanford.ekf(run)
    estimates = {"linear_kf": kf.beta, "ekf": ekf.beta}
    if config.model == "single_track_nonlinear_tyre":
        # peers of the same symbolic model and the same parameter file, in the same run
        estimates.update({k: v.beta for k, v in stanford.nonlinear_tyre_peers(run, config.parameter_path).items()})
    result = {"observer": {**table(beta), **extra}, "baselines": {k: table(b) for k, b in estimates.items()},
              "status_flags": int(np.count_nonzero(status)), "samples": int(len(status)), "data": run.source,
              "signals": {"t": t, "beta_true": run.beta_true, "beta": beta, **estimates}}
    split = _identification_split(config, t, run.source)
    if split is not None:
        def rms(b, m):
            return float(np.degrees(np.sqrt(np.mean((b - run.beta_true)[m] ** 2))))
        result["splits"] = {"t_split": split, "identification": {"samples": int((t < split).sum())},
                            "evaluation": {"samples": int((t >= split).sum())}}
        for part, m in (("identification", t < split), ("evaluation", t >= split)):
            result["splits"][part].update({"observer": rms(beta, m), **{k: rms(b, m) for k, b in estimates.items()}})
    result["peaks"] = peak_errors(t, run.beta_true, {"observer": beta, **estimates})
    return result


PEAK_TIMES = (110.0, 170.0, 207.0)
"""Times [s from the log's start] of the three large-sideslip peaks of the shared Stanford half
(the truth reaches about -5 deg there)."""
PEAK_HALF_WIDTH = 5.0


def peak_errors(t, truth, estimates: dict) -> list:
    """Max |beta error| [deg] of each estimate within +-PEAK_HALF_WIDTH s of each peak inside the log."""
    out = []
    for tp in PEAK_TIMES:
        m = np.abs(t - tp) <= PEAK_HALF_WIDTH
        if not m.any():
            continue
        tm = truth[m]
        out.append({"t": tp, "truth_peak_deg": float(np.degrees(tm[np.argmax(np.abs(tm))])),
                    **{k: float(np.degrees(np.abs(b[m] - truth[m]).max())) for k, b in estimates.items()}})
    return out


def _identification_split(config, t, path=None):
    """Where the evaluation part of a log starts [s from its start]: the observer's parameter file's
    ``[meta] identification_t_end`` (its numbers were chosen before it), else, on the shared Stanford
    log, :data:`codegen.validation.stanford.EVALUATION_T_START` (the same protocol for every estimator
    of that log); None when the log does not reach past it."""
    from ..model import load_parameters
    from . import stanford
    raw = load_parameters(config.parameter_path).meta.get("identification_t_end")
    if raw is not None:
        split = float(raw)
    elif path is not None and str(path) == str(stanford.STANFORD_PATH):
        split = stanford.EVALUATION_T_START
    else:
        return None
    return split if t[-1] > split else None


def plot_data(result: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sig = result["signals"]
    if result.get("kind") == "column_map":       # a user's log: every estimate, with its reference
        names = [k for k in sig if k != "t" and not k.endswith("_truth")]
        fig, ax = plt.subplots(len(names), 1, figsize=(10, 2.2 * len(names)), sharex=True, squeeze=False)
        for a, k in zip(ax[:, 0], names):
            if f"{k}_truth" in sig:
                a.plot(sig["t"], sig[f"{k}_truth"], "k", lw=0.8, label="reference")
            a.plot(sig["t"], sig[k], "r", lw=0.8, label="observer (C step)")
            a.set_ylabel(k)
            a.legend(loc="upper right", fontsize=8)
        ax[-1, 0].set_xlabel("t [s]")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return
    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    deg = 180 / np.pi
    ax[0].plot(sig["t"], sig["beta_true"] * deg, "k", lw=0.8, label="reference atan2(vy, vx) of the log")
    ax[0].plot(sig["t"], sig["beta"] * deg, "r", lw=0.8, label="observer (C step)")
    ax[0].plot(sig["t"], sig["linear_kf"] * deg, "b", lw=0.6, alpha=0.6, label="linear KF")
    ax[0].set_ylabel("beta [deg]")
    ax[0].legend(loc="upper right", fontsize=8)
    for key, color in (("beta", "r"), ("linear_kf", "b"), ("ekf", "g"), ("ekf_nonlinear_tyre", "m"),
                       ("ukf_nonlinear_tyre", "c")):
        if key in sig:
            ax[1].plot(sig["t"], (sig[key] - sig["beta_true"]) * deg, color, lw=0.6, label=key)
    for pk in result.get("peaks", ()):
        for a in ax:
            a.axvspan(pk["t"] - PEAK_HALF_WIDTH, pk["t"] + PEAK_HALF_WIDTH, color="0.85", zorder=0)
    if "splits" in result:
        for a in ax:
            a.axvline(result["splits"]["t_split"], color="k", ls=":", lw=0.8)
    ax[1].set_ylabel("error [deg]")
    ax[1].set_xlabel("t [s]")
    ax[1].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_data_table(result: dict) -> str:
    """The real-data table. With an identification split, the evaluation part (samples no choice
    was made on) is the headline column, the identification part and the whole log beside it."""
    if result.get("kind") == "column_map":
        from . import logs
        return logs.format_table(result)
    rows = [("observer", result["observer"])] + list(result["baselines"].items())
    sp_ = result.get("splits")
    if sp_:
        ev, idn = sp_["evaluation"], sp_["identification"]
        lines = [f"beta RMSE [deg] on the evaluation part (t >= {sp_['t_split']:g} s, {ev['samples']} samples; the "
                 f"headline), the identification part (t < {sp_['t_split']:g} s, {idn['samples']} samples) and the "
                 f"whole log; max, MAE [deg] and vy RMSE [m/s] on the whole log",
                 f"{'estimator':18s} {'evaluation':>10s} {'identif.':>9s} {'whole':>9s} {'beta max':>9s} {'beta MAE':>9s} "
                 f"{'vy RMSE':>9s}"]
        for name, t in rows:
            lines.append(f"{name:18s} {ev[name]:10.4f} {idn[name]:9.4f} {t['beta']['rms']:9.4f} {t['beta']['max']:9.4f} "
                         f"{t['beta']['mae']:9.4f} {t['vy']['rms']:9.4f}")
    else:
        lines = [f"{'estimator':18s} {'beta RMSE':>10s} {'beta max':>9s} {'beta MAE':>9s} {'vy RMSE':>9s}   [deg, m/s]"]
        for name, t in rows:
            lines.append(f"{name:18s} {t['beta']['rms']:10.4f} {t['beta']['max']:9.4f} {t['beta']['mae']:9.4f} "
                         f"{t['vy']['rms']:9.4f}")
    for pk in result.get("peaks", ()):
        lines.append(f"peak t = {pk['t']:g} s (truth peak {pk['truth_peak_deg']:.2f} deg), max |beta error| within "
                     f"+-{PEAK_HALF_WIDTH:g} s: " + ", ".join(f"{k} {v:.2f}" for k, v in pk.items()
                                                           if k not in ("t", "truth_peak_deg")))
    if "delta" in result["observer"]:
        d = result["observer"]["delta"]
        lines.append(f"steering angle delta (an unknown input of this observer) vs the log's measured delta: "
                     f"RMSE {d['rms']:.4f} deg, max {d['max']:.4f} deg, MAE {d['mae']:.4f} deg")
    return "\n".join(lines)


def scenario_names(name) -> tuple:
    """The validation scenarios of an observer that ``uiogen demo`` runs (its family's
    ``demo_scenarios``), or the generic excitation scenario for a family without its own."""
    config = observers.get(name) if isinstance(name, str) else name
    return tuple(families.get(config.family).demo_scenarios) or ("excitation",)


def scenario_inputs(name, scenario, plant: str = "nominal", duration: float | None = None) -> np.ndarray:
    """The (n, n_input) input sequence the compiled observer is given on a validation scenario
    (recorded from the run itself: the noisy measurements, the derived scheduling signals)."""
    from python_bindings import Recorder
    from ..extension.build import load
    config = observers.get(name) if isinstance(name, str) else name
    recorder = Recorder(load(config))
    run_scenario(config, scenario, plant, duration=duration, observer=recorder)
    runs = [inputs for inputs, _ in recorder.calls]
    if not runs:
        raise SampleError(f"{config.name}: scenario {scenario!r} did not run the compiled observer")
    if runs[0].ndim == 1:           # sample by sample (step): the consecutive rows of the first run
        rows = []
        for r in runs:
            if r.ndim != 1:
                break
            rows.append(r)
        return np.vstack(rows)
    return runs[0]
