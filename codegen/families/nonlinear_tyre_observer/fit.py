"""``uiogen fit``: a nonlinear-tyre observer's numbers identified on a declared sample range of a log.

The log must carry a sideslip reference (the shared Stanford format: ``vx``, ``vy``, ``ay``,
``yaw_rate``, ``yaw_acc``, ``delta``, ``ax``). Only samples A..B-1 are read for any choice. Fitted:

1. **The tyre** (parameter file): each axle's cornering stiffness and *one* friction coefficient
   for both axles, three numbers, by least squares of the log's a_y and yaw acceleration (the
   latter times :data:`YAW_LEVER`) against the model's, from its axle forces at the log's own
   velocities (v_y = ``vy``, r = ``yaw_rate``). Both sides are averaged over 0.21 s (21 samples
   at 100 Hz): the accelerometers' vibration is not force. The
   fit starts from a physical prior the log does not set (stiffness 15 F_z per rad, mu = 1), never
   from the committed values. m, l_f, l_r, I_z, g and the drive layout stay as the file has them.
2. **The noise levels** of the l2-gain design (observer file ``[design] sigma_*``), each by its
   definition on the range: the axle force residual (RMS of the 0.21 s averages, per axle), the
   sensors' vibration (standard deviation of a_y and r after the source repository's high-pass
   filter, :func:`codegen.validation.stanford.highpass_std`), the Euler residual T_s/2 |x''| (RMS,
   from the reference's second derivative).
3. **The Kalman peers' two noise levels** (parameter file ``[meta] peer_sigma_fy``,
   ``peer_sigma_ay``): the grid sigma_fy in {0.02, 0.05, 0.1, 0.2} x sigma_ay in {high-pass std, 0.3,
   1.0} m/s^2, by the EKF's sideslip RMS on the range.

Values are rounded to four significant digits. ``folds`` > 1 cross-validates inside the range:
the range is cut into that many contiguous folds; for each, 1. and 2. are fitted on the others
(a 0.21 s guard band left out on both sides), the observer designed with them, run over the whole
range, and its sideslip RMS taken on the fold it never saw. Everything is deterministic (closed
forms, scipy's least squares from a fixed start, a fixed grid).
"""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import casadi as ca
import numpy as np
import sympy as sp

from ...errors import ConfigurationError, DatasetError, SampleError
from ...model import load_parameters
from ...validation import stanford
from .representation import numeric

WINDOW = 21                 # samples of the moving averages (0.21 s at 100 Hz)
YAW_LEVER = 1.0             # m: the yaw-acceleration residual [rad/s^2] weighs as this lever times it [m/s^2]
"""Weight of the yaw acceleration beside a_y in the tyre fit, chosen by 5-fold cross-validation inside the
identification part (samples 0-13749; pooled held-out sideslip RMS of the designed observer): 0.1 m 0.2667,
0.3 m 0.2558, 1 m 0.2526 deg, the axle forces themselves (a lever of about I_z / (m l)) 0.2584 deg."""
DIGITS = 4
PEER_GRID = {"sigma_fy": (0.02, 0.05, 0.1, 0.2), "sigma_ay": (None, 0.3, 1.0)}
MIN_SAMPLES = 500


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


def _average(x: np.ndarray) -> np.ndarray:
    """Centered moving average over WINDOW samples, the ends (WINDOW // 2 each) left out."""
    return np.convolve(x, np.full(WINDOW, 1.0 / WINDOW), mode="valid")


