"""Stanford sideslip data set: loader, the source repository's linear Kalman filter, an EKF.

Data
----
``../shared/data/stanford_sideslip/run_20140222_part1.csv.gz`` (beside the checkout) (see that folder's README):
100 Hz, 27,500 samples of run 20140222_01_01_03_250lm with optical-sensor ground-truth sideslip,
from MBDS/sideslip-angle-vehicle-estimation (MIT, (c) 2021 J. L. Blanco-Claraco), used in Leanza,
Reina, Blanco-Claraco, Sensors 21(16) 5409, 2021. :func:`load` accepts that path, any plain or
gzip CSV with the same columns, or the shorthand ``"stanford"``.

Baselines
---------
:func:`linear_kf` reproduces ``estimators/matlab_kf/BetaStanfordLinear.m`` + ``LinearKF.m`` of the
source repository (commit 2a427a76), line by line:

* states x = (β, r), measurements y = (a_y, r), input δ (road-wheel angle), axle stiffnesses
  C_f = 0.7e5, C_r = 1.2e5 N/rad (F_yf = C_f α_f), m = 982 kg, l_f = 1.33, l_r = 1.07,
  I_z = m/12 (1.7² + 4.09²);
* forward-Euler discretization at dt = 0.01 s scheduled on the *previous* sample's v_x:
  A_d = I + dt A(v_x[k-1]), B_d = dt B(v_x[k-1]); the output matrix uses the current v_x[k]
  (C = [-(C_f+C_r)/m, -(l_f C_f - l_r C_r)/(m v_x); 0, 1], D = [C_f/m; 0]);
* noise covariances from the data's own high-frequency content: each signal is high-pass filtered
  with an equiripple FIR (MATLAB ``fdesign.highpass('Fst,Fp,Ast,Ap', 0.15, 0.25, 60, 1)``, i.e.
  stop band below 0.15·Nyquist = 7.5 Hz at -60 dB, pass band above 12.5 Hz, 1 dB ripple) and
  R = diag(std(HP a_y)², std(HP r)²); process noise enters through the steering input only,
  Q_d = B_d q B_d^T with q = (1000 · std(HP δ))² (the factor 1000 is in the source);
* x_0 = 0, P_0 = diag(1e4, 1e4); predict with δ[k-1], correct with y[k] and δ[k]; the estimate at
  sample 0 is the initial state 0 (MATLAB's zero-filled ``States(:,1)``).

:func:`ekf` is a nonlinear single-track EKF with a Fiala (brush) tyre; see its docstring for every
physical choice. Neither baseline is tuned on ``beta_true``.
"""
from __future__ import annotations

import csv
import gzip
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ModelDefinitionError, SampleError
from . import metrics

__all__ = [
    "STANFORD_PATH", "COLUMNS", "DatasetError", "StanfordRun", "load", "VehicleParams",
    "STANFORD_CAR", "highpass_std", "BaselineResult", "linear_kf", "EKFConfig", "ekf",
    "fiala_axle_force",
]

STANFORD_PATH = (Path(__file__).resolve().parents[3] / "shared" / "data" / "stanford_sideslip"
                 / "run_20140222_part1.csv.gz")
"""Location of the converted first half of run 20140222_01_01_03_250lm."""

COLUMNS = ("t", "vx", "vy", "beta_true", "ax", "ay", "yaw_rate", "yaw_acc",
           "delta", "delta_fl", "delta_fr")
"""Required CSV columns, SI units (s, m/s, rad, m/s², rad/s, rad/s²)."""

# Plausibility limits used to catch unit mistakes (degrees instead of radians, km/h, g units).
_LIMITS = {
    "vx": (-5.0, 100.0),          # m/s
    "vy": (-20.0, 20.0),          # m/s
    "beta_true": (-0.7, 0.7),     # rad (40 deg: anything larger is degrees)
    "ax": (-30.0, 30.0),          # m/s^2
    "ay": (-30.0, 30.0),          # m/s^2
    "yaw_rate": (-3.0, 3.0),      # rad/s
    "yaw_acc": (-30.0, 30.0),     # rad/s^2
    "delta": (-0.8, 0.8),         # rad, road-wheel angle
    "delta_fl": (-0.8, 0.8),
    "delta_fr": (-0.8, 0.8),
}


