"""Nonlinear single-track observer with saturating axle tyres, certified by the DMVT over slip sets.

Model (``model_defs/single_track_nonlinear_tyre.py``, :mod:`.representation`): x = (v_y, r), known
inputs delta and a_x, measured v_x, outputs a_y and r; the dynamics and a_y are affine in the
body-frame axle forces Phi_k, and Phi_k depends on the unmeasured v_y only through the axle's slip.

Step (discrete, sample time T_s; r_m, a_y, delta, a_x, v_x measured at sample k)::

    inside S:   x_hat_{k+1} = x_hat_k + T_s f(v_hat_y, r_m, u, v_x) + L (y_k - [a_y(v_hat_y, r_m, u, v_x); r_hat])
    flagged:    v_hat_y,k+1 = v_hat_y + T_s (a_y,m - r_m v_x),  r_hat_{k+1} = r_m + T_s f_r

The gain L is designed by LMIs jointly with the Lyapunov matrix (:mod:`.design`), or given in the
observer file and certified. The measured r stands in for the state r inside the tyre forces, so
the error e = x - x_hat obeys, by the mean-value theorem applied to each axle force along its
slip (the true and the estimated slips lie on one segment),

    e_{k+1} = A(s, Theta) e_k + (B_x - L B_y) w_k,   A = I + T_s [G_f Theta s, 0] - L [[G_a Theta s, 0], [0, 1]],

with s = 1/v_x, theta_k = v_x dPhi_k/dv_y at an intermediate point and w the disturbances of
:mod:`.design`. theta_k is bounded soundly over the certified set S: |t_k| <= rho t_sl,k
(``sliding_fraction`` rho < 1 of each axle's sliding slip, which the measured a_x lowers through
the friction circle), delta and a_x within ``[state_bounds]``, v_x within ``[scheduling.v_x]``,
and the declared ranges of each axle's stiffness and friction. There the Fiala slope is at least
(1 - rho)^2 C_k; at full sliding it is 0 and v_y is unobservable from (a_y, r), so no decay over a
set holding full sliding can be certified. ``through_sliding`` certifies the step at every slip instead
(:func:`.design.through_sliding`): the slope box [theta_full, 0] holds beyond sliding, and with a third
Lyapunov matrix V decays at a rate proportional to the axle slopes and grows at most at
``sliding_growth`` where both axles slide; the step then corrects by the tyre model at every slip.

Samples whose estimated slip (not with ``through_sliding``), delta, a_x or v_x lie outside S are flagged (excess > 0,
SCHEDULING_CLAMPED): the certificate does not cover them, the tyre model carries (almost) no
information on v_y there, and the step integrates the exact kinematics v_y' = a_y - r v_x with
the measured a_y instead (a tyre model whose friction is a little low would otherwise drive the
estimate along a saturated force without end). The true slip cannot be checked (v_y is not
measured).
"""
from __future__ import annotations

import functools
import sys
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import sympy as sp

from ...certificate.artifact import artifact_head, significant, solver_certificate
from ...certificate.certificate import Bound, Certificate, Recheck, Step
from ...design import lock
from ...model import load_parameters
from ...settings import Rule, parse_settings, setting
from ...design.precision import margin_field, precision_field
from ...emit.stepgen import lambdify
from ...contract.family import ObserverBuild, StepNotes
from . import design as dsn
from .representation import TyreRepresentation, represent