@dataclasses.dataclass(frozen=True)
class _Problem:
    """The log's range as the model sees it, and the model's forces as fast numpy functions."""

    signals: dict           # the model's symbols -> arrays over the range
    measured: np.ndarray    # (n, 2) axle forces from (a_y, yaw acceleration)
    forces: object          # (fitted values...) -> (n, 2) model axle forces
    fitted: tuple           # (C_f, C_r, mu) symbols; mu stands for every axle's friction
    start: np.ndarray
    G2: np.ndarray


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
    meas = np.linalg.solve(G2, np.vstack([np.asarray(run.ay, float)[a:b], np.asarray(run.yaw_acc, float)[a:b]])).T
    values = {**keep, **zero_w, **{f: mu for f in fric}}
    exprs = [numeric(e, values) for e in (module.Phi_f, module.Phi_r)]
    fns = [sp.lambdify([*symbols, *stiff, mu], e, "numpy") for e in exprs]
    args = [signals[s] for s in symbols]

    def forces(x):
        return np.column_stack([fn(*args, *x) for fn in fns])
    others = {u: 0 for u in model.known_inputs if columns[str(u)] != "delta"}     # the static capacity: a_x = 0
    static = [float(numeric(ax.peak, {**subs, **{f: 1 for f in fric}, **others})) for ax in axles]
    start = np.array([15.0 * fz for fz in static] + [1.0])       # 15 F_z per rad, mu = 1: a physical prior
    return _Problem(signals, meas, forces, (*stiff, mu), start, G2)


def _tyre_fit(prob: _Problem, mask: np.ndarray) -> np.ndarray:
    from scipy.optimize import least_squares
    m_avg = np.column_stack([_average(prob.measured[:, k]) for k in range(2)])
    scale = prob.start
    W = np.diag([1.0, YAW_LEVER]) @ prob.G2          # axle forces -> (a_y, YAW_LEVER r')

    def residual(q):
        f = prob.forces(q * scale)
        res = m_avg - np.column_stack([_average(f[:, k]) for k in range(2)])
        return (res[mask] @ W.T).ravel()
    sol = least_squares(residual, np.ones(3), x_scale=np.ones(3), method="trf")
    return sol.x * scale


