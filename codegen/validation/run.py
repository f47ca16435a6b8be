"""``uiogen validate``: an observer's errors on a plant it was not derived from, beside baselines.

Simulated runs (``--scenario``) belong to the observer's family (``Scenarios.validate``: its
plants, its paper's table format); logged runs (``--data``) are common to every observer that
reads the log's signals. Measurements carry seeded white sensor noise where the family's paper
does (:data:`codegen.validation.common.SENSOR_NOISE`); baselines see the same measurements, so
every figure is a ratio measured in one run.
"""
from __future__ import annotations

import json
import math

import numpy as np

from .. import families
from ..project import observer_file as observers
from ..project import outputs
from ..errors import ConfigurationError, SampleError
from . import metrics
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
                 seed: int = 0, progress=None, observer=None, noise: bool = True) -> dict:
    """Simulate the observer's family plant, run the compiled step and the baselines; returns the
    tables (``observer``, ``baselines``), the signals and ``family`` (which formats the table).
    ``observer``: the compiled observer to run (default: the observer's extension), e.g. a
    :class:`python_bindings.Recorder` of it. ``noise``: the excitation scenario's measurements carry
    the parameter file's ``[sensor_noise]`` (False: ``--noise-free``; a family's own scenarios carry
    their paper's noise, and refuse it)."""
    from ..extension.build import require_current
    config = observers.get(name) if isinstance(name, str) else name
    if duration is not None and not (isinstance(duration, (int, float)) and math.isfinite(duration)
                                     and duration > SETTLE_TIME):
        raise ConfigurationError(f"--duration {duration!r}: allowed: a number of seconds above {SETTLE_TIME:g} (the "
                                 f"scenario is truncated there, and the errors are taken after the first "
                                 f"{SETTLE_TIME:g} s)", source="--duration", key="--duration", value=duration)
    if scenario == "excitation" and plant == "commonroad":
        raise ConfigurationError("--plant commonroad: the excitation scenario runs on the observer's own model (the "
                                 "model plant); CommonRoad's vehicle models drive a family's named scenarios (uiogen "
                                 "validate NAME --scenario S --plant commonroad)", source="--plant", key="--plant",
                                 value=plant)
    if not noise and scenario != "excitation":
        raise ConfigurationError(f"--noise-free: scenario {scenario!r} is the {config.family} family's, with the sensor "
                                 f"noise of its paper (or none); --noise-free turns off the [sensor_noise] of the "
                                 f"excitation scenario (uiogen validate NAME --scenario excitation --noise-free)",
                                 source="--noise-free", key="--noise-free", value=True,
                                 allowed="--scenario excitation")
    require_current(config)                 # never the compiled step of an older design
    if scenario == "excitation":            # every model: its own equations, swept and excited
        from . import excitation
        return {"family": config.family, **excitation.run(config, duration, seed, progress=progress,
                                                          observer=observer, noise=noise)}
    from ..families.capabilities import Scenarios, require
    family = require(families.get(config.family), Scenarios)
    result = family.validate(config, scenario, plant, duration, seed, progress=progress, observer=observer)
    return {"family": config.family, **result}


def format_table(result: dict) -> str:
    """The validation table in the format of the observer family's paper (or the generic one of
    the excitation scenario)."""
    if result.get("table_format") == "generic":
        from . import excitation
        return excitation.format_table(result)
    return families.get(result["family"]).validation_table(result)


def header(name: str, result: dict) -> str:
    """The line above the table: scenario, plant, samples, flagged samples (:mod:`codegen.certificate.text`)."""
    from ..certificate.text import validation_header
    from .common import SETTLE_TIME
    return validation_header(families.get(result["family"]), name, result, SETTLE_TIME)