@dataclass(frozen=True)
class NonlinearTyreSettings:
    """``[design]`` of a nonlinear-tyre observer: the sets, the decay required, the noise levels the
    gain is designed for, and optionally given gains (rows v_y, r; columns a_y, r)."""

    gain_vy_ay: float | None = setting(None, doc="given L[v_y, a_y] [s]; absent: designed")
    gain_vy_r: float | None = setting(None, doc="given L[v_y, r] [m/rad]")
    gain_r_ay: float | None = setting(None, doc="given L[r, a_y] [s/m]")
    gain_r_r: float | None = setting(None, doc="given L[r, r] [-]")
    sliding_fraction: float = setting(0.9, gt=0, lt=1, doc="rho: the certified set |t| <= rho t_sl per axle "
                                                            "(decay, status bit, kinematic fallback)")
    through_sliding: bool = setting(False, doc="certify the step at every slip (a decay rate proportional to the "
                                               "axle slopes, V growing at most at sliding_growth where both axles "
                                               "slide): the step then corrects by the tyre model at every slip, "
                                               "with no kinematic fallback beyond sliding_fraction")
    sliding_growth: float | None = setting(None, gt=0, doc="epsilon [1/s]: the growth of V the through-sliding "
                                                           "certificate allows where both axles slide (v_y is "
                                                           "unobservable there); absent: 1e-3")
    fallback_growth: float | None = setting(None, gt=0, doc="epsilon_fb [1/s]: certify the kinematic fallback too "
                                                            "(the gains designed with it): on a sample flagged for "
                                                            "its estimated slip alone V grows at most by 1 + Ts "
                                                            "epsilon_fb, whatever the true slip; absent: the "
                                                            "fallback is not certified")
    gain_sliding_fraction: float = setting(0.3, gt=0, lt=1, doc="the set of the l2 gain bound, <= sliding_fraction")
    decay: float | None = setting(None, gt=0, lt=1, doc="lambda: V(e+) <= lambda^2 V(e) required; absent: "
                                                        "decay_fraction of the largest certifiable rate")
    decay_fraction: float = setting(0.2, gt=0, le=1, doc="fraction of the largest certifiable decay rate required")
    objective: str = setting("gamma", choices=("gamma", "noise_bound"),
                             doc="what the gains minimize: gamma, one l2 gain for every channel at its level; "
                                 "noise_bound, the RMS bound of the sideslip error with every channel at its level "
                                 "(one multiplier per channel, as a Kalman gain weighs each noise by its variance)")
    stiffness_range: tuple = setting((1.0, 1.0), items=Rule(float, gt=0),
                                     doc="[lo, hi]: factors on each axle's cornering stiffness the certificate covers")
    friction_range: tuple = setting((1.0, 1.0), items=Rule(float, gt=0),
                                    doc="[lo, hi]: factors on each axle's friction coefficient the certificate covers")
    sigma_force_front: float | None = setting(None, gt=0, doc="unmodelled front axle force level [N]")
    sigma_force_rear: float | None = setting(None, gt=0, doc="unmodelled rear axle force level [N]")
    sigma_ay: float = setting(1.0, gt=0, doc="a_y sensor error level [m/s^2]")
    sigma_r: float = setting(0.005, gt=0, doc="yaw-rate sensor error level [rad/s]")
    sigma_euler_vy: float = setting(0.02, gt=0, doc="Euler residual of v_y' [m/s^2]")
    sigma_euler_r: float = setting(0.01, gt=0, doc="Euler residual of r' [rad/s^2]")
    margin: float = setting(1e-6, gt=0, doc="smallest eigenvalue imposed on every LMI block")
    tol: float = setting(1e-8, gt=0, doc="solver tolerance")
    bounds_rel_tol: float = setting(1e-3, gt=0, doc="tightness of the Jacobian bounds")
    precision: str = precision_field()
    float32_margin: float = margin_field()

    def __post_init__(self):
        gains = [self.gain_vy_ay, self.gain_vy_r, self.gain_r_ay, self.gain_r_r]
        if any(g is not None for g in gains) and any(g is None for g in gains):
            raise ValueError("gain_vy_ay, gain_vy_r, gain_r_ay and gain_r_r are given all four (the gains are then "
                             "certified, not designed) or none (designed)")
        if self.sliding_growth is not None and not self.through_sliding:
            raise ValueError(f"sliding_growth = {self.sliding_growth:g} is read with through_sliding = true only (the "
                             f"growth the certificate at every slip allows where both axles slide); set both, or "
                             f"neither")
        if self.fallback_growth is not None and self.through_sliding:
            raise ValueError(f"fallback_growth = {self.fallback_growth:g} certifies the kinematic fallback beyond "
                             f"sliding_fraction, which through_sliding = true replaces by the tyre correction; set "
                             f"one of them")
        if self.gain_sliding_fraction > self.sliding_fraction:
            raise ValueError(f"gain_sliding_fraction = {self.gain_sliding_fraction:g} must not exceed "
                             f"sliding_fraction = {self.sliding_fraction:g} (the gain set lies in the certified set)")
        for key in ("stiffness_range", "friction_range"):
            rng = getattr(self, key)
            if len(rng) != 2 or not rng[0] <= 1.0 <= rng[1]:
                raise ValueError(f"{key} = {list(rng)} must be [lo, hi] with lo <= 1 <= hi (factors on the "
                                 f"parameter file's value)")
        missing = [key for key in ("sigma_force_front", "sigma_force_rear") if getattr(self, key) is None]
        if missing:
            raise ValueError(f"{' and '.join(missing)} {'is' if len(missing) == 1 else 'are'} required: the level of "
                             f"the axle force the tyre model misses [N] (`uiogen fit` identifies it from a log with a "
                             f"sideslip reference)")

    @property
    def given_gains(self) -> bool:
        return self.gain_vy_ay is not None

    @property
    def gain(self) -> np.ndarray:
        return np.array([[self.gain_vy_ay, self.gain_vy_r], [self.gain_r_ay, self.gain_r_r]], dtype=float)

    @property
    def sigma(self) -> np.ndarray:
        return np.array([self.sigma_force_front, self.sigma_force_rear, self.sigma_ay, self.sigma_r,
                         self.sigma_euler_vy, self.sigma_euler_r], dtype=float)


