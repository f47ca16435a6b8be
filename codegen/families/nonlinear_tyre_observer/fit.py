"""``uiogen fit``: a nonlinear-tyre observer's numbers identified on a declared sample range of a log.

The log must carry a sideslip reference, and is read as ``uiogen validate --data`` reads it
(:func:`read_run`): an observer file with a ``[data]`` map reads any log the map names -- CSV, Parquet,
MDF4, a ROS 2 bag (``TOPIC.FIELD``), a CAN log with its DBC (``MESSAGE.SIGNAL``) -- through the same
reader (:class:`codegen.validation.logs.MappedLog`: the file's units converted, every channel on the
observer's sample time, the model's physics checked), the lateral speed reference its ``[data.truth]``
entry; without a map, the shared Stanford format (``vx``, ``vy``, ``ay``, ``yaw_rate``, ``delta``,
``ax``, optionally ``yaw_acc``) in a CSV, Parquet or MDF4 file (:func:`codegen.validation.stanford.open_log`).
The yaw acceleration is the log's ``yaw_acc`` where it records one (a mapped log: the channel its ``[data.fit]
yaw_acceleration`` names, converted to rad/s^2); where it records none (most logs), the yaw rate's derivative ``numpy.gradient(yaw_rate, t)`` on the observer's grid over the
range, said in the printed output (on the shared Ferrari half, samples 0:13750, the gradient instead of
the recorded column moves the fitted stiffnesses by 0.1 %, mu not at all, the sideslip RMS by 1e-5 deg).
Only samples A..B-1 are read for any choice. Fitted:

1. **The tyre** (parameter file): each axle's cornering stiffness and *one* friction coefficient
   for both axles, three numbers, by least squares of the log's a_y and yaw acceleration (the
   latter times :data:`YAW_LEVER`) against the model's, from its axle forces at the log's own
   velocities (v_y = ``vy``, r = ``yaw_rate``). Both sides are averaged over :data:`AVERAGE_S`
   (21 samples at 100 Hz, 43 at 200 Hz): the accelerometers' vibration is not force. The
   fit starts from a physical prior the log does not set (stiffness 15 F_z per rad, mu = 1), never
   from the committed values. m, l_f, l_r, I_z, g and the drive layout stay as the file has them.
   A parameter file with a ``[prior]`` of both axle stiffnesses (published values and their stated
   uncertainty) adds a second tyre set, :data:`CANDIDATES`: the published stiffnesses with the
   friction alone from the log, never below what the log's combined acceleration reaches.
2. **The noise levels** of the l2-gain design (observer file ``[design] sigma_*``), each by its
   definition on the range: the axle force residual (RMS of the averages, per axle), the
   sensors' vibration (standard deviation of a_y and r after the source repository's high-pass
   filter, :func:`codegen.validation.peers.highpass_std`), the Euler residual T_s/2 |x''| (RMS,
   from the reference's second derivative).
3. **The Kalman peers' two noise levels** (parameter file ``[meta] peer_sigma_fy``,
   ``peer_sigma_ay``): the grid sigma_fy in {0.02, 0.05, 0.1, 0.2} x sigma_ay in {high-pass std, 0.3,
   1.0} m/s^2, by the EKF's sideslip RMS on the range.

Values are rounded to four significant digits. ``folds`` > 1 cross-validates inside the range:
the range is cut into that many contiguous folds; for each, every tyre set and 2. are fitted on the
others (a guard band of one average left out on both sides), the observer designed with them, run over
the whole range, and its sideslip RMS taken on the fold it never saw. The set with the lower pooled
held-out RMS is written, each number with its block-jackknife standard error over the folds, the
same-tyre EKF's held-out RMS beside it; ``choose`` adds ``[design]`` settings to the same choice. With
a ``[prior]`` and no ``folds``, :data:`DEFAULT_FOLDS`. ``judge`` runs the result on other runs of the
same car (never read for a choice). Everything is deterministic (closed forms, scipy's least squares
from a fixed start, fixed grids).
"""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import casadi as ca
import numpy as np
import sympy as sp

from ...errors import CertificateError, ConfigurationError, SampleError
from ...model import load_parameters
from ...validation import stanford
from ...validation.peers import highpass_std, nonlinear_tyre_peers, peer_noise
from ...validation.workers import Workers
from .representation import numeric

AVERAGE_S = 0.21            # s, the span of the moving averages: the accelerometers' vibration is not force
WINDOW = 21                 # samples of the moving averages at 100 Hz (:func:`window` at another sample time)
YAW_LEVER = 1.0             # m: the yaw-acceleration residual [rad/s^2] weighs as this lever times it [m/s^2]
"""Weight of the yaw acceleration beside a_y in the tyre fit, chosen by 5-fold cross-validation inside the
identification part (samples 0-13749; pooled held-out sideslip RMS of the designed observer): 0.1 m 0.2667,
0.3 m 0.2558, 1 m 0.2526 deg, the axle forces themselves (a lever of about I_z / (m l)) 0.2584 deg."""
DIGITS = 4
PEER_GRID = {"sigma_fy": (0.02, 0.05, 0.1, 0.2), "sigma_ay": (None, 0.3, 1.0)}
MIN_SAMPLES = 500


def parse_jobs(jobs) -> int:
    """``--jobs``: the processes the folds and the peers' grid run on; None: every CPU of the machine."""
    import os
    if jobs is None:
        return max(1, os.cpu_count() or 1)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ConfigurationError(f"--jobs {jobs!r}: an integer >= 1 (the processes the folds run on)",
                                 source="--jobs", key="--jobs", value=jobs)
    return jobs