def plot(result: dict, path: str) -> None:
    plt = outputs.pyplot()
    sig = result["signals"]
    names = [n for n in sig["estimate"] if n in sig["truth"]]
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 2.2 * len(names)), sharex=True)
    for ax, n in zip(np.atleast_1d(axes), names):
        unit, scale, _ = metrics.reported_unit(result["units"].get(n))
        ax.plot(sig["t"], sig["truth"][n] * scale, "k", lw=1.0, label="truth")
        ax.plot(sig["t"], sig["estimate"][n] * scale, "r--", lw=1.0, label="observer")
        ax.set_ylabel(n + (f" [{unit}]" if unit else ""))
    np.atleast_1d(axes)[0].legend(loc="upper right")
    np.atleast_1d(axes)[-1].set_xlabel("t [s]")
    fig.suptitle(f"{result['scenario']} on the {result['plant']} plant")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def failure(result: dict) -> str:
    """Why a run says nothing of the observer's accuracy, or "": the step failed numerically (and
    reset its state) on some samples, or an estimate's error is not finite (it diverged)."""
    import math
    why = []
    failed = result.get("status_counts", {}).get("NUMERICAL_FAILURE", 0)
    if failed:
        why.append(f"the step reported NUMERICAL_FAILURE on {failed} of {result['samples']} samples and reset its "
                   f"state there")
    diverged = [s for s, row in result.get("observer", {}).items()
                if isinstance(row, dict) and isinstance(row.get("rms"), float) and not math.isfinite(row["rms"])]
    if diverged:
        why.append(f"the error of {', '.join(diverged)} is not finite (the estimate diverged)")
    return "; ".join(why)


def to_json(result: dict) -> str:
    """``uiogen validate --json``: every row in the one definition (``definitions`` says what each
    key means and in which unit), and the family's paper format beside it (``paper_format``)."""
    from . import noise
    keys = ("observer", "baselines", "plant", "plant_model", "scenario", "status_flags", "status_counts", "samples",
            "max_abs_ay", "paper_format", "noise")
    return json.dumps({**{k: result[k] for k in keys if k in result}, "definitions": metrics.DEFINITIONS,
                       "uninformative": sorted(noise.uninformative(result.get("observer", {})))},
                      indent=1, sort_keys=True)


DATA_COLUMNS = {"delta": "delta", "y_r": "yaw_rate", "y_a_y": "ay", "v_x": "vx", "y_delta": "delta",
                "y_v_x": "vx", "a_x": "ax"}


# the input sequence of an observer of the shared log, for tools that need one (codegen.tools.qemu,
# codegen.targets.float32): its validation is the logged run, not a simulated scenario
SHARED_LOG = "stanford log"
SHARED_LOGS = {SHARED_LOG: "stanford", "niki log": "niki"}
"""The shared logs as validation runs: {scenario name: the ``--data`` shorthand}. A parameter file's
``[meta] shared_log`` names its car's (``niki``): the float build is held to it too."""


def reads_the_log(input_names) -> bool:
    """Whether every input of the observer is a column of the shared log (DATA_COLUMNS)."""
    return all(c in DATA_COLUMNS for c in input_names)


def shared_log_inputs(input_names, log: str = "stanford") -> np.ndarray | None:
    """A shared log (``log``: a shorthand of :data:`SHARED_LOGS`) as the observer's input matrix, or
    None when the observer takes other signals than the log's (DatasetError, typed, where ../shared is
    absent)."""
    if not reads_the_log(input_names):
        return None
    from . import stanford
    run = stanford.load(log)
    return np.ascontiguousarray(np.column_stack([getattr(run, DATA_COLUMNS[c]) for c in input_names]),
                                dtype=np.float64)


PEAK_HALF_WIDTH = 5.0

BASELINE_MAX_SAMPLES = 300_000
"""The Kalman baselines run on logs of at most this many samples (50 min at 100 Hz): they hold the
whole run in memory and step at about 0.1 ms per sample, so on a longer log the observer is
reported alone and the result says why (``baselines_skipped``)."""