# --- the step ----------------------------------------------------------------------------------------

def _functions(rep: TyreRepresentation, xp):
    args = rep.symbols
    return ([lambdify(args, e, xp) for e in rep.f], lambdify(args, rep.a_y, xp),
            [lambdify(args, rep.rho * e, xp) for e in rep.sliding], [lambdify(args, t, xp) for t in rep.slips])


@functools.lru_cache(maxsize=64)
def _compiled_once(args: tuple, expr):
    return lambdify(args, expr, ca)


def _parametric_functions(rep: TyreRepresentation):
    """What :func:`_functions` gives for CasADi, compiled once per model expression in this process with the
    parameters as arguments and their numbers passed in: the same step up to the order of a few operations on
    the numbers (the emitted C is compiled from :func:`_functions`). The folds of ``uiogen fit`` change only
    the tyre's numbers: sympy's printing of the tyre laws, most of a fold's step, is then done once."""
    symbols, values = tuple(p for p, _ in rep.parameters), tuple(v for _, v in rep.parameters)
    args = (*rep.symbols, *symbols)

    def bound(expr):
        fn = _compiled_once(args, expr)
        return lambda *signals: fn(*signals, *values)
    f, a_y, sliding, slips = rep.forms
    return [bound(e) for e in f], bound(a_y), [bound(rep.rho * e) for e in sliding], [bound(t) for t in slips]


def step_parts(rep, L, Ts, z, u, y, rho, fns, xp=np):
    """(x_next, excess): z = [x_hat_k (prediction from k-1)]; u = the known inputs (delta, a_x), y = the
    outputs in the model's order (a_y and r), rho = [v_x]."""
    f_fn, ay_fn, lim_fn, t_fn = fns
    fmin, fmax, fabs = (ca.fmin, ca.fmax, ca.fabs) if xp is ca else (min, max, abs)
    vy, rh = z[0], z[1]
    a_m, r_m, v = y[rep.signals.a_y_index], y[rep.signals.yaw_rate_index], rho[0]
    vc = fmin(fmax(v, rep.v_x_box[0]), rep.v_x_box[1])
    excess = fabs(v - vc)
    for k, (_, (lo, hi)) in enumerate(rep.input_boxes):
        excess = excess + fmax(0.0, fmax(lo - u[k], u[k] - hi))
    args = (vy, r_m, *[u[k] for k in range(len(rep.input_boxes))], vc)
    if rep.through_set is None:          # through sliding, every slip is certified: only the boxes flag
        for t_k, lim_k in zip(t_fn, lim_fn):
            excess = excess + fmax(0.0, fabs(t_k(*args)) - lim_k(*args))
    f = [fn(*args) for fn in f_fn]
    ea = a_m - ay_fn(*args)
    er = r_m - rh
    corrected = (vy + Ts * f[0] + L[0, 0] * ea + L[0, 1] * er, rh + Ts * f[1] + L[1, 0] * ea + L[1, 1] * er)
    kinematic = (vy + Ts * (a_m - r_m * v), r_m + Ts * f[1])
    if xp is ca:
        out = tuple(ca.if_else(excess > 0, k_, c_) for k_, c_ in zip(kinematic, corrected))
    else:
        out = kinematic if excess > 0 else corrected
    return out, excess