def parse_samples(text: str, n: int) -> tuple:
    """``"A:B"`` -> (A, B) with 0 <= A < B <= n and B - A >= MIN_SAMPLES (ConfigurationError naming --samples)."""
    m = re.fullmatch(r"\s*(\d+)\s*:\s*(\d+)\s*", str(text))
    if not m:
        raise ConfigurationError(f"--samples {text!r}: expected A:B, two sample indices (the range A..B-1 of the log, "
                                 f"e.g. 0:13750)", source="--samples", key="--samples", value=text)
    a, b = int(m.group(1)), int(m.group(2))
    if not (0 <= a < b <= n):
        raise ConfigurationError(f"--samples {text}: the log has samples 0..{n - 1}; allowed: 0 <= A < B <= {n}",
                                 source="--samples", key="--samples", value=text)
    if b - a < MIN_SAMPLES:
        raise ConfigurationError(f"--samples {text}: {b - a} samples; a fit needs at least {MIN_SAMPLES} "
                                 f"({MIN_SAMPLES / 100:g} s at 100 Hz)", source="--samples", key="--samples", value=text)
    return a, b


def _round(x: float) -> float:
    return float(f"{x:.{DIGITS}g}")


def window(Ts: float) -> int:
    """Samples of the moving averages at the sample time ``Ts``: AVERAGE_S, odd (a centred average)."""
    n = max(1, int(round(AVERAGE_S / Ts)))
    return n if n % 2 else n + 1


def _average(x: np.ndarray, n: int = WINDOW) -> np.ndarray:
    """Centered moving average over ``n`` samples, the ends (n // 2 each) left out."""
    return np.convolve(x, np.full(n, 1.0 / n), mode="valid")


@dataclasses.dataclass(frozen=True)
class _Problem:
    """The log's range as the model sees it, and the model's forces as fast numpy functions."""

    signals: dict           # the model's symbols -> arrays over the range
    measured: np.ndarray    # (n, 2) axle forces from (a_y, yaw acceleration)
    forces: object          # (fitted values...) -> (n, 2) model axle forces
    fitted: tuple           # (C_f, C_r, mu) symbols; mu stands for every axle's friction
    start: np.ndarray
    G2: np.ndarray
    window: int             # samples of the moving averages (AVERAGE_S at the observer's sample time)
    prior: tuple            # published (C_f, C_r) of the parameter file's [prior], or None
    mu_reached: float       # the friction the log's combined acceleration reaches (ENVELOPE_QUANTILE)


def log_columns(module, source: str) -> dict:
    """{the model's signal (states, known inputs, speed, ``y_`` outputs): the shared log's column},
    by role (:func:`.representation.signals`): the lateral speed ``vy``, the yaw rate ``yaw_rate``,
    the forward speed ``vx``, the steering angle ``delta``, the lateral acceleration ``ay``; a further
    known input only by the built-in model's name ``a_x`` (``ax``: nothing in the structure says a
    measured signal is the longitudinal acceleration)."""
    from .representation import signals
    s = signals(module, getattr(module, "__file__", None) or source)
    return {s.lateral_speed: "vy", s.yaw_rate: "yaw_rate", s.speed: "vx", s.steering: "delta", "a_x": "ax",
            f"y_{s.a_y}": "ay", f"y_{s.yaw_rate_output}": "yaw_rate"}


DERIVED_YAW_ACC = ("yaw acceleration: the log records none; derived from the yaw rate as numpy.gradient(yaw_rate, t) "
                   "on the observer's grid over the samples read (a recorded one: [data.fit] yaw_acceleration)")
"""The line the fit prints when it derives the yaw acceleration."""


def yaw_acceleration(run, a: int, b: int) -> np.ndarray:
    """The yaw acceleration [rad/s^2] over samples a..b-1: the log's ``yaw_acc`` where it records one, else
    ``numpy.gradient(yaw_rate, t)`` of the range alone (no sample outside it is read)."""
    if run.yaw_acc is not None:
        return np.asarray(run.yaw_acc, float)[a:b]
    return np.gradient(np.asarray(run.yaw_rate, float)[a:b], np.asarray(run.t, float)[a:b])


def read_run(config, path) -> tuple:
    """``(run, notes)``: a log as the fit reads it (a :class:`~codegen.validation.stanford.StanfordRun`,
    ``yaw_acc`` None where the log records none) and the lines its reading adds to the output (the channels
    resampled, the log checks' warnings): through the observer file's ``[data]`` map when it has one, as
    ``uiogen validate --data`` reads it (:class:`codegen.validation.logs.MappedLog`), else in the shared
    format (:func:`codegen.validation.stanford.load`)."""
    if config.column_map is None:
        return stanford.load(path, sample_time=config.sample_time), []
    from ...project.columns import UNITS, model_unit
    from ...validation import logs
    from .representation import signals
    module = config.load_model_module()
    s = signals(module, config.source)
    inputs = [*s.known_inputs, *(f"y_{n}" for n in s.outputs), s.speed]
    outputs = [s.lateral_speed, s.yaw_rate]
    cmap = config.column_map
    if s.lateral_speed not in cmap.truth:
        raise ConfigurationError(f"{cmap.source}: [data.truth] {s.lateral_speed} is missing: uiogen fit judges the "
                                 f"sideslip atan2({s.lateral_speed}, {s.speed}) against the log's reference; allowed: "
                                 f"{s.lateral_speed} = {{ column = \"...\", unit = \"...\" }} in [data.truth], the "
                                 f"log's lateral speed reference", source=cmap.source, section="data.truth",
                                 key=s.lateral_speed, allowed="the log's lateral speed reference")
    p = stanford._resolve(path)
    log = logs.MappedLog(config, p, inputs, outputs, config.sample_time, fit_signals=("yaw_acceleration",))
    parts = {}
    for t, ins, refs, extra in log.chunks():
        for k, v in {"t": t, **ins, **{f"truth:{n}": x for n, x in refs.items()},
                     **{f"fit:{n}": x for n, x in extra.items()}}.items():
            parts.setdefault(k, []).append(v)
    report = log.finish()
    notes = [x for x in [logs.resampled_line(log.resampling)] if x]
    notes += [f"warning: {w}" for w in [*log.warnings, *report["warnings"]]]
    model, cols, out = module.MODEL, log_columns(module, config.source), {"t": np.concatenate(parts["t"])}
    for key in [*inputs, *(f"truth:{n}" for n in outputs)]:        # a measured input before a reference
        sig = key.removeprefix("truth:")
        col = cols.get(sig)
        if col is None or col in out or key not in parts:
            continue
        x = np.concatenate(parts[key])                  # in the model's unit: to the shared format's (SI)
        unit, shared = model_unit(model, sig), stanford.UNITS[col]
        if unit in UNITS and UNITS[unit][0] == UNITS[shared][0] and unit != shared:
            x = x * (UNITS[unit][1] / UNITS[shared][1])
        out[col] = x
    lacking = [c for c in ("vx", "vy", "ay", "yaw_rate", "delta", "ax") if c not in out]
    if lacking:
        said = ", ".join(f"{k} as {v}" for k, v in cols.items())
        raise ConfigurationError(f"{cmap.source}: uiogen fit reads {', '.join(lacking)} through the observer's inputs "
                                 f"and outputs ({said}); model {model.name!r} has no signal for them",
                                 source=cmap.source, section="data")
    vx, vy = out["vx"], out["vy"]
    # delta_fl, delta_fr: the fit reads neither (the mean road-wheel angle stands for both)
    return stanford.StanfordRun(t=out["t"], vx=vx, vy=vy, beta_true=np.arctan2(vy, vx), ax=out["ax"], ay=out["ay"],
                                yaw_rate=out["yaw_rate"], yaw_acc=(np.concatenate(parts["fit:yaw_acceleration"])
                                                                   if "fit:yaw_acceleration" in parts else None),
                                delta=out["delta"], delta_fl=out["delta"],
                                delta_fr=out["delta"], source=str(p)), notes


