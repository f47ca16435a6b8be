"""Nonlinear single-track observer with saturating axle tyres, certified by the DMVT over slip sets.

Model (``model_defs/single_track_nonlinear_tyre.py``): x = (v_y, r), known input delta, measured
v_x, outputs a_y and r; the dynamics and a_y are *affine in the body-frame axle forces* Phi_k,
and Phi_k depends on the unmeasured v_y only through the axle's slip t_k (``AXLES``).

Step (discrete, sample time T_s; r_m, a_y, delta, v_x measured at sample k)::

    x_hat_{k+1} = x_hat_k + T_s f(v_hat_y, r_m, delta, v_x) + L (y_k - [a_y(v_hat_y, r_m, delta, v_x); r_hat])

with the fixed gain L of the ``[design]`` table (identified, see the parameter file). The
measured r stands in for the state r inside the tyre forces (as the TS fuzzy UIO does with its
measured premises), so the estimation error e = x - x_hat obeys, by the mean-value theorem
applied to each axle force along v_y alone,

    e_{k+1} = (I + T_s G_f Theta s e_1^T - L [G_a Theta s e_1^T; e_2^T]) e_k =: A(s, Theta) e_k,

with s = 1/v_x, Theta = (theta_f, theta_r), theta_k = v_x dPhi_k/dv_y at an intermediate point,
and G_f = d f/d Phi, G_a = d a_y/d Phi constant. theta_k is bounded *soundly* (interval
arithmetic, :mod:`codegen.representation.bounds`) over the certified set S: |t_k| <= rho t_sl,k (``sliding_fraction``
rho < 1 of each axle's sliding slip), |delta| within ``[state_bounds] delta``, v_x within
``[scheduling.v_x]``. There the Fiala slope is at least (1 - rho)^2 C_k; at full sliding it is 0
and v_y is unobservable from (a_y, r), so no certificate over a set holding full sliding exists.

A(s, Theta) is multi-affine in (s, theta_f, theta_r): one quadratic Lyapunov matrix P with
A_v' P A_v < lambda^2 P at the 8 vertices certifies V(e_{k+1}) < lambda^2 V(e_k) for every
sample inside S (LMIs on :mod:`codegen.design.lmi`, re-checked with numpy on the emitted P). Samples
whose estimated slip, delta or v_x lie outside S are flagged (excess > 0, SCHEDULING_CLAMPED):
the certificate does not cover them; the true slip cannot be checked (v_y is not measured).
"""
from __future__ import annotations

import functools
import itertools
import time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
import sympy as sp

from ...certificate.artifact import artifact_head, significant, solver_certificate
from ...representation.bounds import range_bound
from ...design.canonical import decimal_round
from ...errors import CertificateError, ModelDefinitionError, SchedulingBoundsError
from ...design.lmi import LMIProblem, bmat, check_blocks, trace
from ...model import load_parameters, parameter_substitution
from ...project.settings import parse_settings, setting
from ...design.precision import margin_field, precision_field, required_margin
from ...emit.stepgen import CASADI_MODULES


@dataclass(frozen=True)
class NonlinearTyreSettings:
    """``[design]`` of a nonlinear-tyre observer: its gain L (rows v_y, r; columns a_y, r) and the set S."""

    gain_vy_ay: float = setting(0.0, doc="L[v_y, a_y] [s]")
    gain_vy_r: float = setting(0.0, doc="L[v_y, r] [m/rad]")
    gain_r_ay: float = setting(0.0, doc="L[r, a_y] [s/m]")
    gain_r_r: float = setting(0.0, doc="L[r, r] [-]")
    sliding_fraction: float = setting(0.9, gt=0, lt=1, doc="rho: certified |t| <= rho t_sl per axle")
    decay: float = setting(1.0, gt=0, le=1, doc="lambda: V(e+) <= lambda^2 V(e) is certified")
    margin: float = setting(1e-9, gt=0, doc="smallest eigenvalue imposed on every LMI block")
    tol: float = setting(1e-9, gt=0, doc="solver tolerance")
    bounds_rel_tol: float = setting(1e-3, gt=0, doc="tightness of the Jacobian bounds")
    precision: str = precision_field()
    float32_margin: float = margin_field()

    @property
    def gain(self) -> np.ndarray:
        return np.array([[self.gain_vy_ay, self.gain_vy_r], [self.gain_r_ay, self.gain_r_r]])