@dataclass(frozen=True)
class Build(ObserverBuild):
    """A certified nonlinear-tyre observer (see the module docstring)."""

    config: object
    rep: TyreRepresentation
    settings: NonlinearTyreSettings
    plant: dsn.Plant
    synthesis: dsn.Design
    level: dsn.LevelBound
    decay_verts: tuple
    gain_verts: tuple
    recheck: dict
    timings: dict
    through: object = None          # dsn.Through (through_sliding), else None
    through_verts: tuple = ()

    @property
    def L(self) -> np.ndarray:
        return self.synthesis.L

    @property
    def P(self) -> np.ndarray:
        return self.synthesis.P

    @property
    def solution(self):
        return self.synthesis.solution

    @property
    def definition(self):
        return self.config.load_model()

    @property
    def known_inputs(self) -> list:
        return list(self.rep.signals.known_inputs)

    # every name is the model's (representation.Signals): states, known inputs, outputs, speed
    state_names = property(lambda self: [f"{n}_next" for n in self.output_names] + self.output_names)
    output_names = property(lambda self: [self.rep.signals.lateral_speed, self.rep.signals.yaw_rate])
    input_names = property(lambda self: [*self.known_inputs, *(f"y_{n}" for n in self.rep.signals.outputs),
                                         self.rep.signals.speed])
    nu = property(lambda self: len(self.rep.input_boxes))
    ny = property(lambda self: 2)

    def step_function(self, parametric: bool = False):
        """The step as a CasADi function (what is emitted as C); ``parametric``: the same step from the model's
        expressions compiled once per process (:func:`_parametric_functions`), for the many designs of a fit."""
        nu = self.nu
        z, u, y, rho = ca.SX.sym("z", 4), ca.SX.sym("u", nu), ca.SX.sym("y", 2), ca.SX.sym("rho", 1)
        fns = _parametric_functions(self.rep) if parametric else _functions(self.rep, ca)
        (vy_n, r_n), excess = step_parts(self.rep, self.L, self.config.sample_time, z, u, y, rho, fns, xp=ca)
        # the sympy expressions are put together unevaluated (representation.numeric): one cos(delta),
        # one capacity per axle, ... instead of one per use
        outs = ca.cse([ca.vertcat(vy_n, r_n, z[0], z[1]), excess])
        return ca.Function(f"{self.name}_kernel", [z, u, y, rho], outs, ["z", "u", "y", "rho"], ["z_next", "excess"])

    def reference_step(self, z, u, y, rho):
        z, u, y, rho = (np.asarray(a, float) for a in (z, u, y, rho))
        (vy_n, r_n), excess = step_parts(self.rep, self.L, self.config.sample_time, z, u, y, rho,
                                         self.rep.numpy_functions, xp=np)
        return np.array([vy_n, r_n, z[0], z[1]], dtype=float), float(excess)

    def contraction_metrics(self):
        """The common P over the DMVT vertices of the certified set: the prediction (v_y, r).

        With ``through_sliding`` the step is not flagged beyond that set, so the decay set's P says
        nothing there: the metric is then the through-sliding P_t, whose certificate holds at every slip
        with the rate a phi - eps (1 - phi). Its c is the rate at full slope on both axles; at a sample
        with less slope the step's own gain in the P_t norm (its Jacobian at the sample, which the
        through-sliding blocks bound by sqrt(1 - T_s (a phi - eps (1 - phi))), above 1 only where both
        axles slide) replaces it (:func:`codegen.targets.float32.deviation_bound`)."""
        from ...certificate.contraction import ContractionMetric
        D = self.plant.D            # P is solved in the scaled state D x (certify: D' P D)
        if self.through is not None:
            c = float(np.sqrt(1.0 - self.config.sample_time * self.through.rate))
            return [ContractionMetric(c, (D.T @ self.through.P @ D,), tuple(self.state_names[:2]),
                                      f"through-sliding P_t at every slip: A' P_t A <= c^2 P_t at full slope (rate "
                                      f"{self.through.rate:.4g} 1/s), the step's own gain where the axles slide "
                                      f"(growth at most {self.through.growth:.3g} 1/s)",
                                      knob="[design] decay or decay_fraction (the gains' rate), or through_sliding "
                                           "= false")]
        return [ContractionMetric(float(self.recheck["contraction_per_step"]), (D.T @ self.P @ D,),
                                  tuple(self.state_names[:2]),
                                  "common P over the DMVT vertices: A' P A <= c^2 P, on the certified slip set",
                                  knob="[design] decay or decay_fraction (the rate the LMIs impose), a lower "
                                       "sliding_fraction")]

    def lmi_problem(self):
        d = self.synthesis
        L_scaled = None if not d.given else self.plant.D @ d.L @ np.linalg.inv(self.plant.D)
        return dsn.lmi_problem(self.plant, self.decay_verts, self.gain_verts, self.settings, d.rate, d.best_rate,
                               L_scaled)

    def input_boxes(self):
        return {self.rep.signals.speed: list(self.rep.v_x_box), **{n: list(b) for n, b in self.rep.input_boxes}}

    def scheduling_boxes(self):
        return [(self.rep.signals.speed, *self.rep.v_x_box, False)]

    def signal_docs(self):
        s = self.rep.signals
        vy, r, u = s.lateral_speed, s.yaw_rate, s.unit
        state = [{"name": f"{vy}_next", "doc": f"predicted lateral speed for the next sample [{u(vy)}]"},
                 {"name": f"{r}_next", "doc": f"predicted yaw rate for the next sample [{u(r)}]"},
                 {"name": vy, "doc": f"estimate of {vy} at this sample, from the samples before it [{u(vy)}]"},
                 {"name": r, "doc": f"estimate of {r} at this sample, from the samples before it [{u(r)}]"}]
        docs = {s.steering: f"road-wheel steering angle [{u(s.steering)}]"}
        if "a_x" in s.known_inputs and s.steering != "a_x":     # the built-in model's combined slip
            docs["a_x"] = (f"measured longitudinal acceleration at the CoG [{u('a_x')}] (combined slip: the "
                           f"axles' lateral capacity)")
        inputs = [{"name": n, "doc": docs.get(n, f"measured {n}, read by the axles' lateral capacity [{u(n)}]")}
                  for n in self.known_inputs]
        measured = {s.a_y: f"measured lateral acceleration at the CoG [{u(s.a_y)}]",
                    s.yaw_rate_output: f"measured yaw rate [{u(s.yaw_rate_output)}]"}
        inputs += [{"name": f"y_{n}", "doc": measured[n]} for n in s.outputs]
        inputs += [{"name": s.speed, "doc": f"measured longitudinal speed [{u(s.speed)}]"}]
        return state, inputs, state[2:]

    def step_notes(self):
        s = self.rep.signals
        measured = [s.speed, *s.known_inputs]
        which = ", ".join(measured[:-1]) + " or " + measured[-1]
        slip = ("" if self.through is not None else
                ", or an estimated\n * axle slip beyond sliding_fraction of its sliding slip")
        return StepNotes(
            notes=("Each call takes the measurements of sample k and returns the estimate of sample k made",
                   "from the samples before it; the state's head is the prediction for sample k+1.",
                   f"A flagged sample integrates the kinematics {s.lateral_speed}' = {s.a_y} - {s.yaw_rate} "
                   f"{s.speed} (no tyre correction)."),
            clamp=(f"{which} outside the certified set ({s.speed} clamped for the model){slip}: the certificate "
                   "does not cover this sample,\n * and the step integrates the kinematics instead of correcting "
                   "by the tyre model."),
            warmup="never set.")

    @property
    def certificate(self):
        c, s = self.recheck, self.settings
        lv = dict(zip(dsn.CHANNELS, s.sigma.tolist()))
        ranges = ""
        if list(s.stiffness_range) != [1.0, 1.0] or list(s.friction_range) != [1.0, 1.0]:
            ranges = (f"; every axle's cornering stiffness x[{s.stiffness_range[0]:g}, {s.stiffness_range[1]:g}] "
                      f"and friction x[{s.friction_range[0]:g}, {s.friction_range[1]:g}] of the parameter file")
        gains = "given" if self.synthesis.given else "designed (LMIs, jointly with the Lyapunov matrix)"
        names = self.rep.signals
        measured = ", ".join([names.steering, names.speed, *(n for n in names.known_inputs if n != names.steering)])
        return Certificate(
            family="nonlinear_tyre_observer",
            claim=(f"one quadratic Lyapunov matrix at every vertex of (1/v_x, theta_f, theta_r) (DMVT, gains "
                   f"{gains}): the estimation error decays at {c['decay_rate']:.4g} 1/s (the largest certifiable: "
                   f"{c['best_decay_rate']:.4g} 1/s), and on the gain set (|t_k| <= {s.gain_sliding_fraction:g} "
                   f"t_sl,k) the sideslip error has the l2 gain gamma from the disturbances normalized by their "
                   f"levels, and (per-channel multipliers, a second Lyapunov matrix) an RMS bound with every "
                   f"channel at its level" + self._through_claim() + self._fallback_claim()),
            plant_class=(f"the single-track model {self.config.model} with the tyre law of its AXLES per axle "
                         f"(the capacity from the measured signals), Euler-discretized at Ts = "
                         f"{self.config.sample_time:g} s, parameters of "
                         f"{self.config.parameters}{ranges}"),
            noise=(f"axle force residuals (sigma {lv['force_front']:.4g}, {lv['force_rear']:.4g} N), a_y sensor "
                   f"error ({lv['ay']:.4g} m/s^2), yaw-rate sensor error ({lv['r']:.4g} rad/s), Euler residuals "
                   f"({lv['euler_vy']:.4g} m/s^2, {lv['euler_r']:.4g} rad/s^2): any sequences"),
            region={self.rep.signals.speed: tuple(self.rep.v_x_box),
                    **{n: tuple(b) for n, b in self.rep.input_boxes}},
            region_note=(f"|t_k| <= {s.sliding_fraction:g} t_sl,k on each axle (the sliding slip at the measured "
                         f"signals) for the true AND the estimated state; SCHEDULING_CLAMPED flags the estimated "
                         f"slip or a measured signal ({measured} where the law reads it) outside the set: the "
                         f"true slip is not seen ({self.rep.signals.lateral_speed} is not measured)"
                         + ("" if s.fallback_growth is None else
                            f"; a sample flagged for its estimated slip alone is covered by the fallback's bound (V "
                            f"grows at most by 1 + Ts {s.fallback_growth:g}), one flagged for a measured signal is not")
                         if self.through is None else
                         f"every slip for the true and the estimated state (each axle force constant beyond its "
                         f"sliding slip, checked on the model at |t| = 1 to 3 t_sl; the front slip angle within "
                         f"+-(90 deg - max |{names.steering}|)); the decay and the l2 gain at |t_k| <= "
                         f"{s.sliding_fraction:g} and {s.gain_sliding_fraction:g} t_sl,k; SCHEDULING_CLAMPED "
                         f"flags a measured signal ({measured}) outside its box only"),
            recheck=Recheck(c["blocks"], c["worst_block"], c["worst_min_eig"], c["worst_relative_margin"]),
            step=Step(self.config.sample_time, "Euler step of the observer (" + (
                "kinematic fallback outside the set" if self.through is None else
                "tyre correction at every slip; kinematic fallback outside the boxes") + ")",
                      c["contraction_per_step"]),
            bounds=(Bound("gamma", c["gamma_deg"], "deg", "l2", "beta, the sideslip estimation error",
                          "the disturbances w, each channel divided by its level sigma"),
                    Bound("beta_rms", c["bound_deg_at_levels"], "deg", "rms", "beta, the sideslip estimation error",
                          "every disturbance channel at its level sigma, on the gain set (per-channel "
                          "multipliers: " + ", ".join(f"{k} {v:.3g}" for k, v in c["bound_deg_by_channel"].items())
                          + " deg)")),
            extras=solver_certificate(self.solution, recheck=self.recheck))

    def _fallback_claim(self) -> str:
        if self.settings.fallback_growth is None:
            return ""
        return (f"; on a sample flagged for its estimated slip alone (the kinematic fallback, the measured signals in "
                f"their boxes) V(e+) <= (1 + Ts eps_fb) V(e), eps_fb = {self.settings.fallback_growth:.4g} 1/s, "
                f"whatever the true slip (the same Lyapunov matrix)")

    def _through_claim(self) -> str:
        if self.through is None:
            return ""
        c = self.recheck
        return (f"; at every slip, with a third Lyapunov matrix: V(e+) <= (1 - Ts (a phi - eps (1 - phi))) V(e), "
                f"a = {c['through_rate']:.4g} 1/s with both axles at full slope, eps = {c['sliding_growth']:.3g} "
                f"1/s (growth) with both sliding, phi the mean over the axles of theta_k / theta_k,full")

    def _representation(self):
        rep = self.rep

        def axles(bounds):
            return [{"theta_bounds": list(map(significant, b.theta)),
                     "theta_attained_on_grid": list(map(significant, b.attained)),
                     "slope_bounds": list(map(significant, b.slope)),
                     "kinematic_factor_bounds": list(map(significant, b.kinematic)),
                     "slip_max": significant(b.slip_max)} for b in bounds]
        return {"G_f": rep.G_f.tolist(), "G_a": rep.G_a.tolist(), "v_x_box": list(rep.v_x_box),
                "input_boxes": {n: list(b) for n, b in rep.input_boxes},
                "certified_set": {"sliding_fraction": self.settings.sliding_fraction, "axles": axles(rep.decay_set)},
                "gain_set": {"sliding_fraction": self.settings.gain_sliding_fraction, "axles": axles(rep.gain_set)},
                **({} if rep.through_set is None else {"through_set": {"axles": axles(rep.through_set)}}),
                "stiffness_range": list(self.settings.stiffness_range),
                "friction_range": list(self.settings.friction_range)}

    def artifact(self):
        return {**artifact_head(self, [self.rep.signals.speed], flags_from_inputs_only=False),
                "representation": self._representation(),
                "L": self.L.tolist(), "P": self.P.tolist(), "gains": "given" if self.synthesis.given else "designed",
                "noise_levels": dict(zip(dsn.CHANNELS, self.settings.sigma.tolist())),
                "sliding_fraction": self.settings.sliding_fraction,
                **({} if self.through is None else {"P_through": self.through.P.tolist()})}

    def figures(self):
        c = self.recheck
        s = self.settings
        return {"gains": "given" if self.synthesis.given else "designed",
                "theta_bounds": [list(b.theta) for b in self.rep.decay_set],
                "theta_gain_set": [list(b.theta) for b in self.rep.gain_set],
                "slip_max": [b.slip_max for b in self.rep.decay_set], "L": self.L.tolist(), "P": self.P.tolist(),
                "lmi_blocks": c["blocks"], "worst_block": c["worst_block"], "worst_min_eig": c["worst_min_eig"],
                "worst_relative_margin": c["worst_relative_margin"],
                "contraction_per_step": c["contraction_per_step"], "time_constant_s": c["time_constant_s"],
                "slowest_vertex": c["slowest_vertex"], "decay_rate": c["decay_rate"],
                "best_decay_rate": c["best_decay_rate"], "gamma_deg": c["gamma_deg"],
                "bound_deg_at_levels": c["bound_deg_at_levels"], "bound_deg_by_channel": c["bound_deg_by_channel"],
                "sliding_fraction": s.sliding_fraction, "gain_sliding_fraction": s.gain_sliding_fraction,
                "stiffness_range": list(s.stiffness_range), "friction_range": list(s.friction_range),
                "noise_levels": dict(zip(dsn.CHANNELS, s.sigma.tolist())),
                "input_boxes": {n: list(b) for n, b in self.rep.input_boxes}, "v_x_box": list(self.rep.v_x_box),
                "sample_time": self.config.sample_time, "through_sliding": s.through_sliding,
                **({} if s.fallback_growth is None else {"fallback_growth": s.fallback_growth}),
                **({} if self.through is None else {
                    "theta_through": [list(b.theta) for b in self.rep.through_set],
                    "through_rate": c["through_rate"], "sliding_growth": c["sliding_growth"],
                    "through_time_constant_s": c["through_time_constant_s"]})}


