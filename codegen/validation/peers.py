"""The estimators run beside the observers on a logged run (the real-data peers): the source
repository's linear Kalman filter, an EKF on a Fiala single-track model, and the EKF and UKF of the
nonlinear-tyre model with an observer's own parameter file, with the noise levels they read off the log.

They take a :class:`codegen.validation.stanford.StanfordRun` (the shared logs' format, or a user's log
mapped onto it) and are generated from symbolic models by :mod:`codegen.validation.kalman`.

Baselines
---------
Both are generated from symbolic models (``model_defs/baselines.py``) by the generic builder
:mod:`codegen.validation.kalman` (sympy -> CasADi, Jacobians by CasADi differentiation); no filter
matrix is typed in here.

:func:`linear_kf` reproduces ``estimators/matlab_kf/BetaStanfordLinear.m`` + ``LinearKF.m`` of the
source repository (commit 2a427a76), line by line:

* states x = (β, r), measurements y = (a_y, r), input δ (road-wheel angle): the model
  ``LINEAR_SINGLE_TRACK``, i.e. the observer's single-track equations with linear tyres, with the
  data README's axle stiffnesses C_f = 0.7e5, C_r = 1.2e5 N/rad (F_yf = C_f α_f), m = 982 kg,
  l_f = 1.33, l_r = 1.07, I_z = m/12 (1.7² + 4.09²); its Jacobians are the source's
  A(v_x), B, C(v_x) = [-(C_f+C_r)/m, -(l_f C_f - l_r C_r)/(m v_x); 0, 1], D = [C_f/m; 0];
* forward-Euler discretization at dt = 0.01 s scheduled on the *previous* sample's v_x:
  A_d = I + dt A(v_x[k-1]), B_d = dt B(v_x[k-1]); the output matrices use the current v_x[k];
* noise covariances from the data's own high-frequency content: each signal is high-pass filtered
  with an equiripple FIR (MATLAB ``fdesign.highpass('Fst,Fp,Ast,Ap', 0.15, 0.25, 60, 1)``, i.e.
  stop band below 0.15·Nyquist = 7.5 Hz at -60 dB, pass band above 12.5 Hz, 1 dB ripple) and
  R = diag(std(HP a_y)², std(HP r)²); process noise enters through the steering input only,
  Q_d = B_d q B_d^T with q = (1000 · std(HP δ))² (the factor 1000 is in the source);
* x_0 = 0, P_0 = diag(1e4, 1e4); predict with δ[k-1], correct with y[k] and δ[k]; the estimate at
  sample 0 is the initial state 0 (MATLAB's zero-filled ``States(:,1)``).

:func:`ekf` is an EKF on ``FIALA_SINGLE_TRACK``, a nonlinear single-track model with Fiala (brush)
axle forces; see its docstring and :class:`EKFConfig` for every physical choice. Neither baseline
is tuned on ``beta_true``.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import DatasetError, ModelDefinitionError, SampleError
from ..project.observer_file import builtin_model
from . import kalman, metrics
from .stanford import StanfordRun

__all__ = ["VehicleParams", "STANFORD_CAR", "highpass_std", "BaselineResult", "linear_kf", "EKFConfig", "ekf",
           "peer_noise", "nonlinear_tyre_peers"]


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

    def values(self) -> dict:
        """Values keyed by the parameter names of the symbolic models (``model_defs/baselines.py``)."""
        return {"m": self.m, "l_f": self.lf, "l_r": self.lr, "I_z": self.iz, "C_f": self.cf, "C_r": self.cr}


STANFORD_CAR = VehicleParams(m=982.0, lf=1.33, lr=1.07, iz=982.0 / 12.0 * (1.7 ** 2 + 4.09 ** 2),
                             cf=0.7e5, cr=1.2e5)
"""Parameters used with this data by its authors (data README, ``BetaStanfordLinear.m``)."""


@functools.lru_cache(maxsize=8)
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
            break
        order += 2
    h.setflags(write=False)             # shared by every caller (lru_cache)
    return h


def highpass_std(x) -> float:
    """Standard deviation of ``x`` after the source repository's high-pass FIR (causal filter).

    Used as the sensor-noise level estimate (sample std, ddof = 1, as MATLAB ``std``).
    """
    import hashlib
    import sys

    from ..model import cache
    x = np.ascontiguousarray(x, dtype=float)
    # a function of the samples alone, kept across runs (codegen.model.cache): a log validated again
    # needs neither the filter design nor scipy.signal's import (0.6 s)
    digest = cache.key(HIGHPASS_STD, {"samples": hashlib.sha256(x.tobytes()).hexdigest(), "n": int(x.size),
                                      "scipy": _scipy_version(), "code": cache.code_digest(sys.modules[__name__])})
    stored = cache.read(HIGHPASS_STD, digest)
    if isinstance(stored, dict) and isinstance(stored.get("std"), float):
        return stored["std"]
    from scipy import signal
    # the taps are one design (Parks-McClellan, iterated): made once per process, read-only
    value = float(np.std(signal.lfilter(_equiripple_highpass(), [1.0], x), ddof=1))
    cache.write(HIGHPASS_STD, digest, {"std": value})
    return value


HIGHPASS_STD = "highpass_std"


def _scipy_version() -> str:
    import importlib.metadata
    return importlib.metadata.version("scipy")


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


_RUN_COLUMNS = {"delta": "delta", "a_x": "ax"}     # known inputs of the nonlinear-tyre model -> log columns


def _filter_inputs(run: StanfordRun):
    """Inputs u = delta, measurements y = (a_y, r), scheduling rho = v_x of a run."""
    return run.delta, np.column_stack([run.ay, run.yaw_rate]), run.vx


def linear_kf(run: StanfordRun, car: VehicleParams = STANFORD_CAR) -> BaselineResult:
    """Linear Kalman filter of the source repository (``BetaStanfordLinear.m``), reproduced.

    Generated from ``model_defs.baselines.LINEAR_SINGLE_TRACK`` (the observer's single-track
    equations with linear tyres) by :func:`codegen.validation.kalman.linear_kalman_filter`; see the
    module docstring for the discretization and noise covariances.

    Parameters
    ----------
    run : StanfordRun
    car : VehicleParams, optional

    Returns
    -------
    BaselineResult
    """
    _check_run(run)
    s_ay, s_r = highpass_std(run.ay), highpass_std(run.yaw_rate)
    s_d = highpass_std(run.delta) * 1000.0
    model = kalman.kalman_model(builtin_model("baselines").LINEAR_SINGLE_TRACK, car.values(), outputs=("a_y", "r"), noisy_inputs=("delta",))
    u, y, rho = _filter_inputs(run)
    est = kalman.linear_kalman_filter(model, u, y, rho, run.dt, R=np.diag([s_ay ** 2, s_r ** 2]),
                                      Sigma=[[s_d ** 2]], x0=np.zeros(2), P0=np.diag([1e4, 1e4]))
    beta, rh = est.x[:, model.states.index("beta")], est.x[:, model.states.index("r")]
    return BaselineResult(
        beta=beta, r=rh, beta_stats=metrics.error_stats(run.beta_true, beta, degrees=True),
        r_rmse_deg=metrics.rms_error(run.yaw_rate, rh, degrees=True), name="linear_kf",
        settings={"s_ay": s_ay, "s_r": s_r, "s_delta_x1000": s_d, "dt": run.dt, "model": model.name,
                  "discretization": "forward Euler, v_x[k-1]", "P0": 1e4})


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
    """Extended Kalman filter on the nonlinear single-track model with Fiala tyres.

    Generated from ``model_defs.baselines.FIALA_SINGLE_TRACK`` (states x = (v_y, r), input
    delta, the measured v_x as a scheduling signal, measurements (a_y, r)) by
    :func:`codegen.validation.kalman.extended_kalman_filter`: one Heun step per sample, Jacobians
    by CasADi differentiation of the symbolic model. Process noise: the unmodelled axle forces
    w_f, w_r ~ N(0, sigma_fy^2) (fractions of the static axle loads) enter through their physical
    input matrix G = df/dw (their correlation with a_y is ignored). beta = atan(v_y / v_x).

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
    s_ay = cfg.sigma_ay if cfg.sigma_ay is not None else highpass_std(run.ay)
    s_r = cfg.sigma_r if cfg.sigma_r is not None else highpass_std(run.yaw_rate)
    model = kalman.kalman_model(builtin_model("baselines").FIALA_SINGLE_TRACK, {**car.values(), "mu": cfg.mu, "g": cfg.g},
                                outputs=("a_y", "r"))
    u, y, rho = _filter_inputs(run)
    est = kalman.extended_kalman_filter(model, u, y, rho, run.dt, R=np.diag([s_ay ** 2, s_r ** 2]),
                                        Sigma=cfg.sigma_fy ** 2 * np.eye(len(model.noise)),
                                        x0=np.zeros(2), P0=np.diag(cfg.p0))
    vy, rh = est.x[:, model.states.index("v_y")], est.x[:, model.states.index("r")]
    beta = np.arctan2(vy, run.vx)
    return BaselineResult(
        beta=beta, r=rh, beta_stats=metrics.error_stats(run.beta_true, beta, degrees=True),
        r_rmse_deg=metrics.rms_error(run.yaw_rate, rh, degrees=True), name="ekf_fiala",
        settings={"mu": cfg.mu, "s_ay": s_ay, "s_r": s_r, "sigma_fy": cfg.sigma_fy, "dt": run.dt,
                  "p0": cfg.p0, "model": model.name})