@dataclass(frozen=True)
class TyreRepresentation:
    """The model's numbers: force-affine dynamics, axle Jacobian bounds, the set S."""

    f: tuple                  # sympy x_dot (w = 0), in (v_y, r, delta, v_x)
    a_y: sp.Expr              # sympy a_y (w = 0)
    G_f: np.ndarray           # (2, 2) d f / d Phi
    G_a: np.ndarray           # (2,)  d a_y / d Phi
    theta: tuple              # ((lo, hi) of v_x dPhi_k/dv_y) per axle
    theta_attained: tuple
    slips: tuple              # sympy t_k in (v_y, r, delta, v_x)
    slip_limits: tuple        # rho t_sl,k
    v_x_box: tuple
    delta_box: tuple
    symbols: tuple            # (v_y, r, delta, v_x)

    @functools.cached_property
    def numpy_functions(self) -> tuple:
        """(f, a_y, slips) as plain-Python callables of ``symbols``, for the numpy reference step
        (built once per representation: lambdify is slow)."""
        mods = [{"Min": min, "Max": max, "Abs": abs}, "math"]
        return ([sp.lambdify(self.symbols, e, mods) for e in self.f], sp.lambdify(self.symbols, self.a_y, mods),
                [sp.lambdify(self.symbols, t, mods) for t in self.slips])