def parse(config, tol=None) -> NonlinearTyreSettings:
    return parse_settings(NonlinearTyreSettings, config.design, source=config.source, section="design",
                          **({"tol": tol} if tol is not None else {}))


REPRESENTATION = "tyre_representation"
"""The kind of the kept representations (:func:`codegen.model.cache.remembered`): the force form, the slip sets'
slope bounds and the boxes are the same for the same model, parameters and settings, every run."""


def build(config, solver, params=None):
    """model -> force form + sound axle Jacobian bounds on the sets -> vertex LMIs (gains and P,
    answered by ``solver``: :mod:`codegen.design.solver`) -> numpy re-check -> step. ``params``: a :class:`~codegen.model.ParameterSet` instead of the
    observer's parameter file (identification: :mod:`.fit`)."""
    settings = parse(config, solver.tol)
    t0 = time.perf_counter()
    if params is None:          # the observer file's own parameters: kept across runs (REPRESENTATION)
        from ...model import cache
        from . import representation as tyre_representation
        rep = cache.remembered(REPRESENTATION, lock.cache_parts(config, settings=settings),
                               lambda: represent(config.load_model_module(), load_parameters(config.parameter_path),
                                                 settings, config.source),
                               sys.modules[__name__], tyre_representation)
    else:                       # another car's (identification, :mod:`.fit`): derived each time
        rep = represent(config.load_model_module(), params, settings, config.source)
    t1 = time.perf_counter()
    d = float(np.sqrt(rep.v_x_box[0] * rep.v_x_box[1]))
    plant = dsn.Plant(config.sample_time, rep.G_f, rep.G_a, np.array(rep.lever), settings.sigma, np.diag([1.0, d]))
    decay_verts = tuple(dsn.vertices(rep, rep.decay_set, with_speed=False))
    gain_verts = tuple(dsn.vertices(rep, rep.gain_set, with_speed=True))
    design = dsn.synthesize(plant, decay_verts, gain_verts, settings, solver)
    level = dsn.level_bound(plant, gain_verts, settings, design, solver)
    through, through_verts = None, ()
    if rep.through_set is not None:
        through_verts = tuple(dsn.through_vertices(rep))
        through = dsn.through_sliding(plant, through_verts, settings, design, solver)
    t2 = time.perf_counter()
    cert = dsn.certify(plant, decay_verts, gain_verts, design, level, through, through_verts, settings.fallback_growth)
    t3 = time.perf_counter()
    return Build(config, rep, settings, plant, design, level, decay_verts, gain_verts, cert,
                 {"representation_s": t1 - t0, "design_s": t2 - t1, "solve_s": design.solution.solve_time_s,
                  "certificates_s": t3 - t2}, through, through_verts)