class DatasetError(SampleError):
    """A data file is missing, unreadable, or has wrong columns, units or non-finite values."""


@dataclass(frozen=True, eq=False)
class StanfordRun:
    """One run of the Stanford data set, as read-only float arrays (SI units).

    Attributes
    ----------
    t : ndarray
        Time [s], strictly increasing.
    vx, vy : ndarray
        Longitudinal and lateral speed at the CoG [m/s].
    beta_true : ndarray
        Ground-truth sideslip angle from the optical sensor [rad].
    ax, ay : ndarray
        Longitudinal and lateral acceleration at the CoG [m/s²].
    yaw_rate : ndarray
        [rad/s].
    yaw_acc : ndarray
        [rad/s²].
    delta, delta_fl, delta_fr : ndarray
        Road-wheel steering angles (mean, front left, front right) [rad].
    source : str
        Path of the file read.
    """

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    beta_true: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    yaw_rate: np.ndarray
    yaw_acc: np.ndarray
    delta: np.ndarray
    delta_fl: np.ndarray
    delta_fr: np.ndarray
    source: str

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t.size)

    @property
    def dt(self) -> float:
        """Median sample period [s]."""
        return float(np.median(np.diff(self.t)))


def _resolve(path) -> Path:
    if isinstance(path, str) and path.strip().lower() == "stanford":
        return STANFORD_PATH
    return Path(path)