def _problem(config, params, run, a: int, b: int) -> _Problem:
    module = config.load_model_module()
    model = module.MODEL
    from ...model import parameter_substitution
    subs = parameter_substitution(model, params)
    axles = module.AXLES
    stiff = tuple(ax.stiffness for ax in axles)
    fric = tuple(ax.friction for ax in axles)
    mu = sp.Symbol("mu_common", positive=True)
    keep = {s: v for s, v in subs.items() if s not in (*stiff, *fric)}
    zero_w = {w: 0 for w in model.unknown_inputs}
    vy, r = model.states
    vx = model.scheduling[0].symbol
    columns = log_columns(module, config.source)
    symbols = (vy, r, *model.known_inputs, vx)
    missing = [str(s) for s in symbols if str(s) not in columns]
    if missing:
        raise SampleError(f"{config.name}: the fit reads the shared log's columns; the model's signals "
                          f"{', '.join(missing)} are not among them (the log's {', '.join(sorted(set(columns.values())))}"
                          f" are read as the model's {', '.join(k for k in columns if not k.startswith('y_'))})")
    signals = {s: np.asarray(getattr(run, columns[str(s)]), float)[a:b] for s in symbols}
    in_forces = [sp.sympify(e).subs(subs) for e in (module.A_Y_IN_FORCES, module.DYNAMICS_IN_FORCES[1])]
    G2 = np.array(sp.Matrix(in_forces).jacobian(sp.Matrix(module.FORCES)).tolist(), dtype=float)
    meas = np.linalg.solve(G2, np.vstack([np.asarray(run.ay, float)[a:b], yaw_acceleration(run, a, b)])).T
    values = {**keep, **zero_w, **{f: mu for f in fric}}
    exprs = [numeric(e, values) for e in (module.Phi_f, module.Phi_r)]
    fns = [sp.lambdify([*symbols, *stiff, mu], e, "numpy") for e in exprs]
    args = [signals[s] for s in symbols]

    def forces(x):
        return np.column_stack([fn(*args, *x) for fn in fns])
    others = {u: 0 for u in model.known_inputs if columns[str(u)] != "delta"}     # the static capacity: a_x = 0
    static = [float(numeric(ax.peak, {**subs, **{f: 1 for f in fric}, **others})) for ax in axles]
    start = np.array([15.0 * fz for fz in static] + [1.0])       # 15 F_z per rad, mu = 1: a physical prior
    n = window(config.sample_time)
    prior = None
    if all(str(c) in params.prior for c in stiff):
        prior = tuple(float(params.prior[str(c)]["value"]) for c in stiff)
    return _Problem(signals, meas, forces, (*stiff, mu), start, G2, n, prior, mu_reached(run, a, b, n, subs))


ENVELOPE_QUANTILE = 0.995
"""The friction the log reaches: this quantile of |(a_x, a_y)| / g over the range (AVERAGE_S averages): a
lower bound of the day's friction that one spike of the averages does not set."""


def mu_reached(run, a: int, b: int, n: int, subs: dict) -> float:
    g = next((float(v) for k, v in subs.items() if str(k) == "g"), 9.81)
    acc = np.hypot(_average(np.asarray(run.ax, float)[a:b], n), _average(np.asarray(run.ay, float)[a:b], n))
    return float(np.quantile(acc, ENVELOPE_QUANTILE) / g)


CANDIDATES = ("fitted", "published")
"""The tyre sets a fit judges: ``fitted``, the three numbers from the log (from the physical start);
``published``, the parameter file's ``[prior]`` stiffnesses with the friction alone from the log (never
below the friction the log reaches). With ``--folds`` the one with the lower pooled held-out sideslip RMS
is written; without, ``fitted``."""


def _tyre_fit(prob: _Problem, mask: np.ndarray, candidate: str = "fitted") -> np.ndarray:
    """(C_f, C_r, mu) of ``candidate`` by least squares on the masked averages."""
    from scipy.optimize import least_squares
    n = prob.window
    m_avg = np.column_stack([_average(prob.measured[:, k], n) for k in range(2)])
    W = np.diag([1.0, YAW_LEVER]) @ prob.G2          # axle forces -> (a_y, YAW_LEVER r')

    def residual_at(x):
        f = prob.forces(x)
        res = m_avg - np.column_stack([_average(f[:, k], n) for k in range(2)])
        return (res[mask] @ W.T).ravel()
    if candidate == "published":
        c = np.array(prob.prior)
        sol = least_squares(lambda q: residual_at(np.array([c[0], c[1], q[0]])), np.array([max(1.0, prob.mu_reached)]),
                            bounds=([prob.mu_reached], [np.inf]), method="trf")
        return np.array([c[0], c[1], sol.x[0]])
    scale = prob.start
    sol = least_squares(lambda q: residual_at(q * scale), np.ones(3), x_scale=np.ones(3), method="trf")
    return sol.x * scale