def run_data(name, path: str = "stanford", block_bytes: int | None = None, batch_rows: int | None = None,
             out=None) -> dict:
    """Run the compiled step over a logged run, beside the baselines.

    An observer file with a ``[data]`` table maps the log's own columns (:mod:`codegen.validation.logs`);
    otherwise the log is in the shared (Stanford) CSV format. Either way the log is read in
    chunks (``block_bytes`` of text each, or ``batch_rows`` rows of a Parquet or resampled MDF log:
    :mod:`codegen.validation.logfiles`; any size in bounded memory) and checked against its
    units and the physics of the observer's model (:mod:`codegen.validation.log_checks`) before
    anything is returned.

    Returns ``{"observer": {SIGNAL: row}, "baselines": {...}}``, rows in the one definition of
    :func:`codegen.validation.metrics.signal_report` over the whole log, with SIGNAL ``beta`` (in
    deg, converted from the log's rad) and ``vy`` [m/s] (v_y = v_x tan(beta)), plus the signals for
    plots; ``splits`` (sideslip RMS per part of the log, in ``splits.unit``) where the log has an
    evaluation part, ``log_checks`` (every check and its verdict) and ``warnings``.
    """
    from ..extension.build import load, require_current
    from ..model import load_parameters
    from ..project.columns import model_unit
    from ..project.observer_file import get
    from ..project.precision import input_noise
    from . import csvlog, log_checks, stanford, streaming
    config = get(name)
    require_current(config)                 # never the compiled step of an older design
    block_bytes = csvlog.BLOCK_BYTES if block_bytes is None else block_bytes
    if config.column_map is not None:
        from . import logs
        return logs.run(config, path, block_bytes, batch_rows, out)
    if out is not None:
        raise ConfigurationError(f"--out {out}: writing the outputs needs an observer file with a [data] table (the "
                                 f"column map of your own log: docs/validation.md, 'Your own logs'); "
                                 f"{config.name} reads the shared format")
    obs = load(config)
    missing = [c for c in obs.input_names if c not in DATA_COLUMNS]
    if missing:
        raise SampleError(f"observer {config.name!r} needs {', '.join(missing)}, which the log does not record "
                          f"(it has delta, r, a_y, v_x); use an observer designed for this data, e.g. "
                          f"stanford_sideslip")
    model = _model_or_none(config)
    checks = None
    if model is not None:
        checks = log_checks.LogChecks(
            stanford._resolve(path), model, load_parameters(config.parameter_path), obs.input_names,
            {n: log_checks.Column(DATA_COLUMNS[n], stanford.UNITS[DATA_COLUMNS[n]], model_unit(model, n),
                                  declared_by="format") for n in obs.input_names}, obs.sample_time,
            noise=input_noise(config, obs.input_names))
    outputs = obs.output_names
    delta_unknown = "delta" in outputs and "y_delta" not in obs.input_names and "delta" not in obs.input_names
    table = {"beta": streaming.ErrorStats("rad"), "vy": streaming.ErrorStats("m/s")}
    delta_stats, prev_delta = streaming.ErrorStats("rad"), None
    split = _identification_split(config, stanford._resolve(path))
    parts = {"identification": _Rms(), "evaluation": _Rms()}
    peaks = {tp: _Peak() for tp in stanford.peak_times(path)}
    kept, whole = streaming.Decimated(), {c: [] for c in stanford.COLUMNS}
    state, flags, n, t0, t_end = obs.initial_state(), 0, 0, None, None
    for cols in stanford.chunks(path, sample_time=obs.sample_time, block_bytes=block_bytes):
        inputs = np.column_stack([cols[DATA_COLUMNS[c]] for c in obs.input_names])
        t0 = cols["t"][0] if t0 is None else t0
        t = cols["t"] - t0
        if checks is not None:
            checks.feed(cols["t"], {c: inputs[:, j] for j, c in enumerate(obs.input_names)})
        out, status, state = obs.run(inputs, state)
        flags += int(np.count_nonzero(status))
        n += t.size
        t_end = float(t[-1])
        vx, truth = cols["vx"], cols["beta_true"]
        if "beta" in outputs:
            beta = out[:, outputs.index("beta")]
        else:   # observers of v_y (Nguyen et al. 2021): beta = atan(v_y / v_x) with the log's v_x
            beta = np.arctan2(out[:, outputs.index("v_y")], vx)
        table["beta"].add(truth, beta)
        table["vy"].add(vx * np.tan(truth), vx * np.tan(beta))
        if delta_unknown:
            # delta is an unknown input of the observer (one sample late): the log's measured delta checks it
            est = out[:, outputs.index("delta")]
            meas = cols["delta"] if prev_delta is None else np.concatenate([[prev_delta], cols["delta"]])
            delta_stats.add(meas[:est.size - (prev_delta is None)], est[prev_delta is None:])
            prev_delta = float(cols["delta"][-1])
        if split is not None:
            parts["identification"].add(beta, truth, t < split)
            parts["evaluation"].add(beta, truth, t >= split)
        for tp, pk in peaks.items():
            pk.add(t, truth, beta, tp)
        kept.add({"t": t, "beta_true": truth, "beta": beta, "status": status})
        if whole is not None:
            for c in cols:                        # a column of stanford.OPTIONAL the log lacks stays empty
                whole[c].append(cols[c])
            if n > BASELINE_MAX_SAMPLES:
                whole = None                      # too long for the baselines: stop holding the run
    report = checks.finish() if checks is not None else {"checks": [], "warnings": []}
    extra = {"delta": delta_stats.result()} if delta_unknown else {}
    result = {"observer": {k: v.result() for k, v in table.items()} | extra, "baselines": {},
              "status_flags": flags, "samples": n, "data": str(stanford._resolve(path)),
              "log_checks": report["checks"], "warnings": report["warnings"]}
    signals = kept.signals()
    estimates = {}
    if whole is not None:
        run = stanford.StanfordRun(source=result["data"], **{c: np.concatenate(v) if v else None for c, v in whole.items()})
        estimates = _baselines(config, run)
        result["baselines"] = {k: _table(run, b) for k, b in estimates.items()}
        signals.update(estimates)
    else:
        result["baselines_skipped"] = (f"the log has {n} samples, more than {BASELINE_MAX_SAMPLES} (the Kalman "
                                       f"baselines hold the whole run and step at about 0.1 ms per sample); the "
                                       f"observer is reported alone")
    result["signals"], result["signals_stride"] = signals, kept.stride
    if split is not None and t_end is not None and t_end > split:
        result["splits"] = {"t_split": split, "unit": "deg"}
        for part, m in (("identification", signals["t"] < split), ("evaluation", signals["t"] >= split)):
            row = {"samples": parts[part].n, "observer": parts[part].rms()}
            for k, b in estimates.items():
                row[k] = float(np.degrees(np.sqrt(np.mean((b - signals["beta_true"])[m] ** 2))))
            result["splits"][part] = row
    rows = []
    for tp, pk in peaks.items():
        if pk.n:
            row = {"t": tp, "truth_peak_deg": float(np.degrees(pk.truth_peak)), "observer": float(np.degrees(pk.err))}
            if estimates:
                m = np.abs(signals["t"] - tp) <= PEAK_HALF_WIDTH
                row.update({k: float(np.degrees(np.abs(b[m] - signals["beta_true"][m]).max()))
                            for k, b in estimates.items()})
            rows.append(row)
    result["peaks"] = rows
    return result