NONLINEAR_TYRE_PEER_NOISE = {"sigma_fy": 0.1, "sigma_ay": 0.3}
"""Noise levels of the same-tyre EKF and UKF peers (:func:`nonlinear_tyre_peers`) when the parameter
file does not give them (``[meta] peer_sigma_fy``, ``peer_sigma_ay``, which ``uiogen fit`` identifies):
process noise per axle as a fraction of its static load, a_y measurement noise in m/s^2 ("highpass":
the high-pass std of the log's a_y)."""


def peer_noise(parameter_path) -> dict:
    """The peers' noise levels of a parameter file (``[meta] peer_sigma_fy``, ``peer_sigma_ay``), else
    :data:`NONLINEAR_TYRE_PEER_NOISE`."""
    from ..model import load_parameters
    meta = load_parameters(parameter_path).meta
    out = dict(NONLINEAR_TYRE_PEER_NOISE)
    for key in out:
        raw = meta.get(f"peer_{key}")
        if raw is None:
            continue
        if raw == "highpass":
            out[key] = None
            continue
        try:
            out[key] = float(raw)
        except ValueError:
            raise ModelDefinitionError(f"{parameter_path}: [meta] peer_{key} = {raw!r}: must be a number in a string "
                                       f"(\"0.1\") or \"highpass\"") from None
    return out