def _levels(prob: _Problem, x: np.ndarray, run, a: int, b: int, Ts: float, mask: np.ndarray) -> dict:
    f = prob.forces(x)
    n = prob.window
    res = np.column_stack([_average(prob.measured[:, k] - f[:, k], n) for k in range(2)])[mask]
    from scipy.signal import savgol_filter
    half = n // 2
    ddv = savgol_filter(np.asarray(run.vy, float)[a:b], n, 3, deriv=2, delta=Ts)[half:b - a - half][mask]
    ddr = savgol_filter(np.asarray(run.yaw_rate, float)[a:b], n, 3, deriv=2, delta=Ts)[half:b - a - half][mask]
    inner = np.zeros(b - a, bool)
    inner[half:b - a - half] = mask
    return {"sigma_force_front": float(np.sqrt(np.mean(res[:, 0] ** 2))),
            "sigma_force_rear": float(np.sqrt(np.mean(res[:, 1] ** 2))),
            "sigma_ay": highpass_std(np.asarray(run.ay, float)[a:b][inner]),
            "sigma_r": highpass_std(np.asarray(run.yaw_rate, float)[a:b][inner]),
            "sigma_euler_vy": float(0.5 * Ts * np.sqrt(np.mean(ddv ** 2))),
            "sigma_euler_r": float(0.5 * Ts * np.sqrt(np.mean(ddr ** 2)))}


def _with_values(params, values: dict):
    return dataclasses.replace(params, values={**params.values, **values})


def tyre_values(config, fitted: np.ndarray) -> dict:
    """{parameter name: rounded value} of the fitted stiffnesses and the common friction."""
    module = config.load_model_module()
    out = {str(ax.stiffness): _round(c) for ax, c in zip(module.AXLES, fitted[:2])}
    out.update({str(ax.friction): _round(fitted[2]) for ax in module.AXLES})
    return out


def _rounded(config, tyre: dict) -> np.ndarray:
    """(C_f, C_r, mu) of the rounded values, in the order the forces take them."""
    axles = config.load_model_module().AXLES
    return np.array([tyre[str(ax.stiffness)] for ax in axles] + [tyre[str(axles[0].friction)]])


def observer_beta(config, params, design: dict, run, a: int, b: int) -> np.ndarray:
    """The sideslip estimate [rad] of the observer designed with ``params`` and ``design`` overrides
    over samples a..b-1 (the CasADi step, no files written)."""
    from ...design.solver import FreshSolver
    from .build import build
    cfg = dataclasses.replace(config, design={**config.design, **design})
    obs = build(cfg, FreshSolver(), params=params)
    f = obs.step_function(parametric=True)
    nu = obs.nu
    z, x = ca.SX.sym("z", 4), ca.SX.sym("x", nu + 3)
    step = ca.Function("step", [z, x], [f(z, x[:nu], x[nu:nu + 2], x[nu + 2:])[0]])
    cols = log_columns(config.load_model_module(), config.source)
    X = np.column_stack([np.asarray(getattr(run, cols[n]), float)[a:b] for n in obs.input_names])
    zs = np.array(step.mapaccum(b - a)(np.zeros(4), X.T).full())
    return np.arctan2(zs[2], np.asarray(run.vx, float)[a:b])


def _sub_run(run, a: int, b: int):
    return stanford.StanfordRun(**{f.name: (getattr(run, f.name)[a:b] if getattr(run, f.name) is not None
                                            and f.name != "source" else getattr(run, f.name))
                                   for f in dataclasses.fields(run)})


def _same_tyre_peers(config, params, run, noises, which=("ekf_nonlinear_tyre",)) -> list:
    """The same-tyre Kalman peers ``which`` on ``run`` with the numbers of ``params`` (through a parameter
    file of their own, as :func:`codegen.validation.peers.nonlinear_tyre_peers` reads one), one
    {peer: BaselineResult} per {sigma_fy, sigma_ay} of ``noises``."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "parameters.toml"
        path.write_text(_parameter_text(config.parameter_path, params.values, {}))
        return [nonlinear_tyre_peers(run, path, noise, which=which) for noise in noises]


def _ekf_beta(config, params, run, a: int, b: int, noise: dict) -> np.ndarray:
    """The same-tyre EKF's sideslip [rad] over samples a..b-1 at the {sigma_fy, sigma_ay} ``noise``."""
    return _same_tyre_peers(config, params, _sub_run(run, a, b), [noise])[0]["ekf_nonlinear_tyre"].beta


PEER_NOISES = tuple({"sigma_fy": fy, "sigma_ay": ay} for fy in PEER_GRID["sigma_fy"] for ay in PEER_GRID["sigma_ay"])
"""The EKF grid's noise levels, in the order of its table."""


def _best_peer(betas: list, run, a: int, b: int) -> tuple:
    """The EKF grid on the range from its runs at :data:`PEER_NOISES`: (best {sigma_fy, sigma_ay},
    [(sigma_fy, sigma_ay, rms), ...])."""
    truth = np.asarray(run.beta_true, float)[a:b]
    rows = [(g["sigma_fy"], g["sigma_ay"], _rms_deg(beta - truth)) for g, beta in zip(PEER_NOISES, betas)]
    fy, ay, _ = min(rows, key=lambda t: t[2])
    return {"sigma_fy": fy, "sigma_ay": ay}, rows