def load(path="stanford") -> StanfordRun:
    """Read a Stanford-format CSV (plain or gzip) and validate it.

    Parameters
    ----------
    path : str or os.PathLike, optional
        File to read; ``"stanford"`` (default) resolves to :data:`STANFORD_PATH`. Gzip is detected
        from the file's magic bytes, not its name.

    Returns
    -------
    StanfordRun

    Raises
    ------
    DatasetError
        Missing or unreadable file, missing or duplicated columns, non-numeric or non-finite
        values, fewer than 2 rows, non-increasing time, or values outside physical ranges
        (typical of a unit mistake, e.g. degrees for radians).
    """
    p = _resolve(path)
    if not p.is_file():
        raise DatasetError(f"data file not found: {p}")
    try:
        raw = p.read_bytes()
        if raw[:2] == b"\x1f\x8b":
            raw = gzip.decompress(raw)
        text = raw.decode("utf-8")
    except (OSError, EOFError, gzip.BadGzipFile, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read {p}: {exc}") from None
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise DatasetError(f"{p} is empty") from None
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DatasetError(f"{p}: duplicated column(s) {dup}")
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise DatasetError(f"{p}: missing column(s) {missing}; found {header}")
    rows = [r for r in reader if r and any(f.strip() for f in r)]
    if len(rows) < 2:
        raise DatasetError(f"{p}: needs at least 2 data rows, found {len(rows)}")
    bad_len = next((i for i, r in enumerate(rows) if len(r) != len(header)), None)
    if bad_len is not None:
        raise DatasetError(f"{p}: data row {bad_len + 1} has {len(rows[bad_len])} fields, "
                           f"header has {len(header)}")
    try:
        table = np.array(rows, dtype=float)
    except ValueError as exc:
        raise DatasetError(f"{p}: non-numeric value ({exc})") from None
    cols = {}
    for c in COLUMNS:
        a = table[:, header.index(c)].copy()
        nonfinite = ~np.isfinite(a)
        if nonfinite.any():
            raise DatasetError(f"{p}: column {c!r} has {int(nonfinite.sum())} non-finite value(s), "
                               f"first at data row {int(np.flatnonzero(nonfinite)[0]) + 1}")
        if c in _LIMITS:
            lo, hi = _LIMITS[c]
            if a.min() < lo or a.max() > hi:
                raise DatasetError(
                    f"{p}: column {c!r} spans [{a.min():.4g}, {a.max():.4g}], outside the plausible "
                    f"SI range [{lo}, {hi}] (wrong unit?)")
        a.setflags(write=False)
        cols[c] = a
    if np.any(np.diff(cols["t"]) <= 0):
        raise DatasetError(f"{p}: time column is not strictly increasing")
    return StanfordRun(source=str(p), **cols)


@dataclass(frozen=True)
class VehicleParams:
    """Single-track parameters (axle cornering stiffnesses: F_y,axle = C α).

    Attributes
    ----------
    m : float
        Mass [kg].
    lf, lr : float
        CoG to front / rear axle [m].
    iz : float
        Yaw inertia [kg m²].
    cf, cr : float
        Front / rear *axle* cornering stiffness [N/rad].
    """

    m: float
    lf: float
    lr: float
    iz: float
    cf: float
    cr: float

    def __post_init__(self):
        for k in ("m", "lf", "lr", "iz", "cf", "cr"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ModelDefinitionError(f"vehicle parameter {k} must be finite and > 0, got {v!r}")


STANFORD_CAR = VehicleParams(m=982.0, lf=1.33, lr=1.07, iz=982.0 / 12.0 * (1.7 ** 2 + 4.09 ** 2),
                             cf=0.7e5, cr=1.2e5)
"""Parameters used with this data by its authors (data README, ``BetaStanfordLinear.m``)."""


def _equiripple_highpass(fst: float = 0.15, fp: float = 0.25, ast_db: float = 60.0,
                         ap_db: float = 1.0) -> np.ndarray:
    """Minimum-order equiripple FIR high-pass (MATLAB ``fdesign.highpass('Fst,Fp,Ast,Ap')``).

    Frequencies normalized to Nyquist. Order from Herrmann's formula (as ``firpmord``), made even
    (odd length, type I, as a high-pass needs), then Parks-McClellan with ripple weights; grown
    until both ripple specifications hold.
    """
    from scipy import signal
    dp = (10 ** (ap_db / 20) - 1) / (10 ** (ap_db / 20) + 1)
    ds = 10 ** (-ast_db / 20)
    # Herrmann et al. (1973) length estimate, as used by MATLAB firpmord
    a1, a2, a3, a4, a5, a6 = 5.309e-3, 7.114e-2, -4.761e-1, -2.66e-3, -5.941e-1, -4.278e-1
    l1, l2 = math.log10(dp), math.log10(ds)
    dinf = (a1 * l1 ** 2 + a2 * l1 + a3) * l2 + (a4 * l1 ** 2 + a5 * l1 + a6)
    fk = 11.01217 + 0.51244 * (l1 - l2)
    df = (fp - fst) / 2.0                       # transition width in cycles/sample
    order = int(math.ceil(dinf / df - fk * df))
    order += order % 2
    for _ in range(20):
        h = signal.remez(order + 1, [0, fst / 2, fp / 2, 0.5], [0, 1], weight=[dp / ds, 1.0])
        w, H = signal.freqz(h, worN=4096)
        f = w / np.pi
        stop = np.abs(H[f <= fst]).max()
        passb = np.abs(np.abs(H[f >= fp]) - 1).max()
        if stop <= ds * 1.0001 and passb <= dp * 1.0001:
            return h
        order += 2
    return h


def highpass_std(x) -> float:
    """Standard deviation of ``x`` after the source repository's high-pass FIR (causal filter).

    Used as the sensor-noise level estimate (sample std, ddof = 1, as MATLAB ``std``).
    """
    from scipy import signal
    return float(np.std(signal.lfilter(_equiripple_highpass(), [1.0], np.asarray(x, float)), ddof=1))


@dataclass(frozen=True, eq=False)
class BaselineResult:
    """Output of a baseline estimator on a run.

    Attributes
    ----------
    beta, r : ndarray
        Estimated sideslip [rad] and yaw rate [rad/s] per sample.
    beta_stats : metrics.ErrorStats
        Sideslip error statistics against ``beta_true``, in degrees.
    r_rmse_deg : float
        Yaw-rate RMS error [deg/s].
    name : str
        Estimator name.
    settings : dict
        Noise levels and other settings actually used.
    """

    beta: np.ndarray
    r: np.ndarray
    beta_stats: metrics.ErrorStats
    r_rmse_deg: float
    name: str
    settings: dict


def _check_run(run: StanfordRun) -> None:
    if not isinstance(run, StanfordRun):
        raise DatasetError(f"expected a StanfordRun, got {type(run).__name__}")
    if np.any(np.abs(run.vx) < 1.0):
        raise SampleError("the single-track baselines need |v_x| >= 1 m/s on every sample")


def linear_kf(run: StanfordRun, car: VehicleParams = STANFORD_CAR) -> BaselineResult:
    """Linear Kalman filter of the source repository (``BetaStanfordLinear.m``), reproduced.

    See the module docstring for the exact model, discretization and noise covariances.

    Parameters
    ----------
    run : StanfordRun
    car : VehicleParams, optional

    Returns
    -------
    BaselineResult
    """
    _check_run(run)
    m, lf, lr, iz, cf, cr = car.m, car.lf, car.lr, car.iz, car.cf, car.cr
    dt = run.dt
    s_ay, s_r = highpass_std(run.ay), highpass_std(run.yaw_rate)
    s_d = highpass_std(run.delta) * 1000.0
    q = s_d ** 2
    R = np.diag([s_ay ** 2, s_r ** 2])
    x = np.zeros(2)
    P = np.diag([1e4, 1e4])
    vx, d, ay, r = run.vx, run.delta, run.ay, run.yaw_rate
    out = np.zeros((run.n, 2))
    I2 = np.eye(2)
    D = np.array([cf / m, 0.0])
    for i in range(1, run.n):
        v0 = vx[i - 1]
        Ad = np.array([[1 - dt * (cf + cr) / (m * v0), -dt * (1 + (lf * cf - lr * cr) / (m * v0 ** 2))],
                       [-dt * (lf * cf - lr * cr) / iz, 1 - dt * (lf ** 2 * cf + lr ** 2 * cr) / (iz * v0)]])
        Bd = dt * np.array([cf / (m * v0), lf * cf / iz])
        Qd = q * np.outer(Bd, Bd)
        C = np.array([[-(cf + cr) / m, -(lf * cf - lr * cr) / (m * vx[i])], [0.0, 1.0]])
        xp = Ad @ x + Bd * d[i - 1]
        Pp = Ad @ P @ Ad.T + Qd
        S = C @ Pp @ C.T + R
        K = np.linalg.solve(S.T, (Pp @ C.T).T).T
        x = xp + K @ (np.array([ay[i], r[i]]) - C @ xp - D * d[i])
        P = (I2 - K @ C) @ Pp
        out[i] = x
    beta, rh = out[:, 0], out[:, 1]
    return BaselineResult(
        beta=beta, r=rh, beta_stats=metrics.error_stats(run.beta_true, beta, degrees=True),
        r_rmse_deg=metrics.rms_error(run.yaw_rate, rh, degrees=True), name="linear_kf",
        settings={"s_ay": s_ay, "s_r": s_r, "s_delta_x1000": s_d, "dt": dt,
                  "discretization": "forward Euler, v_x[k-1]", "P0": 1e4})


def fiala_axle_force(alpha, c_alpha: float, mu_fz: float):
    """Fiala (brush, parabolic pressure) lateral axle force, Pacejka's sign convention F = +C α.

    ``F = C t - C²/(3 μF_z) |t| t + C³/(27 μ²F_z²) t³`` with ``t = tan α`` for
    ``|t| < 3 μF_z / C`` and ``μF_z sign(α)`` beyond (full sliding); Pacejka, *Tire and Vehicle
    Dynamics*, 3rd ed., Sec. 3.2 (brush model), as used by Hindiyeh & Gerdes (2014).

    Returns
    -------
    (force, dforce_dalpha) : tuple of float or ndarray
    """
    t = np.tan(alpha)
    tsl = 3.0 * mu_fz / c_alpha
    a = c_alpha
    b = c_alpha ** 2 / (3.0 * mu_fz)
    c = c_alpha ** 3 / (27.0 * mu_fz ** 2)
    lin = np.abs(t) < tsl
    f = np.where(lin, a * t - b * np.abs(t) * t + c * t ** 3, mu_fz * np.sign(alpha))
    dfdt = np.where(lin, a - 2 * b * np.abs(t) + 3 * c * t ** 2, 0.0)
    return f, dfdt * (1.0 + t ** 2)


@dataclass(frozen=True)
class EKFConfig:
    """Physical settings of the EKF baseline (no value is fitted to the ground truth).

    Attributes
    ----------
    mu : float
        Tyre-road friction coefficient. Default 1.7: the file's own *measured* lateral
        acceleration peaks at 16.6 m/s² = 1.69 g, and a single-track model without downforce can
        only produce that with μ ≥ 1.69; the range 1.0-1.3 often quoted for slicks (e.g.
        Milliken & Milliken, *Race Car Vehicle Dynamics*, Ch. 2) would cap a_y at 1.3 g and
        contradict the measurements. This uses the a_y *measurement*, never β.
    g : float
        Gravity [m/s²].
    sigma_ay : float or None
        Lateral-acceleration measurement noise [m/s²]; None: the high-pass std of the signal, as
        the source repository's KF does (a property of the sensor, not of β).
    sigma_r : float or None
        Yaw-rate measurement noise [rad/s]; None: as for ``sigma_ay``.
    sigma_fy : float
        Process noise: std of the unmodelled lateral *force* per axle (load transfer, banking,
        combined slip, aero) as a fraction of the static axle load. 0.05 (5 %): the order of the
        road bank/grade effect g·sin(3°) and of the combined-slip force reduction at |a_x| ≈ 0.3 g.
    p0 : tuple of float
        Initial covariance diagonal (v_y [m/s]², r [rad/s]²): (1.0, 0.01), i.e. 1 m/s and 0.1 rad/s.
    """

    mu: float = 1.7
    g: float = 9.81
    sigma_ay: float | None = None
    sigma_r: float | None = None
    sigma_fy: float = 0.05
    p0: tuple = (1.0, 0.01)

    def __post_init__(self):
        if not (math.isfinite(self.mu) and self.mu > 0):
            raise ModelDefinitionError(f"friction coefficient must be > 0, got {self.mu!r}")
        if not (math.isfinite(self.sigma_fy) and self.sigma_fy > 0):
            raise ModelDefinitionError(f"sigma_fy must be > 0, got {self.sigma_fy!r}")
        for k in ("sigma_ay", "sigma_r"):
            v = getattr(self, k)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ModelDefinitionError(f"{k} must be None or > 0, got {v!r}")


def ekf(run: StanfordRun, car: VehicleParams = STANFORD_CAR, cfg: EKFConfig = EKFConfig()
        ) -> BaselineResult:
    """Extended Kalman filter on a nonlinear single-track model with Fiala tyres.

    Model (states x = (v_y, r), inputs δ and the measured v_x as a scheduling signal)::

        α_f = δ - atan((v_y + l_f r) / v_x),     α_r = -atan((v_y - l_r r) / v_x)
        F_yf = Fiala(α_f; C_f, μ F_zf),          F_yr = Fiala(α_r; C_r, μ F_zr)
        F_zf = m g l_r / L,  F_zr = m g l_f / L  (static axle loads)
        v̇_y = (F_yf cos δ + F_yr)/m - r v_x,    ṙ = (l_f F_yf cos δ - l_r F_yr)/I_z
        y = (a_y, r),  a_y = (F_yf cos δ + F_yr)/m

    Discretized with one RK2 (Heun) step per sample at the data rate, the Jacobian taken on the
    Euler part (F = I + dt ∂f/∂x). Process noise: the unmodelled axle forces
    w_f, w_r ~ N(0, (σ_fy F_z)²) enter v̇_y, ṙ and a_y through their physical input matrix
    (Q_d = dt² G Σ Gᵀ, plus the corresponding correlation with a_y ignored). β = atan(v_y / v_x).

    Parameters
    ----------
    run : StanfordRun
    car : VehicleParams, optional
    cfg : EKFConfig, optional

    Returns
    -------
    BaselineResult
    """
    _check_run(run)
    m, lf, lr, iz, cf, cr = car.m, car.lf, car.lr, car.iz, car.cf, car.cr
    L = lf + lr
    fzf, fzr = m * cfg.g * lr / L, m * cfg.g * lf / L
    muf, mur = cfg.mu * fzf, cfg.mu * fzr
    dt = run.dt
    s_ay = cfg.sigma_ay if cfg.sigma_ay is not None else highpass_std(run.ay)
    s_r = cfg.sigma_r if cfg.sigma_r is not None else highpass_std(run.yaw_rate)
    R = np.diag([s_ay ** 2, s_r ** 2])
    Sw = np.diag([(cfg.sigma_fy * fzf) ** 2, (cfg.sigma_fy * fzr) ** 2])

    def forces(x, vx, d):
        vy, r = x
        af = d - math.atan2(vy + lf * r, vx)
        ar = -math.atan2(vy - lr * r, vx)
        ff, dff = fiala_axle_force(af, cf, muf)
        fr, dfr = fiala_axle_force(ar, cr, mur)
        return float(ff), float(dff), float(fr), float(dfr), af, ar

    def f(x, vx, d):
        ff, _, fr, _, _, _ = forces(x, vx, d)
        cd = math.cos(d)
        return np.array([(ff * cd + fr) / m - x[1] * vx, (lf * ff * cd - lr * fr) / iz])

    x = np.zeros(2)
    P = np.diag(cfg.p0)
    vx, d, ay, r = run.vx, run.delta, run.ay, run.yaw_rate
    out = np.zeros((run.n, 2))
    for i in range(1, run.n):
        v0, d0 = vx[i - 1], d[i - 1]
        # Jacobian of f at the prior estimate
        ff, dff, fr, dfr, _, _ = forces(x, v0, d0)
        cd = math.cos(d0)
        vy, rr = x
        # ∂α_f/∂(v_y, r), ∂α_r/∂(v_y, r)
        den_f = v0 ** 2 + (vy + lf * rr) ** 2
        den_r = v0 ** 2 + (vy - lr * rr) ** 2
        daf = np.array([-v0 / den_f, -lf * v0 / den_f])
        dar = np.array([-v0 / den_r, lr * v0 / den_r])
        dFf, dFr = dff * daf, dfr * dar
        J = np.vstack([(dFf * cd + dFr) / m - np.array([0.0, v0]),
                       (lf * dFf * cd - lr * dFr) / iz])
        G = np.array([[cd / m, 1.0 / m], [lf * cd / iz, -lr / iz]])
        # Heun step with inputs held at sample i-1 except speed/steer at the end of the step
        k1 = f(x, v0, d0)
        k2 = f(x + dt * k1, vx[i], d[i])
        xp = x + 0.5 * dt * (k1 + k2)
        Fd = np.eye(2) + dt * J
        Pp = Fd @ P @ Fd.T + dt ** 2 * G @ Sw @ G.T
        # measurement
        ff, dff, fr, dfr, _, _ = forces(xp, vx[i], d[i])
        cd = math.cos(d[i])
        vy, rr = xp
        v1 = vx[i]
        den_f = v1 ** 2 + (vy + lf * rr) ** 2
        den_r = v1 ** 2 + (vy - lr * rr) ** 2
        daf = np.array([-v1 / den_f, -lf * v1 / den_f])
        dar = np.array([-v1 / den_r, lr * v1 / den_r])
        H = np.vstack([(dff * daf * cd + dfr * dar) / m, [0.0, 1.0]])
        yhat = np.array([(ff * cd + fr) / m, rr])
        S = H @ Pp @ H.T + R
        K = np.linalg.solve(S.T, (Pp @ H.T).T).T
        x = xp + K @ (np.array([ay[i], r[i]]) - yhat)
        P = (np.eye(2) - K @ H) @ Pp
        P = 0.5 * (P + P.T)
        out[i] = x
    beta = np.arctan2(out[:, 0], vx)
    rh = out[:, 1]
    return BaselineResult(
        beta=beta, r=rh, beta_stats=metrics.error_stats(run.beta_true, beta, degrees=True),
        r_rmse_deg=metrics.rms_error(run.yaw_rate, rh, degrees=True), name="ekf_fiala",
        settings={"mu": cfg.mu, "s_ay": s_ay, "s_r": s_r, "sigma_fy": cfg.sigma_fy, "dt": dt,
                  "p0": cfg.p0})