def _model_or_none(config):
    """The observer's model definition, or None for a family whose model is not one
    ModelDefinition (its log is then checked by the format alone)."""
    from ..errors import ModelDefinitionError
    try:
        return config.load_model()
    except ModelDefinitionError:
        return None


def _baselines(config, run) -> dict:
    """beta of every baseline of the shared log: the source repository's linear KF, the EKF, and the
    same-model peers of an observer of the nonlinear-tyre model (:class:`~codegen.families.capabilities.LogPeers`),
    the two groups on two processes (:class:`~.workers.Workers`: independent runs, the same estimates)."""
    import os

    from ..families.capabilities import LogPeers
    from .workers import Workers
    family = families.get(config.family)
    calls = [(_source_baselines, (run,))]
    if isinstance(family, LogPeers):        # the family's peers of the observer's own model and parameter file
        calls.append((family.log_peers, (config, run)))
    with Workers(min(len(calls), os.cpu_count() or 1)) as workers:
        estimates = {}
        for part in workers.map(calls):
            estimates.update(part)
    return estimates


def _source_baselines(run) -> dict:
    """beta of the source repository's linear KF and of its EKF on the shared log."""
    from . import peers
    return {"linear_kf": peers.linear_kf(run).beta, "ekf": peers.ekf(run).beta}