def _rms_deg(err: np.ndarray) -> float:
    """RMS [deg] of a sideslip error [rad]."""
    return float(np.degrees(np.sqrt(np.mean(np.square(err)))))


def _max_deg(err: np.ndarray) -> float:
    """Largest |error| [deg] of a sideslip error [rad]."""
    return float(np.degrees(np.max(np.abs(err))))


def _identified(config, prob, run, a: int, b: int, x: np.ndarray, mask: np.ndarray) -> dict:
    """The rounded tyre of ``x`` and the noise levels on ``mask``: what the observer of a fold is designed with."""
    tyre = tyre_values(config, x)
    levels = {k: _round(v) for k, v in _levels(prob, _rounded(config, tyre), run, a, b, config.sample_time,
                                                mask).items()}
    return {"parameters": tyre, "design": levels}


DEFAULT_FOLDS = 5
"""Folds when the parameter file has a ``[prior]`` and ``folds`` is not given: the choice between the tyre
sets is made on held-out data, never by default for the fitted one."""


def fit(config, path="stanford", samples: str = "", folds: int | None = None, peers: bool = True, judge=(),
        choose=(), jobs: int | None = None) -> dict:
    """Identify the tyre, the noise levels and the peers' noise levels on samples A..B-1 of a log; with
    ``folds`` >= 2, judge every tyre set of :data:`CANDIDATES` the parameter file allows on held-out
    contiguous folds and keep the better (module docstring); ``judge``: other runs of the same car (paths
    or shorthands), on which the observer designed with the fitted numbers and its same-tyre peers run
    (:func:`_run_row`); ``choose``: ``[(KEY, [values...]), ...]`` of ``design.*`` settings, every
    combination cross-validated with the tyre sets and the best written (:func:`_chosen_design`); ``jobs``:
    the processes the folds' designs and the peers' grid run on (:func:`parse_jobs`; the result is the same
    with any number)."""
    with Workers(parse_jobs(jobs)) as workers:
        return _fit(config, path, samples, folds, peers, judge, choose, workers)


def _fit(config, path, samples: str, folds, peers: bool, judge, choose, workers: Workers) -> dict:
    if folds is not None and (not isinstance(folds, int) or isinstance(folds, bool) or folds < 0 or folds == 1):
        raise ConfigurationError(f"--folds {folds!r}: 0 (no cross-validation) or an integer >= 2",
                                 source="--folds", key="--folds", value=folds)
    run, notes = read_run(config, path)
    a, b = parse_samples(samples, run.n)
    params = load_parameters(config.parameter_path)
    prob = _problem(config, params, run, a, b)
    if folds is None:
        folds = DEFAULT_FOLDS if prob.prior is not None else 0
    if folds:
        _check_folds(folds, a, b, prob.window)
    candidates = [c for c in CANDIDATES if c == "fitted" or prob.prior is not None]
    settings_table, chosen = None, {}
    if choose:
        if not folds:
            raise ConfigurationError("--choose picks settings by their pooled held-out sideslip RMS: it needs "
                                     "--folds K (K >= 2)", source="--choose", key="--choose", value=choose)
        config, chosen, settings_table, cv = _chosen_design(config, params, prob, run, a, b, folds, candidates,
                                                            choose, workers)
    else:
        cv = _cross_validate(config, params, prob, run, a, b, folds, candidates, workers) if folds else None
    choice = min(candidates, key=lambda c: cv["pooled"][c]) if cv else "fitted"
    half = prob.window // 2
    full = np.ones(b - a - 2 * half, bool)
    x = _tyre_fit(prob, full, choice)
    tyre = tyre_values(config, x)
    fitted_params = _with_values(params, tyre)
    levels = {k: _round(v) for k, v in _levels(prob, _rounded(config, tyre), run, a, b, config.sample_time,
                                               full).items()}
    out = {"observer": config.name, "data": str(path), "samples": [a, b],
           "t_range": [float(run.t[a] - run.t[0]), float(run.t[b - 1] - run.t[0])],
           "parameters": tyre, "design": {**levels, **chosen}, "start": prob.start.tolist(), "choice": choice,
           "window_samples": prob.window, "mu_reached": _round(prob.mu_reached)}
    if run.yaw_acc is None:
        out["yaw_acceleration"] = "derived"
    if prob.prior is not None:
        out["prior"] = {k: dict(v) for k, v in params.prior.items()}
    if settings_table is not None:
        out["settings"] = settings_table
    judged = []
    for p in judge:                                   # every log read before the work
        other, said = read_run(config, p)
        judged.append(other)
        notes += [f"{p}: {x}" for x in said]
    # the observer of the written numbers and the peers' grid: independent runs, over the same processes
    beta, *peer_betas = workers.map([(observer_beta, (config, fitted_params, levels, run, a, b)),
                                     *((_ekf_beta, (config, fitted_params, run, a, b, g)) for g in PEER_NOISES if peers)])
    if peers:
        best, rows = _best_peer(peer_betas, run, a, b)
        out["peers"] = {k: (v if v is not None else "highpass") for k, v in best.items()}
        out["peer_grid"] = [[fy, ay if ay is not None else "highpass", rms] for fy, ay, rms in rows]
        if cv:
            _peer_folds(config, params, run, a, b, cv, choice, best, workers)
    if notes:
        out["log_notes"] = notes
    out["observer_beta_rms_deg"] = _rms_deg(beta - run.beta_true[a:b])
    if judge:
        noise = _peer_levels(config, out)
        out["runs"] = [_run_row(config, fitted_params, levels, noise, _sub_run(run, a, b), f"{path} (the fit, {a}:{b})",
                                beta)]
        out["runs"] += [_run_row(config, fitted_params, levels, noise, other, str(p)) for p, other in zip(judge, judged)]
    if cv:
        rows = cv["folds"]
        out["cross_validation"] = [{"fold": r["fold"], **r[choice]} for r in rows]
        out["cross_validated_rms_deg"] = cv["pooled"][choice]
        out["candidates"] = {c: {"pooled_rms_deg": cv["pooled"][c], "max_abs_deg": cv["max"][c]} for c in candidates}
        if "ekf" in cv["pooled"]:
            out["peer_cross_validated_rms_deg"] = cv["pooled"]["ekf"]
            out["peer_max_abs_deg"] = cv["max"]["ekf"]
        out["uncertainty"] = _jackknife(out["cross_validation"], tyre)
        out["table"] = _table(out, rows, candidates, choice)
    return out