def represent(module, params, settings: NonlinearTyreSettings, source: str) -> TyreRepresentation:
    model = module.MODEL
    if len(model.states) != 2 or len(model.known_inputs) != 1 or len(model.scheduling) != 1 \
            or [n for n, _ in model.outputs] != ["a_y", str(model.states[1])]:
        raise ModelDefinitionError(f"{source}: model {model.name!r}: the nonlinear-tyre observer needs states "
                                   f"(v_y, r), one known input (delta), one scheduling signal (v_x) and outputs "
                                   f"(a_y, r)")
    axles = getattr(module, "AXLES", None)
    if not axles:
        raise ModelDefinitionError(f"{source}: model module of {model.name!r} has no AXLES (how each axle force "
                                   f"depends on v_y; see model_defs/single_track_nonlinear_tyre.py)")
    vy, r = model.states
    delta, vx = model.known_inputs[0], model.scheduling[0].symbol
    subs = parameter_substitution(model, params)
    zero_w = {w: 0 for w in model.unknown_inputs}
    f = tuple(sp.sympify(e).subs(subs).subs(zero_w) for e in model.dynamics)
    a_y = sp.sympify(dict(model.outputs)["a_y"]).subs(subs).subs(zero_w)
    tyre_t = [sp.sympify(a.slip).subs(subs) for a in axles]
    sliding = [float(sp.sympify(a.sliding).subs(subs)) for a in axles]
    if "v_x" not in params.scheduling:
        raise SchedulingBoundsError(f"{params.source}: no [scheduling.v_x] box")
    if "delta" not in params.state_bounds:
        raise SchedulingBoundsError(f"{params.source}: no [state_bounds] delta = [min, max] (the certified set)")
    v_box = (params.scheduling["v_x"].lower, params.scheduling["v_x"].upper)
    d_box = tuple(params.state_bounds["delta"])
    if not v_box[0] > 0:
        raise SchedulingBoundsError(f"{params.source}: [scheduling.v_x] min must be > 0, got {v_box[0]}")
    limits = [settings.sliding_fraction * s for s in sliding]
    if not hasattr(module, "FORCES") or not hasattr(module, "DYNAMICS_IN_FORCES"):
        raise ModelDefinitionError(f"{source}: model module of {model.name!r} needs FORCES, DYNAMICS_IN_FORCES and "
                                   f"A_Y_IN_FORCES (the equations written in the axle forces)")
    Phi = tuple(module.FORCES)
    in_forces = [sp.sympify(e).subs(subs) for e in (*module.DYNAMICS_IN_FORCES, module.A_Y_IN_FORCES)]
    G = sp.Matrix(in_forces).jacobian(sp.Matrix(Phi))
    if any(e.free_symbols for e in G) or any(sp.diff(e, vy) != 0 for e in in_forces):
        raise ModelDefinitionError(f"{source}: the equations in the axle forces must be affine in them with constant "
                                   f"coefficients and free of v_y elsewhere")
    G = np.array(G.tolist(), dtype=float)
    theta, attained = [], []
    for k, a in enumerate(axles):
        # chain rule: v_x dPhi/dv_y = law'(t) projection (v_x dt/dv_y), the last factor in slip coordinates
        t = module.t_sym
        law = sp.sympify(a.law).subs(subs)
        kin = sp.factor(sp.trigsimp(sp.cancel((vx * sp.diff(sp.sympify(a.slip).subs(subs), vy)).subs(
            vy, sp.sympify(a.inverse).subs(subs)))))
        dlaw = sp.expand(sp.diff(law, t).subs(sp.sign(t), sp.Abs(t) / t))   # t sign(t) = |t|
        geo = sp.sympify(a.projection).subs(subs) * kin
        stray = (dlaw.free_symbols - {t}) | (geo.free_symbols - {t, delta})
        if stray:
            raise ModelDefinitionError(f"{source}: axle {a.name}: v_x dPhi/dv_y in slip coordinates still depends on "
                                       f"{sorted(map(str, stray))} (AXLES[{k}].inverse is not v_y(t))")
        # each factor bounded soundly on its own; their product encloses theta (sound, a little wider)
        rl = range_bound(dlaw, {t: (-limits[k], limits[k])}, rel_tol=settings.bounds_rel_tol)
        rg = range_bound(geo, {t: (-limits[k], limits[k]), delta: d_box}, rel_tol=settings.bounds_rel_tol)
        if not (rl.lower > 0 and rg.upper < 0):
            raise CertificateError(f"{source}: axle {a.name}: the tyre slope reaches {rl.lower:.4g} N (or the "
                                   f"kinematic factor {rg.upper:.4g}) on |t| <= {limits[k]:.4g}: v_y is not "
                                   f"observable there; lower sliding_fraction")
        from ...representation.bounds import RangeBound
        rb = RangeBound(rl.upper * rg.lower, rl.lower * rg.upper, rl.attained_max * rg.attained_min,
                        rl.attained_min * rg.attained_max, rl.boxes_examined + rg.boxes_examined)
        rb = RangeBound(min(rb.lower, rb.upper), max(rb.lower, rb.upper), rb.attained_min, rb.attained_max,
                        rb.boxes_examined)
        theta.append((rb.lower, rb.upper))
        attained.append((rb.attained_min, rb.attained_max))
    # the model is the force form with the (clamped) Fiala forces: checked at random points of S
    model_forces = [sp.sympify(e).subs(subs).subs(zero_w) for e in (module.Phi_f, module.Phi_r)]
    rng = np.random.default_rng(0)
    for _ in range(5):
        pt = {vy: rng.uniform(-1, 1), r: rng.uniform(-0.5, 0.5), delta: rng.uniform(*d_box), vx: rng.uniform(*v_box)}
        fp = {P_: float(F.subs(pt)) for P_, F in zip(Phi, model_forces)}
        for e_model, e_force in zip((*f, a_y), in_forces):
            a_, b_ = float(e_model.subs(pt)), float(e_force.subs({**pt, **fp}))
            if not abs(a_ - b_) <= 1e-9 * max(1.0, abs(a_)):
                raise ModelDefinitionError(f"{source}: MODEL is not DYNAMICS_IN_FORCES with the axle forces substituted")
    G_f, G_a = G[:2], G[2]
    return TyreRepresentation(f, a_y, G_f, G_a, tuple(theta), tuple(attained), tuple(tyre_t), tuple(limits),
                              v_box, d_box, (vy, r, delta, vx))


# --- certificate -------------------------------------------------------------------------------------