def _table(run, b) -> dict:
    return {"beta": signal_stats(run.beta_true, b, unit="rad"),
            "vy": signal_stats(run.vx * np.tan(run.beta_true), run.vx * np.tan(b), unit="m/s")}


class _Rms:
    """RMS of the beta error [deg] over the samples of a mask, streamed."""

    def __init__(self):
        self.n, self.sq = 0, 0.0

    def add(self, beta, truth, mask) -> None:
        e = (beta - truth)[mask]
        self.n += int(e.size)
        self.sq += float(np.sum(e * e))

    def rms(self) -> float:
        return float(np.degrees(np.sqrt(self.sq / self.n))) if self.n else float("nan")


class _Peak:
    """The truth's largest |beta| and the observer's largest |error| within +-PEAK_HALF_WIDTH of a time."""

    def __init__(self):
        self.n, self.truth_peak, self.err = 0, 0.0, 0.0

    def add(self, t, truth, beta, tp) -> None:
        m = np.abs(t - tp) <= PEAK_HALF_WIDTH
        if not m.any():
            return
        tm = truth[m]
        i = int(np.argmax(np.abs(tm)))
        if not self.n or abs(tm[i]) > abs(self.truth_peak):
            self.truth_peak = float(tm[i])
        self.err = max(self.err, float(np.abs(beta[m] - tm).max()))
        self.n += int(m.sum())


def _identification_split(config, path=None):
    """Where the evaluation part of a log starts [s from its start]: the observer's parameter file's
    ``[meta] identification_t_end`` (its numbers were chosen before it), else, on the shared Stanford
    log, :data:`codegen.validation.stanford.EVALUATION_T_START` (the same protocol for every estimator
    of that log); None otherwise (and the result has no split when the log does not reach past it)."""
    from ..model import load_parameters
    from . import stanford
    raw = load_parameters(config.parameter_path).meta.get("identification_t_end")
    if raw is not None:
        return float(raw)
    if path is not None and str(path) == str(stanford.STANFORD_PATH):
        return stanford.EVALUATION_T_START
    return None


def plot_data(result: dict, path: str) -> None:
    plt = outputs.pyplot()
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
    truth = result["observer"]["beta"]
    if truth.get("truth_rms"):
        lines.append(f"beta truth RMS {truth['truth_rms']:.4f} deg on the whole log; its RMSE in % of it: "
                     + ", ".join(f"{name} {t['beta']['rms_percent']:.1f} %" for name, t in rows))
    for pk in result.get("peaks", ()):
        lines.append(f"peak t = {pk['t']:g} s (truth peak {pk['truth_peak_deg']:.2f} deg), max |beta error| within "
                     f"+-{PEAK_HALF_WIDTH:g} s: " + ", ".join(f"{k} {v:.2f}" for k, v in pk.items()
                                                           if k not in ("t", "truth_peak_deg")))
    if "delta" in result["observer"]:
        d = result["observer"]["delta"]
        lines.append(f"steering angle delta (an unknown input of this observer) vs the log's measured delta: "
                     f"RMSE {d['rms']:.4f} deg, max {d['max']:.4f} deg, MAE {d['mae']:.4f} deg")
    if result.get("baselines_skipped"):
        lines.append(f"baselines not run: {result['baselines_skipped']}")
    lines += [f"warning: {w}" for w in result.get("warnings", ())]
    return "\n".join(lines)


def scenario_names(name) -> tuple:
    """The validation scenarios of an observer: for a built-in one those ``uiogen demo`` runs (its
    family's ``Scenarios.demo_scenarios``, the papers' on the library's plants), for a project's
    observer and a family without its own the generic excitation scenario on the model's own
    equations (the library's plants are of the built-in models)."""
    from ..families.capabilities import Scenarios
    config = observers.get(name) if isinstance(name, str) else name
    family = families.get(config.family)
    own = tuple(family.demo_scenarios) if isinstance(family, Scenarios) and config.builtin else ()
    return own or ("excitation",)


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