def nonlinear_tyre_peers(run: StanfordRun, parameter_path, noise: dict | None = None,
                         which=("ekf_nonlinear_tyre", "ukf_nonlinear_tyre")) -> dict:
    """EKF and UKF on ``model_defs/single_track_nonlinear_tyre.MODEL`` with the numbers of
    ``parameter_path`` (the observer's own parameter file: the same Fiala tyre, combined slip, the
    same mu and C per axle). States (v_y, r), known inputs (delta, a_x), measurements (a_y, r),
    process noise w_f, w_r ~ N(0, sigma_fy^2); x_0 = 0, P_0 = diag(1, 0.01). ``noise``: None reads
    :func:`peer_noise`. Returns {"ekf_nonlinear_tyre": BaselineResult, "ukf_nonlinear_tyre": ...}."""
    from ..model import load_parameters
    _check_run(run)
    noise = peer_noise(parameter_path) if noise is None else noise
    params = load_parameters(parameter_path)
    s_ay = noise["sigma_ay"] if noise["sigma_ay"] is not None else highpass_std(run.ay)
    s_r = highpass_std(run.yaw_rate)
    definition = builtin_model("single_track_nonlinear_tyre").MODEL
    model = kalman.kalman_model(definition, dict(params.values), outputs=("a_y", "r"))
    _, y, rho = _filter_inputs(run)
    u = np.column_stack([getattr(run, _RUN_COLUMNS[str(s)]) for s in definition.known_inputs])
    out = {}
    filters = {"ekf_nonlinear_tyre": kalman.extended_kalman_filter, "ukf_nonlinear_tyre": kalman.unscented_kalman_filter}
    for name in which:
        est = filters[name](model, u, y, rho, run.dt, R=np.diag([s_ay ** 2, s_r ** 2]),
                            Sigma=noise["sigma_fy"] ** 2 * np.eye(len(model.noise)), x0=np.zeros(2),
                            P0=np.diag([1.0, 0.01]))
        vy, rh = est.x[:, 0], est.x[:, 1]
        beta = np.arctan2(vy, run.vx)
        out[name] = BaselineResult(
            beta=beta, r=rh, beta_stats=metrics.error_stats(run.beta_true, beta, degrees=True),
            r_rmse_deg=metrics.rms_error(run.yaw_rate, rh, degrees=True), name=name,
            settings={**{k: (v if v is not None else s_ay) for k, v in noise.items()}, "s_r": s_r,
                      "model": model.name, "parameters": str(parameter_path)})
    return out