PEERS = ("ekf_nonlinear_tyre", "ukf_nonlinear_tyre")


def _peer_levels(config, result: dict) -> dict:
    """The peers' two noise levels: the fit's grid choice, else the parameter file's ``[meta]``."""
    if "peers" in result:
        return {k: (None if v == "highpass" else float(v)) for k, v in result["peers"].items()}
    return peer_noise(config.parameter_path)


def _run_row(config, params, levels: dict, noise: dict, run, label: str, beta=None) -> dict:
    """One run judged: the observer designed with ``params`` and ``levels`` and the same-tyre EKF and UKF
    (``noise``), each from its initial state; sideslip RMS and largest error [deg], the series for a plot."""
    if beta is None:
        beta = observer_beta(config, params, levels, run, 0, run.n)
    (peers,) = _same_tyre_peers(config, params, run, [noise], PEERS)
    truth = np.asarray(run.beta_true, float)
    series = {"observer": np.asarray(beta, float), **{k: np.asarray(v.beta, float) for k, v in peers.items()}}
    return {"data": label, "samples": int(run.n),
            "estimators": {k: {"rms_deg": _rms_deg(v - truth), "max_abs_deg": _max_deg(v - truth)}
                           for k, v in series.items()},
            "series": {"t": np.asarray(run.t, float) - float(run.t[0]), "truth": truth, **series}}