def vertices(rep: TyreRepresentation, Ts: float, L: np.ndarray) -> list:
    """(label, A_v) of the error map at the 8 vertices of (s, theta_f, theta_r)."""
    out = []
    s_box = (1.0 / rep.v_x_box[1], 1.0 / rep.v_x_box[0])
    for (si, s), *ths in itertools.product(enumerate(s_box), *[list(enumerate(b)) for b in rep.theta]):
        theta = np.array([t for _, t in ths])
        col_f = Ts * (rep.G_f @ theta) * s              # T_s d f/dv_y
        col_a = (rep.G_a @ theta) * s                   # d a_y/dv_y
        J_h = np.array([[col_a, 0.0], [0.0, 1.0]])
        A = np.eye(2) + np.column_stack([col_f, np.zeros(2)]) - L @ J_h
        tag = "".join("lu"[i] for i, _ in ths)
        out.append((f"vertex v_x={'max' if si == 0 else 'min'} theta={tag}", A))
    return out


def _blocks(verts, P, decay, xp):
    cat = np.block if xp is np else bmat
    return [(f"(A'PA < lambda^2 P) {label}", cat([[decay ** 2 * P, (P @ A).T], [P @ A, P]])) for label, A in verts]


def lmi_problem(verts, settings: NonlinearTyreSettings) -> LMIProblem:
    prob = LMIProblem("nonlinear-tyre observer: common quadratic Lyapunov matrix over the DMVT vertices")
    P = prob.symmetric("P", 2)
    prob.require_psd("P >= I", P, margin=1.0)
    for label, blk in _blocks(verts, P, settings.decay, LMIProblem):
        prob.require_psd(label, blk, margin=settings.margin,
                         hint="lower sliding_fraction or change the gain: the tyre slope is too small at a vertex")
    prob.minimize(trace(P))
    return prob


def certify(verts, P: np.ndarray, decay: float, samples_A=None) -> dict:
    checks = check_blocks({"P > 0": P, **dict(_blocks(verts, P, decay, np))})
    worst = min(checks, key=lambda c: c.min_eig)
    if worst.min_eig <= 0:
        raise CertificateError(f"nonlinear-tyre observer: LMI {worst.label!r} fails the numpy re-check on the emitted "
                               f"P: smallest eigenvalue {worst.min_eig:.3e}")
    # the contraction factor: max over the vertices of the generalized eigenvalue of (A'PA, P)
    Li = np.linalg.inv(np.linalg.cholesky(P))
    ratio = max(float(np.linalg.eigvalsh(Li @ A.T @ P @ A @ Li.T).max()) for _, A in verts)
    if ratio >= 1.0:
        raise CertificateError(f"nonlinear-tyre observer: V(e+)/V(e) reaches {ratio:.9f} >= 1 at a vertex")
    return {"blocks": len(checks), "worst_block": worst.label, "worst_min_eig": worst.min_eig,
            "worst_relative_margin": worst.relative_margin, "max_ratio": ratio,
            "contraction_per_step": float(np.sqrt(ratio))}


# --- the step ----------------------------------------------------------------------------------------

def _functions(rep: TyreRepresentation, xp):
    mods = CASADI_MODULES if xp is ca else "numpy"
    args = rep.symbols
    return [sp.lambdify(args, e, mods) for e in rep.f], sp.lambdify(args, rep.a_y, mods), \
        [sp.lambdify(args, t, mods) for t in rep.slips]


def step_parts(rep, L, Ts, z, u, y, rho, fns, xp=np):
    """(x_next, x_now, excess): z = [x_hat_k (prediction from k-1)]; u = [delta], y = [a_y, r], rho = [v_x]."""
    f_fn, ay_fn, t_fn = fns
    fmin, fmax, fabs = (ca.fmin, ca.fmax, ca.fabs) if xp is ca else (min, max, abs)
    vy, rh = z[0], z[1]
    d, a_m, r_m, v = u[0], y[0], y[1], rho[0]
    vc = fmin(fmax(v, rep.v_x_box[0]), rep.v_x_box[1])
    excess = fabs(v - vc) + fmax(0.0, fmax(rep.delta_box[0] - d, d - rep.delta_box[1]))
    for t_k, lim in zip(t_fn, rep.slip_limits):
        excess = excess + fmax(0.0, fabs(t_k(vy, r_m, d, vc)) - lim)
    f = [fn(vy, r_m, d, vc) for fn in f_fn]
    ea = a_m - ay_fn(vy, r_m, d, vc)
    er = r_m - rh
    vy_n = vy + Ts * f[0] + L[0, 0] * ea + L[0, 1] * er
    r_n = rh + Ts * f[1] + L[1, 0] * ea + L[1, 1] * er
    return (vy_n, r_n), excess