def _levels(prob: _Problem, x: np.ndarray, run, a: int, b: int, Ts: float, mask: np.ndarray) -> dict:
    f = prob.forces(x)
    res = np.column_stack([_average(prob.measured[:, k] - f[:, k]) for k in range(2)])[mask]
    from scipy.signal import savgol_filter
    half = WINDOW // 2
    ddv = savgol_filter(np.asarray(run.vy, float)[a:b], WINDOW, 3, deriv=2, delta=Ts)[half:-half][mask]
    ddr = savgol_filter(np.asarray(run.yaw_rate, float)[a:b], WINDOW, 3, deriv=2, delta=Ts)[half:-half][mask]
    inner = np.zeros(b - a, bool)
    inner[half:b - a - half] = mask
    return {"sigma_force_front": float(np.sqrt(np.mean(res[:, 0] ** 2))),
            "sigma_force_rear": float(np.sqrt(np.mean(res[:, 1] ** 2))),
            "sigma_ay": stanford.highpass_std(np.asarray(run.ay, float)[a:b][inner]),
            "sigma_r": stanford.highpass_std(np.asarray(run.yaw_rate, float)[a:b][inner]),
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
    f = obs.step_function()
    nu = obs.nu
    z, x = ca.SX.sym("z", 4), ca.SX.sym("x", nu + 3)
    step = ca.Function("step", [z, x], [f(z, x[:nu], x[nu:nu + 2], x[nu + 2:])[0]])
    cols = log_columns(config.load_model_module(), config.source)
    X = np.column_stack([np.asarray(getattr(run, cols[n]), float)[a:b] for n in obs.input_names])
    zs = np.array(step.mapaccum(b - a)(np.zeros(4), X.T).full())
    return np.arctan2(zs[2], np.asarray(run.vx, float)[a:b])


def _peers(config, params, run, a: int, b: int) -> tuple:
    """The EKF grid on the range: (best {sigma_fy, sigma_ay}, [(sigma_fy, sigma_ay, rms), ...])."""
    import tempfile
    sub = stanford.StanfordRun(**{f.name: (getattr(run, f.name)[a:b] if f.name != "source" else run.source)
                                  for f in dataclasses.fields(run)})
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "parameters.toml"
        path.write_text(_parameter_text(config.parameter_path, params.values, {}))
        for fy in PEER_GRID["sigma_fy"]:
            for ay in PEER_GRID["sigma_ay"]:
                ekf = stanford.nonlinear_tyre_peers(sub, path, {"sigma_fy": fy, "sigma_ay": ay},
                                                    which=("ekf_nonlinear_tyre",))["ekf_nonlinear_tyre"]
                rows.append((fy, ay, ekf.beta_stats.rms))
    fy, ay, _ = min(rows, key=lambda t: t[2])
    return {"sigma_fy": fy, "sigma_ay": ay}, rows


def fit(config, path="stanford", samples: str = "", folds: int = 0, peers: bool = True) -> dict:
    """Identify the tyre, the noise levels and the peers' noise levels on samples A..B-1 of a log."""
    if not isinstance(folds, int) or folds < 0 or folds == 1:
        raise ConfigurationError(f"--folds {folds!r}: 0 (no cross-validation) or an integer >= 2",
                                 source="--folds", key="--folds", value=folds)
    try:
        run = stanford.load(path, sample_time=config.sample_time)
    except DatasetError as exc:
        if config.column_map is None:
            raise
        # the user mapped their log for validate: say that the fit does not read that map, rather than
        # leave them with the shared format's missing columns (and a did-you-mean to a column in g)
        raise DatasetError(f"{exc}. uiogen fit reads the shared log's format only (columns "
                           f"{', '.join(stanford.COLUMNS)}, SI units); the [data] table of {config.source} maps a "
                           f"log for uiogen validate --data, not for the fit") from None
    a, b = parse_samples(samples, run.n)
    params = load_parameters(config.parameter_path)
    if folds:
        _check_folds(folds, a, b)
    prob = _problem(config, params, run, a, b)
    half = WINDOW // 2
    full = np.ones(b - a - 2 * half, bool)
    x = _tyre_fit(prob, full)
    tyre = tyre_values(config, x)
    fitted_params = _with_values(params, tyre)
    levels = {k: _round(v) for k, v in _levels(prob, _rounded(config, tyre), run, a, b, config.sample_time,
                                               full).items()}
    out = {"observer": config.name, "data": str(path), "samples": [a, b],
           "t_range": [float(run.t[a] - run.t[0]), float(run.t[b - 1] - run.t[0])],
           "parameters": tyre, "design": levels, "start": prob.start.tolist()}
    if peers:
        best, rows = _peers(config, fitted_params, run, a, b)
        out["peers"] = {k: (v if v is not None else "highpass") for k, v in best.items()}
        out["peer_grid"] = [[fy, ay if ay is not None else "highpass", rms] for fy, ay, rms in rows]
    beta = observer_beta(config, fitted_params, levels, run, a, b)
    out["observer_beta_rms_deg"] = float(np.degrees(np.sqrt(np.mean((beta - run.beta_true[a:b]) ** 2))))
    if folds:
        cv = _cross_validate(config, params, prob, run, a, b, folds)
        out["cross_validation"] = cv
        out["cross_validated_rms_deg"] = float(np.sqrt(np.mean([r["held_out_rms_deg"] ** 2 for r in cv])))
        names = list(tyre)
        out["table"] = {"header": ["held-out fold (samples)", *names, "β RMSE on the fold [deg]", "on the rest [deg]"],
                        "rows": [[f"{r['fold'][0]}–{r['fold'][1] - 1}", *[r["parameters"][k] for k in names],
                                  r["held_out_rms_deg"], r["training_rms_deg"]] for r in cv]
                        + [["pooled over the folds", *[None for _ in names], out["cross_validated_rms_deg"], None],
                           [f"{a}–{b - 1} (the fit)", *[tyre[k] for k in names], None, out["observer_beta_rms_deg"]]]}
    return out


def _fold_edges(a: int, b: int, folds: int) -> list:
    return [a + ((b - a) * k) // folds for k in range(folds + 1)]


def _fold_sizes(a: int, b: int, folds: int) -> tuple:
    """(smallest held-out fold, smallest training set) in samples; a training set is the range less its
    fold and the WINDOW guard on each side of it (no average on one side may see the other)."""
    edges = _fold_edges(a, b, folds)
    held = [hi - lo for lo, hi in zip(edges, edges[1:])]
    train = [(b - a) - h - WINDOW * ((lo > a) + (hi < b)) for h, lo, hi in zip(held, edges, edges[1:])]
    return min(held), min(train)


def _check_folds(folds: int, a: int, b: int) -> None:
    """Every held-out fold and every training set at least MIN_SAMPLES, as for a fit (ConfigurationError)."""
    held, train = _fold_sizes(a, b, folds)
    if held >= MIN_SAMPLES and train >= MIN_SAMPLES:
        return
    most = max((k for k in range(2, (b - a) // MIN_SAMPLES + 1) if min(_fold_sizes(a, b, k)) >= MIN_SAMPLES),
               default=None)
    allowed = (f"2..{most} for samples {a}:{b}" if most else
               f"none for samples {a}:{b}: cross-validation needs at least {2 * MIN_SAMPLES + WINDOW} samples")
    raise ConfigurationError(f"--folds {folds}: the smallest held-out fold has {held} samples and the smallest "
                             f"training set {train}; each needs at least {MIN_SAMPLES} ({MIN_SAMPLES / 100:g} s at "
                             f"100 Hz); allowed: {allowed}", source="--folds", key="--folds", value=folds)


def _cross_validate(config, params, prob, run, a, b, folds) -> list:
    half = WINDOW // 2
    edges = _fold_edges(a, b, folds)
    idx = np.arange(a + half, b - half)              # samples the averages cover
    rows = []
    for k in range(folds):
        lo, hi = edges[k], edges[k + 1]
        train = (idx < lo - WINDOW) | (idx >= hi + WINDOW)
        x = _tyre_fit(prob, train)
        tyre = tyre_values(config, x)
        p = _with_values(params, tyre)
        levels = {kk: _round(v) for kk, v in _levels(prob, _rounded(config, tyre), run, a, b, config.sample_time,
                                                     train).items()}
        beta = observer_beta(config, p, levels, run, a, b)
        err = np.degrees(beta - run.beta_true[a:b])
        rows.append({"fold": [lo, hi], "parameters": tyre, "design": levels,
                     "held_out_rms_deg": float(np.sqrt(np.mean(err[lo - a:hi - a] ** 2))),
                     "training_rms_deg": float(np.sqrt(np.mean(np.concatenate([err[:lo - a], err[hi - a:]]) ** 2)))})
    return rows


# --- the files --------------------------------------------------------------------------------------

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
                new = f'"{v}"' if isinstance(v, str) else repr(float(v))
                pad = max(1, len(m.group(4)) + len(m.group(5)) - len(new)) if m.group(6) else 0
                lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{new}{' ' * pad}{m.group(6) or ''}".rstrip()
                seen.add(m.group(2))
    rest = [k for k in values if k not in seen]
    if rest:
        if last_of_table is None:
            raise ConfigurationError(f"no [{table}] table to write {', '.join(rest)} into")
        add = [f'{k} = "{values[k]}"' if isinstance(values[k], str) else f"{k} = {float(values[k])!r}" for k in rest]
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
    out = [f"uiogen fit {result['observer']} on {result['data']}, samples {a}:{b} (t - t_0 in [{t0:g}, {t1:g}] s, "
           f"{b - a} samples)",
           f"  tyre (least squares of a_y and {YAW_LEVER:g} m x the yaw acceleration against the model's at the log's "
           "own velocities, 0.21 s averages; start: 15 F_z per rad, mu = 1):",
           "    " + ", ".join(f"{k} = {v:g}" for k, v in p.items()),
           "  noise levels of the l2-gain design ([design]):",
           "    " + ", ".join(f"{k} = {v:g}" for k, v in result["design"].items())]
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
    return out