def plot_runs(result: dict, path) -> None:
    """The sideslip of the fit run and every judged run, truth and estimates, one panel a run (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs = result["runs"]
    fig, axes = plt.subplots(len(runs), 1, figsize=(10, 3 * len(runs)), squeeze=False)
    for ax, row in zip(axes[:, 0], runs):
        s = row["series"]
        ax.plot(s["t"], np.degrees(s["truth"]), "k", lw=1.2, label="reference")
        for name in ("observer", *PEERS):
            e = row["estimators"][name]
            ax.plot(s["t"], np.degrees(s[name]), lw=0.8, label=f"{name} (RMS {e['rms_deg']:.3f}°, max {e['max_abs_deg']:.2f}°)")
        ax.set_title(row["data"], fontsize=9)
        ax.set_ylabel("β [deg]")
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("t - t_0 [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _jackknife(rows: list, tyre: dict) -> dict:
    """{parameter: block-jackknife standard error} from the K fits that each left one contiguous fold out:
    sqrt((K-1)/K sum (theta_k - mean)^2), the spread a fit on this much log has."""
    k = len(rows)
    return {name: _round(float(np.sqrt((k - 1) / k * np.sum((np.array([r["parameters"][name] for r in rows])
                                                            - np.mean([r["parameters"][name] for r in rows])) ** 2))))
            for name in tyre}


def _table(out: dict, rows: list, candidates: list, choice: str) -> dict:
    """Per held-out fold: each candidate's tyre and held-out sideslip RMS, the same-tyre EKF's beside the
    chosen one; pooled; the written numbers with their jackknife standard errors."""
    names = list(out["parameters"])
    header = ["held-out fold (samples)"]
    for c in candidates:
        header += [f"{c}: {n}" for n in names] + [f"{c}: β RMSE on the fold [deg]"]
    with_peer = "peer_cross_validated_rms_deg" in out
    if with_peer:
        header.append(f"EKF ({choice} tyre): β RMSE on the fold [deg]")
    body = []
    for r in rows:
        line = [f"{r['fold'][0]}–{r['fold'][1] - 1}"]
        for c in candidates:
            line += [r[c]["parameters"][n] for n in names] + [r[c]["held_out_rms_deg"]]
        if with_peer:
            line.append(r["ekf_held_out_rms_deg"])
        body.append(line)
    pooled = ["pooled over the folds"]
    for c in candidates:
        pooled += [None for _ in names] + [out["candidates"][c]["pooled_rms_deg"]]
    if with_peer:
        pooled.append(out["peer_cross_validated_rms_deg"])
    a, b = out["samples"]
    written = [f"{a}–{b - 1}: {choice} (written)"]
    for c in candidates:
        written += ([f"{out['parameters'][n]:g} ± {out['uncertainty'][n]:.2g}" for n in names] + [None]
                    if c == choice else [None for _ in names] + [None])
    if with_peer:
        written.append(None)
    return {"header": header, "rows": body + [pooled, written]}


def _fold_edges(a: int, b: int, folds: int) -> list:
    return [a + ((b - a) * k) // folds for k in range(folds + 1)]


def _fold_sizes(a: int, b: int, folds: int, n: int = WINDOW) -> tuple:
    """(smallest held-out fold, smallest training set) in samples; a training set is the range less its
    fold and the ``n``-sample guard on each side of it (no average on one side may see the other)."""
    edges = _fold_edges(a, b, folds)
    held = [hi - lo for lo, hi in zip(edges, edges[1:])]
    train = [(b - a) - h - n * ((lo > a) + (hi < b)) for h, lo, hi in zip(held, edges, edges[1:])]
    return min(held), min(train)


def _check_folds(folds: int, a: int, b: int, n: int = WINDOW) -> None:
    """Every held-out fold and every training set at least MIN_SAMPLES, as for a fit (ConfigurationError)."""
    held, train = _fold_sizes(a, b, folds, n)
    if held >= MIN_SAMPLES and train >= MIN_SAMPLES:
        return
    most = max((k for k in range(2, (b - a) // MIN_SAMPLES + 1) if min(_fold_sizes(a, b, k, n)) >= MIN_SAMPLES),
               default=None)
    allowed = (f"2..{most} for samples {a}:{b}" if most else
               f"none for samples {a}:{b}: cross-validation needs at least {2 * MIN_SAMPLES + n} samples")
    raise ConfigurationError(f"--folds {folds}: the smallest held-out fold has {held} samples and the smallest "
                             f"training set {train}; each needs at least {MIN_SAMPLES} ({MIN_SAMPLES / 100:g} s at "
                             f"100 Hz); allowed: {allowed}", source="--folds", key="--folds", value=folds)


def _cross_validate(config, params, prob, run, a, b, folds, candidates, workers: Workers) -> dict:
    """Each candidate fitted on the range less one contiguous fold (and a guard of one average on each
    side), designed, run over the range and judged on the fold; the folds over ``workers``."""
    n = prob.window
    half = n // 2
    edges = _fold_edges(a, b, folds)
    idx = np.arange(a + half, b - half)              # samples the averages cover
    fitted = []

    def designs():                          # each fold's design goes to the workers once its tyre is fitted
        for k in range(folds):
            lo, hi = edges[k], edges[k + 1]
            train = (idx < lo - n) | (idx >= hi + n)
            for c in candidates:
                fitted.append((k, c, _identified(config, prob, run, a, b, _tyre_fit(prob, train, c), train)))
                f = fitted[-1][2]
                yield observer_beta, (config, _with_values(params, f["parameters"]), f["design"], run, a, b)
    betas = workers.map(designs())
    rows = [{"fold": [edges[k], edges[k + 1]]} for k in range(folds)]
    errors = {c: [] for c in candidates}
    for (k, c, identified), beta in zip(fitted, betas):
        lo, hi = edges[k], edges[k + 1]
        err = beta - run.beta_true[a:b]
        errors[c].append(err[lo - a:hi - a])
        rows[k][c] = {**identified, "held_out_rms_deg": _rms_deg(err[lo - a:hi - a]),
                      "training_rms_deg": _rms_deg(np.concatenate([err[:lo - a], err[hi - a:]]))}
    pooled = {c: _rms_deg(np.concatenate(errors[c])) for c in candidates}
    biggest = {c: _max_deg(np.concatenate(errors[c])) for c in candidates}
    return {"folds": rows, "pooled": pooled, "max": biggest}


def _chosen_design(config, params, prob, run, a, b, folds, candidates, choose, workers: Workers) -> tuple:
    """Every combination of the ``design.*`` values of ``choose`` cross-validated with every tyre set;
    (the config with the best combination, {key: value} of it, the table of every combination, its
    cross-validation). A combination the design refuses (no certificate) is a row of the table."""
    import itertools
    from ...errors import REFUSALS
    keys = [k for k, _ in choose]
    bad = [k for k in keys if not k.startswith("design.") or k.count(".") != 1]
    if bad:
        raise ConfigurationError(f"--choose {bad[0]}: the fit chooses [design] settings only (design.KEY, e.g. "
                                 f"design.decay_fraction=[0.1, 0.2]); the tyre sets are its own choice",
                                 source="--choose", key=bad[0])
    if len(set(keys)) != len(keys):
        raise ConfigurationError(f"--choose: a key given twice in {keys}", source="--choose", key=keys)
    rows, best = [], None
    for values in itertools.product(*[v for _, v in choose]):
        setting = {k.split(".", 1)[1]: v for k, v in zip(keys, values)}
        cfg = dataclasses.replace(config, design={**config.design, **setting})
        try:
            cv = _cross_validate(cfg, params, prob, run, a, b, folds, candidates, workers)
        except REFUSALS as exc:
            rows.append([*values, *([None] * len(candidates)), f"{type(exc).__name__}: {str(exc).splitlines()[0]}"])
            continue
        rows.append([*values, *(cv["pooled"][c] for c in candidates), "certified"])
        score = min(cv["pooled"][c] for c in candidates)
        if best is None or score < best[0]:
            best = (score, cfg, setting, cv)
    if best is None:
        raise CertificateError(f"--choose: the design refuses every combination ({rows[0][-1]}); see uiogen sweep for "
                               f"the settings that certify")
    table = {"header": [*keys, *(f"{c}: pooled held-out β RMSE [deg]" for c in candidates), "outcome"], "rows": rows,
             "keys": keys, "candidates": list(candidates)}
    return best[1], best[2], table, best[3]


def _peer_folds(config, params, run, a: int, b: int, cv: dict, choice: str, noise: dict, workers: Workers) -> None:
    """The same-tyre EKF on each fold with the tyre ``choice`` fitted without it (its two noise levels
    those the grid chose on the whole range: an advantage to the peer), added to ``cv``."""
    truth, errors = np.asarray(run.beta_true, float)[a:b], []
    betas = workers.map([(_ekf_beta, (config, _with_values(params, row[choice]["parameters"]), run, a, b, noise))
                         for row in cv["folds"]])
    for row, beta in zip(cv["folds"], betas):
        lo, hi = row["fold"]
        err = (beta - truth)[lo - a:hi - a]
        row["ekf_held_out_rms_deg"] = _rms_deg(err)
        errors.append(err)
    cv["pooled"]["ekf"] = _rms_deg(np.concatenate(errors))
    cv["max"]["ekf"] = _max_deg(np.concatenate(errors))


# --- the files --------------------------------------------------------------------------------------

def _toml(v) -> str:
    """A setting's value as TOML writes it: a bool as true/false (not the 1.0 a float of it would be)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    return f'"{v}"' if isinstance(v, str) else repr(float(v))


