"""Named, seeded, reproducible driving scenarios (input profiles for a plant).

A :class:`Scenario` holds, on a uniform output grid (100 Hz default): the speed profile
``v_ref`` and its derivative ``a_ref``, the assistance torque ``T_a``, an open-loop human torque
component ``T_d_open`` (band-limited, 0.1-5 Hz, a few tenths of N m to a few N m) and, for
scenarios defined by a path, a reference curvature ``kappa_ref`` tracked by a simple driver model
(:class:`DriverGains`) that turns the path into handwheel torque. Friction is a scale on the
tyre's nominal coefficients (1 = nominal dry road), constant or a function of position.

Same name and seed -> bit-identical arrays (numpy ``default_rng(seed)``; no global state).

Library (seed paper and section in each description): ``track_varying_speed``,
``takeover_opposing_assist``, ``zigzag_growing_ay``, ``zigzag_constant_speed_assist``
(Nguyen et al. 2019 scenarios 1-4), ``random_trajectory_accel``, ``circular_path_normal``,
``time_varying_grip_normal`` (Nguyen et al. 2021 scenarios 1-3 in the paper's 'normal driving' speed range;
``circular_path`` and ``time_varying_grip`` are faster stress readings of scenarios 2 and 3),
``braking_on_bend``, ``banked_road_braking`` (Menhour et al. 2014: road bank profile ``bank``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import ScenarioError

__all__ = ["ScenarioError", "DriverGains", "Scenario", "SCENARIOS", "names", "make",
           "straight_line", "steady_circle",
           "band_limited", "paper_grip"]


def band_limited(t: np.ndarray, rng: np.random.Generator, rms: float, f_lo: float = 0.1,
                 f_hi: float = 5.0, n: int = 16) -> np.ndarray:
    """Zero-mean sum of ``n`` sinusoids with log-uniform frequencies in [f_lo, f_hi] Hz.

    Amplitudes fall as 1/f (human steering is mostly low-frequency); the result is scaled to the
    requested RMS value. Deterministic given ``rng``'s state.
    """
    if not (0 < f_lo < f_hi) or rms < 0:
        raise ScenarioError(f"band_limited: need 0 < f_lo < f_hi and rms >= 0 (got {f_lo}, {f_hi}, {rms})")
    f = np.exp(rng.uniform(np.log(f_lo), np.log(f_hi), n))
    ph = rng.uniform(0.0, 2 * np.pi, n)
    amp = 1.0 / f
    x = (amp[:, None] * np.sin(2 * np.pi * f[:, None] * t[None, :] + ph[:, None])).sum(axis=0)
    s = float(np.sqrt(np.mean(x * x)))
    return x * (rms / s) if s > 0 else x


def _smoothstep(t, t0, t1):
    """C¹ ramp from 0 (t <= t0) to 1 (t >= t1)."""
    u = np.clip((np.asarray(t, float) - t0) / (t1 - t0), 0.0, 1.0)
    return u * u * (3 - 2 * u)


def paper_grip(X: float, Y: float, mu_grip: float = 0.6, l_r: float = 1.4, floor: float = 0.05) -> float:
    """Nguyen et al. 2021 Sec. IV-D road grip ``μ_grip (1 + sin(π sqrt(X² + Y²) / l_r))``.

    Taken literally (range [0, 2 μ_grip]); floored at ``floor`` because a zero peak force makes
    the magic formula singular (B = K / (C D)). ``l_r`` is the paper's length scale (its rear axle
    distance; 1.4 m by default, of the order of the CommonRoad cars' b).
    """
    return max(floor, mu_grip * (1.0 + math.sin(math.pi * math.hypot(X, Y) / l_r)))


@dataclass(frozen=True)
class DriverGains:
    """Driver model turning a reference curvature into handwheel torque.

    Outer loop (curvature, optional circular path): ``κ_cmd = κ_ref + (k_e e + k_edot ė)/v²``
    with e the radial distance error to the circle. Middle loop: road-wheel angle reference
    ``δ_ref = L κ_cmd + k_r (v κ_cmd - r) + k_ri ∫(v κ_cmd - r)``. Inner loop (arms on the
    handwheel, angle θ = R_s δ): ``T = k_p (θ_ref - θ) + k_i ∫(θ_ref - θ) - k_d θ̇``, plus the
    scenario's open-loop human torque component.

    Attributes
    ----------
    wheelbase, R_s : float
        Driver's idea of the wheelbase [m] and gear ratio [-].
    k_e, k_edot : float
        Path gains [1/s², 1/s].
    k_r, k_ri : float
        Yaw-rate gains [s], [-].
    k_p, k_i, k_d : float
        Arm stiffness [N m/rad], integral [N m/(rad s)], damping [N m s/rad] on the handwheel.
    """

    wheelbase: float = 2.6
    R_s: float = 16.0
    k_e: float = 0.25
    k_edot: float = 1.0
    k_r: float = 0.05
    k_ri: float = 0.3
    k_p: float = 40.0
    k_i: float = 80.0
    k_d: float = 1.0


class _Driver:
    def __init__(self, sc: "Scenario"):
        self.sc = sc
        self.g = sc.driver
        self.i_r = 0.0
        self.i_th = 0.0
        self.dt = 1.0 / sc.sample_rate

    def preload(self, torque: float) -> None:
        """Start holding ``torque`` on the handwheel (integrator preset), e.g. in a steady bend."""
        if self.g is not None and self.g.k_i > 0:
            self.i_th = torque / self.g.k_i

    def __call__(self, k: int, meas: dict) -> float:
        sc, g = self.sc, self.g
        if g is None or sc.kappa_ref is None:
            return float(sc.T_d_open[k])
        v = max(meas["v_x"], 1.0)
        kap = float(sc.kappa_ref[k])
        if sc.circle is not None:
            cx, cy, rad = sc.circle
            dx, dy = meas["X"] - cx, meas["Y"] - cy
            dist = math.hypot(dx, dy)
            c, s = math.cos(meas["psi"]), math.sin(meas["psi"])
            vX = meas["v_x"] * c - meas["v_y"] * s
            vY = meas["v_x"] * s + meas["v_y"] * c
            edot = (vX * dx + vY * dy) / max(dist, 1e-6)
            kap += (g.k_e * (dist - rad) + g.k_edot * edot) / (v * v)
        er = v * kap - meas["r"]
        self.i_r += er * self.dt
        d_ref = g.wheelbase * kap + g.k_r * er + g.k_ri * self.i_r
        eth = g.R_s * (d_ref - meas["delta"])
        self.i_th += eth * self.dt
        return float(g.k_p * eth + g.k_i * self.i_th - g.k_d * g.R_s * meas["delta_dot"]
                     + sc.T_d_open[k])


@dataclass(frozen=True, eq=False)
class Scenario:
    """A reproducible input profile.

    Attributes
    ----------
    name : str
    seed : int
    description : str
        What it reproduces (seed paper, section) and how.
    sample_rate : float
        [Hz].
    t : ndarray
        Output grid [s], starting at 0.
    v_ref, a_ref : ndarray
        Speed profile [m/s] and its time derivative [m/s²].
    T_a : ndarray
        Assistance torque [N m] (known input).
    T_d_open : ndarray
        Open-loop human torque [N m]: the whole driver torque when ``kappa_ref`` is None, else an
        additive component on top of the driver model.
    kappa_ref : ndarray or None
        Reference path curvature [1/m] for the driver model.
    circle : tuple or None
        (X_c, Y_c, radius) of a circular path the driver model regulates to.
    driver : DriverGains or None
    grip : callable or None
        ``grip(t, X, Y) -> μ scale``; None: constant ``mu``.
    mu : float
        Constant friction scale when ``grip`` is None.
    bank : ndarray or None
        Road bank angle [rad] per sample (None: flat road); positive when gravity's component in
        the road plane points to the vehicle's right (-y).
    """

    name: str
    seed: int
    description: str
    sample_rate: float
    t: np.ndarray
    v_ref: np.ndarray
    a_ref: np.ndarray
    T_a: np.ndarray
    T_d_open: np.ndarray
    kappa_ref: np.ndarray | None = None
    circle: tuple | None = None
    driver: DriverGains | None = None
    grip: Callable | None = None
    mu: float = 1.0
    bank: np.ndarray | None = None

    @property
    def duration(self) -> float:
        """Last sample time [s]."""
        return float(self.t[-1])

    def make_driver(self) -> Callable[[int, dict], float]:
        """Fresh driver (own integrator states): ``driver(k, meas) -> T_d`` [N m].

        ``meas`` needs keys X, Y, psi, v_x, v_y, r, delta, delta_dot (plant truth).
        """
        return _Driver(self)

    def friction(self, t: float, X: float, Y: float) -> float:
        """Friction scale at time ``t`` and position (X, Y)."""
        return float(self.grip(t, X, Y)) if self.grip is not None else self.mu

    def arrays(self) -> dict:
        """All array fields (for reproducibility checks and saving)."""
        out = {k: getattr(self, k) for k in ("t", "v_ref", "a_ref", "T_a", "T_d_open")}
        if self.kappa_ref is not None:
            out["kappa_ref"] = self.kappa_ref
        if self.bank is not None:
            out["bank"] = self.bank
        return out


def _grid(duration: float, rate: float) -> np.ndarray:
    return np.arange(int(round(duration * rate)) + 1) / rate


def _finish(name, seed, desc, rate, t, v, T_a, T_d, kappa=None, circle=None, driver=None,
            grip=None, mu=1.0, bank=None) -> Scenario:
    a = np.gradient(v, 1.0 / rate)
    arrs = [np.ascontiguousarray(x, dtype=float) for x in (t, v, a, T_a, T_d)]
    kap = None if kappa is None else np.ascontiguousarray(kappa, dtype=float)
    bnk = None if bank is None else np.ascontiguousarray(bank, dtype=float)
    for x in arrs + [y for y in (kap, bnk) if y is not None]:
        x.setflags(write=False)
    return Scenario(name, seed, desc, rate, *arrs, kappa_ref=kap, circle=circle, driver=driver,
                    grip=grip, mu=mu, bank=bnk)


def _speed_random(t, rng, lo, hi, a_max, n_knots):
    """Smooth random speed profile within [lo, hi] with |dv/dt| <= a_max."""
    knots = np.linspace(t[0], t[-1], n_knots)
    vals = rng.uniform(lo, hi, n_knots)
    vals[0] = 0.5 * (lo + hi)
    v = np.interp(t, knots, vals)
    # smooth by a 2 s moving average, then enforce the rate limit
    w = max(1, int(round(2.0 / (t[1] - t[0]))))
    v = np.convolve(np.pad(v, (w, w), mode="edge"), np.ones(w) / w, mode="same")[w:-w]
    dt = t[1] - t[0]
    # the rate limit in Python floats: the same IEEE operations as np.clip per sample, 20x faster
    step, vs = float(a_max * dt), v.tolist()
    out = [vs[0]]
    for x in vs[1:]:
        prev = out[-1]
        out.append(prev + min(max(x - prev, -step), step))
    return np.clip(np.array(out), lo, hi)


def _bends(t, rng, v, ay_max, n_bends):
    """Curvature profile: ``n_bends`` smooth bends of random sign and lateral acceleration."""
    kap = np.zeros_like(t)
    T = t[-1]
    centres = np.sort(rng.uniform(0.1 * T, 0.9 * T, n_bends))
    for c in centres:
        width = rng.uniform(2.0, 5.0)
        ay = rng.uniform(0.3, 1.0) * ay_max * rng.choice([-1.0, 1.0])
        bump = np.exp(-0.5 * ((t - c) / (0.4 * width)) ** 2)
        kap += ay / np.maximum(v, 1.0) ** 2 * bump
    return kap


def _track_varying_speed(seed, rate):
    rng = np.random.default_rng(seed)
    t = _grid(60.0, rate)
    v = _speed_random(t, rng, 10.0, 30.0, 2.0, 9)
    kap = _bends(t, rng, v, 4.0, 10)
    td = band_limited(t, rng, 0.3)
    return _finish("track_varying_speed", seed,
                   "Nguyen et al. 2019 Sec. V-A scenario 1: manual track driving, T_a = 0, speed 10-30 m/s "
                   "(|a_x| <= 2 m/s²), ten bends of 1.2-4 m/s² each (overlapping bends reach about "
                   "5.5 m/s²), driver model + 0.3 N m RMS band-limited human torque", rate, t, v, np.zeros_like(t), td, kap,
                   driver=DriverGains())


def _takeover_opposing_assist(seed, rate):
    rng = np.random.default_rng(seed)
    t = _grid(30.0, rate)
    v = np.full_like(t, 14.0)
    # lane change (sine doublet) between 10 and 16 s, 3.5 m at 14 m/s: a_y peak ~ 2 m/s^2
    tc0, tc1 = 10.0 + rng.uniform(-0.5, 0.5), 0.0
    tc1 = tc0 + 6.0
    u = np.clip((t - tc0) / (tc1 - tc0), 0.0, 1.0)
    inside = (t > tc0) & (t < tc1)
    ay = np.where(inside, 2.0 * np.sin(2 * np.pi * u), 0.0)
    kap = ay / v ** 2
    # lane-keeping assistance: small centring torque, then opposing the driver during take-over
    T_a = band_limited(t, rng, 0.2, 0.1, 1.0, 8) - 2.0 * np.where(inside, np.sin(2 * np.pi * u), 0.0)
    td = band_limited(t, rng, 0.3)
    return _finish("takeover_opposing_assist", seed,
                   "Nguyen et al. 2019 Sec. V-B scenario 2: 14 m/s, lane-keeping assistance; the driver takes "
                   "over for a lane change (10-16 s) against an assistance torque of opposite sign "
                   "(up to 2 N m)", rate, t, v, T_a, td, kap, driver=DriverGains())


def _zigzag_growing_ay(seed, rate):
    rng = np.random.default_rng(seed)
    t = _grid(40.0, rate)
    v = 14.0 + 6.0 * _smoothstep(t, 2.0, 20.0) + band_limited(t, rng, 0.3, 0.02, 0.1, 4)
    f = rng.uniform(0.22, 0.28)
    ay_amp = 1.0 + 7.0 * _smoothstep(t, 3.0, 36.0)          # 1 -> 8 m/s^2
    kap = ay_amp * np.sin(2 * np.pi * f * t) * _smoothstep(t, 0.0, 2.0) / v ** 2
    td = band_limited(t, rng, 0.3)
    return _finish("zigzag_growing_ay", seed,
                   "Nguyen et al. 2019 Sec. V-C scenario 3: zigzag without assistance, speed 14 -> 20 m/s, "
                   f"lateral acceleration amplitude growing 1 -> 8 m/s² at {f:.3f} Hz", rate, t, v,
                   np.zeros_like(t), td, kap, driver=DriverGains())


def _zigzag_constant_speed_assist(seed, rate):
    rng = np.random.default_rng(seed)
    t = _grid(30.0, rate)
    v = np.full_like(t, 15.0)
    f = rng.uniform(0.25, 0.3)
    sq = np.tanh(1.5 * np.sin(2 * np.pi * f * t)) / np.tanh(1.5)   # sharpened zigzag
    kap = 4.0 * sq * _smoothstep(t, 1.0, 3.0) / v ** 2
    T_a = 1.5 * np.tanh(2.0 * np.sin(2 * np.pi * f * t + rng.uniform(0.2, 0.6))) * _smoothstep(t, 1, 3)
    td = band_limited(t, rng, 0.3)
    return _finish("zigzag_constant_speed_assist", seed,
                   "Nguyen et al. 2019 Sec. V-D scenario 4: straight road at 15 m/s, sharp zigzag (|a_y| <= 4 "
                   "m/s²) shared with an assistance torque of up to 1.5 N m", rate, t, v, T_a, td, kap,
                   driver=DriverGains())


def _random_trajectory_accel(seed, rate):
    rng = np.random.default_rng(seed)
    t = _grid(30.0, rate)
    v = 12.0 + 1.5 * np.clip(t - 14.0, 0.0, None)
    v = np.minimum(v, 12.0 + 1.5 * 10.0)                    # 12 -> 27 m/s from 14 s to 24 s
    kap = _bends(t, rng, v, 3.0, 7)
    td = band_limited(t, rng, 0.3)
    return _finish("random_trajectory_accel", seed,
                   "Nguyen et al. 2021 Sec. IV-B scenario 1: random trajectory, 12 m/s then accelerating at "
                   "1.5 m/s² after 14 s", rate, t, v, np.zeros_like(t), td, kap, driver=DriverGains())


def _circle(name, seed, rate, v0, v1, description, R=40.0):
    """Left circle of radius R, speed v0 -> v1 between 5 and 35 s, path-following driver."""
    rng = np.random.default_rng(seed)
    t = _grid(40.0, rate)
    v = v0 + (v1 - v0) * _smoothstep(t, 5.0, 35.0)
    td = band_limited(t, rng, 0.2)
    return _finish(name, seed, description, rate, t, v, np.zeros_like(t), td, np.full_like(t, 1.0 / R),
                   circle=(0.0, R, R), driver=DriverGains())


def _circular_path(seed, rate):
    return _circle("circular_path", seed, rate, 10.0, 15.0,
                   "Nguyen et al. 2021 Sec. IV-C scenario 2: circle of radius 40 m (left), speed 10 -> 15 m/s "
                   "(a_y 2.5 -> 5.6 m/s²), path-following driver model")


def _circular_path_normal(seed, rate):
    return _circle("circular_path_normal", seed, rate, 6.0, 9.0,
                   "Nguyen et al. 2021 Sec. IV-C scenario 2 in the paper's own 'normal driving' range (its linear "
                   "tyre model (3)): circle of radius 40 m, speed 6 -> 9 m/s (a_y 0.9 -> 2.0 m/s²)")


def _contour_grip(name, seed, rate, v0, v1, l_r, description):
    """Contour whose radius of curvature swings 50 ± 5 m (period 15-25 s, drawn), speed v0 -> v1
    (smooth, 2-38 s), grip :func:`paper_grip` with length scale ``l_r`` over world coordinates
    whose origin is the start point (the plant starts at X = Y = 0), curvature-following driver."""
    rng = np.random.default_rng(seed)
    t = _grid(40.0, rate)
    v = v0 + (v1 - v0) * _smoothstep(t, 2.0, 38.0)
    radius = 50.0 + 5.0 * np.sin(2 * np.pi * t / rng.uniform(15.0, 25.0))
    kap = 1.0 / radius
    td = band_limited(t, rng, 0.2)

    def grip(_t, X, Y):
        return paper_grip(X, Y, l_r=l_r)

    return _finish(name, seed, description, rate, t, v, np.zeros_like(t), td, kap, driver=DriverGains(),
                   grip=grip)


def _time_varying_grip(seed, rate):
    return _contour_grip("time_varying_grip", seed, rate, 8.0, 13.0, 1.4,
                         "Nguyen et al. 2021 Sec. IV-D scenario 3, stress case: contour with radius 45-55 m, speed "
                         "8 -> 13 m/s (a_y up to 3.7 m/s² on the path), grip 0.6 (1 + sin(π sqrt(X² + Y²) "
                         "/ l_r)), l_r = 1.4 m, floored at 0.05")


def _time_varying_grip_normal(seed, rate):
    return _contour_grip("time_varying_grip_normal", seed, rate, 6.0, 9.0, 1.49,
                         "Nguyen et al. 2021 Sec. IV-D scenario 3 in the paper's 'normal driving' range (the speeds "
                         "of circular_path_normal): contour with radius 45-55 m, increasing speed 6 -> 9 m/s "
                         "(a_y 0.7 -> 1.8 m/s² on the path), the literal grip law 0.6 (1 + sin(π "
                         "sqrt(X² + Y²) / l_r)) with Table I's l_r = 1.49 m (floored at 0.05), X, Y from the "
                         "start point")


def _braking_on_bend(seed, rate):
    rng = np.random.default_rng(seed)
    t = _grid(12.0, rate)
    tb = 5.0 + rng.uniform(-0.3, 0.3)
    v = 22.0 - 4.0 * np.clip(t - tb, 0.0, 3.0)               # 22 -> 10 m/s at -4 m/s^2
    v = np.convolve(np.pad(v, 25, mode="edge"), np.ones(51) / 51, mode="same")[25:-25]
    kap = _smoothstep(t, 1.0, 3.0) / 100.0                   # R = 100 m: a_y 4.8 m/s^2 at entry
    td = band_limited(t, rng, 0.2)
    return _finish("braking_on_bend", seed,
                   "braking at -4 m/s² (22 -> 10 m/s) in a 100 m-radius bend entered at 22 m/s "
                   "(a_y ≈ 4.8 m/s²): combined slip and load transfer", rate, t, v,
                   np.zeros_like(t), td, kap, driver=DriverGains())


def _banked_road_braking(seed, rate):
    rng = np.random.default_rng(seed)
    t = _grid(60.0, rate)
    ss = _smoothstep
    # speed: 90 km/h, sharp braking (peak -4.5 m/s^2) to 36 km/h (14-19 s) in a banked left bend, 36 km/h,
    # back to 22 m/s, braking (peak -3.75 m/s^2) to 12 m/s (44-48 s) in a second banked bend
    v = (25.0 - 15.0 * ss(t, 14.0, 19.0) + 12.0 * ss(t, 28.0, 38.0) - 10.0 * ss(t, 44.0, 48.0))
    # bends: left R = 200 m (5-21 s), right R = 80 m (30-35 s), left R = 120 m (42-52 s), plus a
    # little lane-keeping curvature noise
    kap = (ss(t, 5.0, 9.0) * (1 - ss(t, 17.0, 21.0)) / 200.0
           - ss(t, 30.0, 31.5) * (1 - ss(t, 34.0, 35.5)) / 80.0
           + ss(t, 42.0, 44.0) * (1 - ss(t, 50.0, 52.0)) / 120.0
           + band_limited(t, rng, 2e-4, 0.05, 0.5, 8))
    # bank: superelevation -3 deg in the first bend (gravity towards the inside), +2 deg crossfall on
    # the straight after it and in the right bend, -1.5 deg in the last bend, flat at both ends
    deg = np.pi / 180.0
    bank = deg * (-3.0 * ss(t, 5.0, 9.0) + 5.0 * ss(t, 20.0, 24.0) - 2.0 * ss(t, 36.0, 40.0)
                  - 1.5 * ss(t, 40.0, 44.0) + 1.5 * ss(t, 51.0, 55.0))
    td = band_limited(t, rng, 0.2)
    return _finish("banked_road_braking", seed,
                   "Menhour et al. 2014 Sec. IV hard case: banked road with sharp braking (90 -> 36 km/h, peak -4.5 m/s², in a "
                   "200 m left bend with -3° superelevation), +2° crossfall, a right bend, a second braking "
                   "(22 -> 12 m/s) in a -1.5° bend; speed 10-25 m/s, |a_y| <= 4 m/s²", rate, t, v,
                   np.zeros_like(t), td, kap, driver=DriverGains(), bank=bank)


def straight_line(speed: float = 20.0, duration: float = 3.0, sample_rate: float = 100.0) -> Scenario:
    """Constant speed, no steering torque at all (open loop, T_d = T_a = 0): β must stay 0."""
    t = _grid(duration, sample_rate)
    z = np.zeros_like(t)
    return _finish("straight_line", 0, f"straight line at {speed} m/s, hands off", sample_rate, t,
                   np.full_like(t, float(speed)), z, z.copy())


def steady_circle(radius: float = 60.0, speed: float = 12.0, duration: float = 8.0,
                  sample_rate: float = 100.0) -> Scenario:
    """Constant-speed left circle (centre (0, radius)) followed by the path driver, no noise torque."""
    if not (radius > 0 and speed > 0 and duration > 0):
        raise ScenarioError("steady_circle needs radius, speed, duration > 0")
    t = _grid(duration, sample_rate)
    z = np.zeros_like(t)
    return _finish("steady_circle", 0, f"steady circle R = {radius} m at {speed} m/s", sample_rate,
                   t, np.full_like(t, float(speed)), z, z.copy(), np.full_like(t, 1.0 / radius),
                   circle=(0.0, float(radius), float(radius)), driver=DriverGains())


SCENARIOS: dict[str, tuple[Callable, int]] = {
    "track_varying_speed": (_track_varying_speed, 1),
    "takeover_opposing_assist": (_takeover_opposing_assist, 2),
    "zigzag_growing_ay": (_zigzag_growing_ay, 3),
    "zigzag_constant_speed_assist": (_zigzag_constant_speed_assist, 4),
    "random_trajectory_accel": (_random_trajectory_accel, 5),
    "circular_path": (_circular_path, 6),
    "circular_path_normal": (_circular_path_normal, 9),
    "time_varying_grip": (_time_varying_grip, 7),
    "time_varying_grip_normal": (_time_varying_grip_normal, 12),
    "braking_on_bend": (_braking_on_bend, 8),
    "banked_road_braking": (_banked_road_braking, 10),
}
"""name -> (builder, default seed)."""


def names() -> tuple[str, ...]:
    """Names of all scenarios, in library order."""
    return tuple(SCENARIOS)


def make(name: str, seed: int | None = None, sample_rate: float = 100.0) -> Scenario:
    """Build a scenario.

    Parameters
    ----------
    name : str
        One of :func:`names`.
    seed : int, optional
        Random seed; default: the scenario's own.
    sample_rate : float, optional
        Output grid rate [Hz].

    Returns
    -------
    Scenario

    Raises
    ------
    ScenarioError
        Unknown name, negative seed or non-positive rate.
    """
    if name not in SCENARIOS:
        raise ScenarioError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)} (and, in uiogen validate, "
                            f"excitation: any model on its own equations)")
    builder, default = SCENARIOS[name]
    s = default if seed is None else seed
    if not isinstance(s, (int, np.integer)) or s < 0:
        raise ScenarioError(f"seed must be a non-negative integer, got {s!r}")
    if not (isinstance(sample_rate, (int, float)) and math.isfinite(sample_rate) and sample_rate > 0):
        raise ScenarioError(f"sample_rate must be > 0, got {sample_rate!r}")
    return builder(int(s), float(sample_rate))