def _build_class():
    from ..base import ObserverBuild

    @dataclass(frozen=True)
    class Build(ObserverBuild):
        """A certified nonlinear-tyre observer (see the module docstring)."""

        config: object
        rep: TyreRepresentation
        settings: NonlinearTyreSettings
        P: np.ndarray
        verts: tuple
        certificate: dict
        solution: object
        timings: dict

        @property
        def L(self) -> np.ndarray:
            return self.settings.gain

        @property
        def definition(self):
            return self.config.load_model()

        state_names = property(lambda self: ["v_y_next", "r_next", "v_y", "r"])
        output_names = property(lambda self: ["v_y", "r"])
        input_names = property(lambda self: ["delta", "y_a_y", "y_r", "v_x"])
        nu = property(lambda self: 1)
        ny = property(lambda self: 2)

        def step_function(self):
            z, u, y, rho = ca.SX.sym("z", 4), ca.SX.sym("u", 1), ca.SX.sym("y", 2), ca.SX.sym("rho", 1)
            (vy_n, r_n), excess = step_parts(self.rep, self.L, self.config.sample_time, z, u, y, rho,
                                             _functions(self.rep, ca), xp=ca)
            return ca.Function(f"{self.name}_kernel", [z, u, y, rho], [ca.vertcat(vy_n, r_n, z[0], z[1]), excess],
                               ["z", "u", "y", "rho"], ["z_next", "excess"])

        def reference_step(self, z, u, y, rho):
            z, u, y, rho = (np.asarray(a, float) for a in (z, u, y, rho))
            (vy_n, r_n), excess = step_parts(self.rep, self.L, self.config.sample_time, z, u, y, rho,
                                             self.rep.numpy_functions, xp=np)
            return np.array([vy_n, r_n, z[0], z[1]], dtype=float), float(excess)

        def lmi_problem(self):
            return lmi_problem(self.verts, self.settings)

        def contraction_metrics(self):
            """The common P over the DMVT vertices: the prediction (v_y, r) for the next sample."""
            from ...certificate.contraction import ContractionMetric
            return [ContractionMetric(float(self.certificate["contraction_per_step"]), (self.P,), ("v_y_next", "r_next"),
                                      "common P over the DMVT vertices: A' P A <= c^2 P, on the certified slip set",
                                      knob="[design] decay (lambda imposed by the LMIs), a lower sliding_fraction or another gain")]

        def input_boxes(self):
            return {"v_x": list(self.rep.v_x_box), "delta": list(self.rep.delta_box)}

        def scheduling_boxes(self):
            return [("v_x", *self.rep.v_x_box, False)]

        def signal_docs(self):
            state = [{"name": "v_y_next", "doc": "predicted lateral speed for the next sample [m/s]"},
                     {"name": "r_next", "doc": "predicted yaw rate for the next sample [rad/s]"},
                     {"name": "v_y", "doc": "estimate of v_y at this sample, from the samples before it [m/s]"},
                     {"name": "r", "doc": "estimate of r at this sample, from the samples before it [rad/s]"}]
            inputs = [{"name": "delta", "doc": "road-wheel steering angle [rad]"},
                      {"name": "y_a_y", "doc": "measured lateral acceleration at the CoG [m/s^2]"},
                      {"name": "y_r", "doc": "measured yaw rate [rad/s]"},
                      {"name": "v_x", "doc": "measured longitudinal speed [m/s]"}]
            return state, inputs, state[2:]

        def emit_notes(self):
            c = self.certificate
            return {
                "headline": f"DMVT vertex LMIs worst margin {c['worst_min_eig']:.3g}",
                "stability": (f"common quadratic Lyapunov matrix over the 8 vertices of (1/v_x, theta_f, theta_r): "
                              f"sqrt(V) contracts by {c['contraction_per_step']:.6f} per step on the certified set"),
                "step_notes": [
                    "Each call takes the measurements of sample k and returns the estimate of sample k made",
                    "from the samples before it; the state's head is the prediction for sample k+1.",
                ],
                "clamp_doc": ("v_x or delta outside the certified set (v_x clamped for the model), or an estimated\n"
                              " * axle slip beyond sliding_fraction of its sliding limit: the certificate does not cover this sample."),
                "warmup_doc": "never set.",
                "has_warmup": False,
            }

        def artifact(self):
            rep = self.rep
            return {**artifact_head(self, ["v_x"], flags_from_inputs_only=False),
                    "representation": {"G_f": rep.G_f.tolist(), "G_a": rep.G_a.tolist(),
                                       "theta_bounds": [list(map(significant, b)) for b in rep.theta],
                                       "theta_attained": [list(map(significant, b)) for b in rep.theta_attained],
                                       "slip_limits": [significant(x) for x in rep.slip_limits],
                                       "v_x_box": list(rep.v_x_box), "delta_box": list(rep.delta_box)},
                    "L": self.L.tolist(), "P": self.P.tolist(), "sliding_fraction": self.settings.sliding_fraction,
                    "certificate": solver_certificate(self.solution, recheck=self.certificate)}

        def summary(self, path):
            c = self.certificate
            return {"observer": self.name, "artifact": str(path), "theta_bounds": [list(b) for b in self.rep.theta],
                    "slip_limits": list(self.rep.slip_limits), "L": self.L.tolist(), "P": self.P.tolist(),
                    "lmi_blocks": c["blocks"], "worst_block": c["worst_block"], "worst_min_eig": c["worst_min_eig"],
                    "worst_relative_margin": c["worst_relative_margin"], "contraction_per_step": c["contraction_per_step"],
                    "sliding_fraction": self.settings.sliding_fraction, "sample_time": self.config.sample_time}

        def summary_lines(self, s):
            lines = [f"observer {s['observer']}: nonlinear single-track observer, Fiala tyre per axle, certified on "
                     f"|t| <= {s['sliding_fraction']:g} t_sl per axle"]
            for name, b, lim in zip(("front", "rear"), s["theta_bounds"], s["slip_limits"]):
                lines.append(f"  v_x dPhi_{name}/dv_y in [{b[0]:.6g}, {b[1]:.6g}] N on |tan alpha| <= {lim:.4g} "
                             f"(sound, interval arithmetic)")
            lines += [f"  L = {s['L']}",
                      f"  {s['lmi_blocks']} LMI blocks; worst margin {s['worst_min_eig']:.3e} (relative "
                      f"{s['worst_relative_margin']:.3e}) in {s['worst_block']} (numpy re-check)",
                      f"  sqrt(V) contracts by {s['contraction_per_step']:.6f} per step at the worst vertex",
                      f"artifact: {s['artifact']}"]
            return lines

    return Build


Build = _build_class()


def build(config, tol: float | None = None):
    """model -> force form + sound axle Jacobian bounds on S -> vertex LMIs -> numpy re-check -> step."""
    settings = parse_settings(NonlinearTyreSettings, config.design, source=config.source, section="design",
                              **({"tol": tol} if tol is not None else {}))
    if required_margin(settings):       # precision = "float32": the LMIs impose lambda <= 1 - float32_margin
        settings = replace(settings, decay=min(settings.decay, 1.0 - required_margin(settings)))
    t0 = time.perf_counter()
    rep = represent(config.load_model_module(), load_parameters(config.parameter_path), settings, config.source)
    t1 = time.perf_counter()
    verts = tuple(vertices(rep, config.sample_time, settings.gain))
    sol = lmi_problem(verts, settings).solve(tol=settings.tol)
    P = decimal_round(0.5 * (sol["P"] + sol["P"].T))
    t2 = time.perf_counter()
    cert = certify(verts, P, settings.decay)
    t3 = time.perf_counter()
    return Build(config, rep, settings, P, verts, cert, sol,
                 {"representation_s": t1 - t0, "design_s": t2 - t1, "solve_s": sol.solve_time_s,
                  "certificates_s": t3 - t2})