def _set_values(text: str, table: str, values: dict) -> str:
    """``text`` (TOML) with the values of ``KEY = VALUE`` lines of ``[table]`` replaced, comments kept;
    a key the table lacks is appended at its end."""
    lines = text.split("\n")
    current, last_of_table, seen = None, None, set()
    for i, line in enumerate(lines):
        head = re.match(r"\s*\[([^\]]+)\]", line)
        if head:
            current = head.group(1).strip()
            continue
        if current != table:
            continue
        m = re.match(r"(\s*)([A-Za-z_][\w]*)(\s*=\s*)(\"[^\"]*\"|[^#\s]+)(\s*)(#.*)?$", line)
        if m:
            last_of_table = i
            if m.group(2) in values:
                v = values[m.group(2)]
                new = _toml(v)
                pad = max(1, len(m.group(4)) + len(m.group(5)) - len(new)) if m.group(6) else 0
                lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{new}{' ' * pad}{m.group(6) or ''}".rstrip()
                seen.add(m.group(2))
    rest = [k for k in values if k not in seen]
    if rest:
        if last_of_table is None:
            raise ConfigurationError(f"no [{table}] table to write {', '.join(rest)} into")
        add = [f"{k} = {_toml(values[k])}" for k in rest]
        lines[last_of_table + 1:last_of_table + 1] = add
    return "\n".join(lines)


def _parameter_text(path: Path, values: dict, meta: dict) -> str:
    text = Path(path).read_text()
    text = _set_values(text, "parameters", values)
    return _set_values(text, "meta", meta) if meta else text


def files(config, result: dict) -> dict:
    """{path: new text} of the parameter file and the observer file with the fitted values."""
    meta = {}
    if "peers" in result:
        meta = {f"peer_{k}": str(v) for k, v in result["peers"].items()}
    return {Path(config.parameter_path): _parameter_text(config.parameter_path, result["parameters"], meta),
            Path(config.source): _set_values(Path(config.source).read_text(), "design", result["design"])}


def lines(result: dict) -> list:
    a, b = result["samples"]
    t0, t1 = result["t_range"]
    p = result["parameters"]
    unc = result.get("uncertainty", {})
    out = [f"uiogen fit {result['observer']} on {result['data']}, samples {a}:{b} (t - t_0 in [{t0:g}, {t1:g}] s, "
           f"{b - a} samples)",
           *(f"  {x}" for x in result.get("log_notes", ())),
           *([f"  {DERIVED_YAW_ACC}"] if result.get("yaw_acceleration") == "derived" else []),
           f"  tyre (least squares of a_y and {YAW_LEVER:g} m x the yaw acceleration against the model's at the log's "
           f"own velocities, {AVERAGE_S:g} s averages"
           + (f" of {result['window_samples']} samples" if "window_samples" in result else "") + "):"]
    if "prior" in result:
        out.append("    published ([prior]): " + ", ".join(
            f"{k} = {v['value']:g} ± {100 * v['rel_sigma']:g} %" + (f" ({v['source']})" if v.get("source") else "")
            for k, v in result["prior"].items()))
    if "mu_reached" in result:
        out.append(f"    the log's combined acceleration reaches mu >= {result['mu_reached']:g} "
                   f"({100 * ENVELOPE_QUANTILE:g}th percentile of |(a_x, a_y)| / g)")
    if "settings" in result:
        t = result["settings"]
        k, names = len(t["keys"]), t["candidates"]
        out.append("    [design] settings judged on the same folds (pooled held-out beta RMS, deg):")
        for row in t["rows"]:
            what = ", ".join(f"{key}={_toml(v) if isinstance(v, bool) else v}" for key, v in zip(t["keys"], row[:k]))
            said = (", ".join(f"{c} {v:.4f}" for c, v in zip(names, row[k:-1])) if row[-1] == "certified"
                    else row[-1])
            out.append(f"      {what}: {said}")
    for c, v in result.get("candidates", {}).items():
        out.append(f"    {c}: pooled held-out beta RMS {v['pooled_rms_deg']:.4f} deg (largest {v['max_abs_deg']:.2f})"
                   + ("  <- chosen" if c == result["choice"] else ""))
    if "peer_cross_validated_rms_deg" in result:
        out.append(f"    same-tyre EKF on the same folds: {result['peer_cross_validated_rms_deg']:.4f} deg (largest "
                   f"{result['peer_max_abs_deg']:.2f})")
    out += ["  " + result.get("choice", "fitted") + ": " + ", ".join(
                f"{k} = {v:g}" + (f" ± {unc[k]:.2g}" if k in unc else "") for k, v in p.items())
            + (" (± block-jackknife standard error over the folds)" if unc else ""),
            "  noise levels of the l2-gain design" + (" and the settings chosen" if "settings" in result else "")
            + " ([design]):",
            "    " + ", ".join(f"{k} = {_toml(v)}" if isinstance(v, bool) else f"{k} = {v:g}"
                           if isinstance(v, (int, float)) else f"{k} = {v!r}"
                           for k, v in result["design"].items())]
    if "peers" in result:
        out += ["  Kalman peers (EKF grid, beta RMS on the range): "
                + ", ".join(f"{k} = {v}" for k, v in result["peers"].items())]
    out.append(f"  the observer designed with these numbers: beta RMS {result['observer_beta_rms_deg']:.4f} deg on "
               f"the range")
    for row in result.get("cross_validation", []):
        lo, hi = row["fold"]
        out.append(f"  fold {lo}:{hi} held out: " + ", ".join(f"{k} = {v:g}" for k, v in row["parameters"].items())
                   + f"; beta RMS on the fold {row['held_out_rms_deg']:.4f} deg (on the rest "
                   f"{row['training_rms_deg']:.4f})")
    if "cross_validation" in result:
        out.append(f"  cross-validated beta RMS (folds pooled): {result['cross_validated_rms_deg']:.4f} deg")
    if result.get("runs"):
        out.append("  the fitted numbers on the fit run and on the other runs (beta RMS / largest error, deg; "
                   "each estimator from its initial state):")
        names = list(result["runs"][0]["estimators"])
        out.append("    " + f"{'run':44s}" + "".join(f"{n:>22s}" for n in names))
        for row in result["runs"]:
            out.append("    " + f"{row['data'][-44:]:44s}" + "".join(
                f"{row['estimators'][n]['rms_deg']:>13.4f} / {row['estimators'][n]['max_abs_deg']:<6.2f}" for n in names))
    return out
