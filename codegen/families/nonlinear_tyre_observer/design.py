"""Gains of the nonlinear-tyre observer: LMIs over the DMVT vertices, solved jointly with the Lyapunov matrix.

Error system (``build.py``): with s = 1/v_x, Theta = (theta_f, theta_r) and the disturbances w,

    e_{k+1} = A(s, Theta) e_k + (B_x(s, v, Theta) - L B_y(s, Theta)) w_k,
    A = A_0 - L J,   A_0 = I + T_s [G_f Theta s, 0],   J = [[G_a Theta s, 0], [0, 1]],

w = (unmodelled axle forces dPhi_f, dPhi_r [N]; a_y sensor error n_a [m/s^2]; yaw-rate sensor error
n_r [rad/s]; Euler residuals d_v [m/s^2], d_r [rad/s^2]), each divided by its level sigma (the
observer file's ``sigma_*``). The a_y model residual enters both the dynamics (v_y' = a_y - r v_x
is exact kinematics) and the a_y innovation; yaw-rate noise enters the forces through the slips
(t_f depends on v_y + l_f r, t_r on v_y - l_r r), the term r v_x and the r innovation. Performance
output: z = s e_vy in degrees, which bounds the sideslip error (|atan a - atan b| <= |a - b|).

With the usual change of variables Y = P L (affine in P, Y), written in the delta form
A = I + T_s F, B = T_s G (the same conditions divided by T_s: no P - P cancellation, which at
a decay near 1 leaves the solver a difference of nearly equal numbers):

* decay rate a [1/s] (V(e+) <= (1 - T_s a) V(e), lambda^2 = 1 - T_s a) at the 8 vertices of
  (s, theta_f, theta_r) on the certified set (``sliding_fraction``):
  [[-(PF + F'P) - a P, sqrt(T_s) F'P], [sqrt(T_s) PF, P]] >= 0;
* l2 gain gamma from w to z (bounded-real lemma) at the 16 vertices of (s, v, theta_f, theta_r)
  on the gain set (``gain_sliding_fraction``), v = v_x taken as independent of s (sound):
  [[-(PF + F'P) - C'C/T_s, -PG, sqrt(T_s) F'P], [-G'P, eta I, sqrt(T_s) G'P],
   [sqrt(T_s) PF, sqrt(T_s) PG, P]] >= 0,  gamma^2 = eta T_s.

Design: the largest certifiable decay rate a* of three significant digits (analysis problems), then one
design problem: the decay rate ``decay_fraction`` a* (or the observer file's ``decay``) required, the
gain minimized; L = P^-1 Y. Then, with L fixed, the RMS bound at the noise levels: the same
bounded-real block at the same vertices with its own Lyapunov matrix Q and one multiplier per
channel, eta I -> diag(mu), sum(mu) minimized. Summed over a trajectory in the gain set it gives
sum_k z_k^2 <= T_s sum_i mu_i sum_k (w_i,k / sigma_i)^2 + V_Q(e_0): every channel at its level, the
RMS of z is at most sqrt(T_s sum(mu)), never above gamma sqrt(6) (mu_i = eta is feasible), and each
channel's share sqrt(T_s mu_i) says which disturbance the bound is made of. Given gains instead (the
four ``gain_*`` keys): the same steps with L fixed (P alone is free). A, C'C and the blocks are
multi-affine in (s, theta) except C'C (s^2, concave), so the vertices suffice. States and outputs are scaled by D = S = diag(1, d),
d = sqrt(v_min v_max) [m/s] (r times a speed is a lateral speed, or an acceleration).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ...design import rates
from ...representation.canonical import decimal_round
from ...design.precision import required_margin
from ...errors import CertificateError, SolverError
from ...design.lmi import LMIProblem, bmat, check_blocks, objective_bound, uncertified, worst_block

DEG = 180.0 / np.pi
CHANNELS = ("force_front", "force_rear", "ay", "r", "euler_vy", "euler_r")
"""The disturbance channels, in the order of w (each normalized by its level)."""


def problem_name(given_gains: bool) -> str:
    return ("nonlinear-tyre observer: decay and l2 gain of given gains over the DMVT vertices" if given_gains else
            "nonlinear-tyre observer: gains, decay and l2 gain over the DMVT vertices")


RATE_DIGITS = 3
"""Significant digits of a committed decay rate (rounded down: :func:`codegen.design.rates.round_down`)."""

RATE_RESOLUTION = 2.0 ** -30
"""The smallest committable rate as a fraction of 1/T_s (a 30-step bisection's resolution)."""


def _largest_rate(plant, feasible) -> float:
    """The largest rate of RATE_DIGITS significant digits in (0, 1/T_s] that ``feasible`` holds at (a binary
    search over those numbers, :mod:`codegen.design.rates`: what a bisection of the rate rounds down to, in
    half the solves); 0 when none."""
    candidates = rates.committable_rates(1.0 / plant.Ts, RATE_DIGITS, RATE_RESOLUTION)
    return rates.largest_holding(candidates, feasible, near_top=False) or 0.0


@dataclass(frozen=True)
class Vertex:
    label: str
    s: float                 # 1 / v_x
    v: float                 # v_x (independent of s in the polytope: sound)
    theta: np.ndarray        # (theta_f, theta_r)


def vertices(rep, bounds, with_speed: bool) -> list:
    """Vertices of (s, [v,] theta_f, theta_r) over the slope bounds ``bounds`` (one AxleBounds per axle)."""
    s_box = (1.0 / rep.v_x_box[1], 1.0 / rep.v_x_box[0])
    v_box = rep.v_x_box if with_speed else (None,)
    out = []
    for (si, s), (vi, v), *ths in itertools.product(enumerate(s_box), enumerate(v_box),
                                                    *[list(enumerate(b.theta)) for b in bounds]):
        tag = "".join("lu"[i] for i, _ in ths)
        label = f"v_x={'max' if si == 0 else 'min'}" + (f" v={'min' if vi == 0 else 'max'}" if with_speed else "") \
            + f" theta={tag}"
        out.append(Vertex(label, s, v if with_speed else 1.0 / s, np.array([t for _, t in ths])))
    return out


@dataclass(frozen=True)
class Plant:
    """The constant matrices of the error system and the scaling."""

    Ts: float
    G_f: np.ndarray
    G_a: np.ndarray
    lever: np.ndarray        # slip t_k depends on v_y + lever_k r
    sigma: np.ndarray        # levels of the channels (CHANNELS order)
    D: np.ndarray            # state and output scaling diag(1, d)

    def matrices(self, x: Vertex):
        """(A_0, J, B_x, B_y, C) at a vertex, in physical units (C: degrees of beta per m/s of v_y)."""
        Ts, s, th = self.Ts, x.s, x.theta
        A0 = np.eye(2) + np.column_stack([Ts * self.G_f @ th * s, np.zeros(2)])
        J = np.array([[self.G_a @ th * s, 0.0], [0.0, 1.0]])
        sf = self.sigma
        dr = -self.lever * th * s                          # dPhi/d n_r = -theta_k s lever_k
        Bx = np.column_stack([Ts * self.G_f[:, 0] * sf[0], Ts * self.G_f[:, 1] * sf[1], np.zeros(2),
                              (Ts * self.G_f @ dr + np.array([Ts * x.v, 0.0])) * sf[3],
                              np.array([Ts * sf[4], 0.0]), np.array([0.0, Ts * sf[5]])])
        By = np.array([[self.G_a[0] * sf[0], self.G_a[1] * sf[1], sf[2], self.G_a @ dr * sf[3], 0.0, 0.0],
                       [0.0, 0.0, 0.0, sf[3], 0.0, 0.0]])
        C = np.array([[s * DEG, 0.0]])
        return A0, J, Bx, By, C

    def delta_form(self, x: Vertex, P, Y):
        """PF, PG, C~ in the scaled coordinates (P, Y: Affine or numpy; Y = P D L S^-1)."""
        A0, J, Bx, By, C = self.matrices(x)
        D, Di = self.D, np.linalg.inv(self.D)
        F0 = (D @ A0 @ Di - np.eye(2)) / self.Ts
        PF = P @ F0 - Y @ (D @ J @ Di / self.Ts)
        PG = (P @ (D @ Bx) - Y @ (D @ By)) * (1.0 / self.Ts)
        return PF, PG, C @ Di


LEVEL_PROBLEM = "nonlinear-tyre observer: RMS bound at the noise levels (per-channel multipliers, gains fixed)"


def decay_block(plant, x, P, Y, rate, xp=np):
    PF = plant.delta_form(x, P, Y)[0]
    cat = np.block if xp is np else bmat
    r = np.sqrt(plant.Ts)
    return cat([[-(PF + PF.T) - rate * P, r * PF.T], [r * PF, P]])


def gain_block(plant, x, P, Y, eta, xp=np):
    """The bounded-real block at a vertex; ``eta``: a scalar (gamma^2 = eta T_s, every channel alike)
    or an (n_w, n_w) matrix of per-channel multipliers diag(mu)."""
    PF, PG, C = plant.delta_form(x, P, Y)
    nw = PG.shape[1]
    W = eta * np.eye(nw) if getattr(eta, "shape", ()) in ((), (1, 1)) else eta
    r = np.sqrt(plant.Ts)
    cat = np.block if xp is np else bmat
    return cat([[-(PF + PF.T) - C.T @ C / plant.Ts, -PG, r * PF.T], [-PG.T, W, r * PG.T], [r * PF, r * PG, P]])


def fallback_vertices(decay_verts) -> list:
    """Vertices (s, theta_f, theta_r) of the kinematic fallback's error step: s over the speed box, each
    axle's theta from its full slope (the end of the certified set's box farthest from 0, reached at zero
    slip) to 0 (sliding): the true slip is anywhere when the estimated one is beyond the set."""
    theta = np.array([x.theta for x in decay_verts])
    full = [theta[np.argmax(np.abs(theta[:, k])), k] for k in range(theta.shape[1])]
    out = []
    for s in sorted({x.s for x in decay_verts}):
        for th in itertools.product(*[(f, 0.0) for f in full]):
            out.append(Vertex(f"fallback s={s:.6g} theta=({th[0]:.6g}, {th[1]:.6g})", s, 1.0 / s, np.array(th)))
    return out


def fallback_block(plant, x, P, growth, xp=np):
    """V(e+) <= (1 + Ts growth) V(e) for the fallback's error step at vertex ``x`` (Schur form, P scaled):
    e_vy+ = e_vy (the exact kinematics with the measured a_y), e_r+ = Ts df_r/dv_y e_vy (r_hat reset to the
    measured r plus one Euler step of the model); the gains do not enter."""
    A = np.array([[1.0, 0.0], [plant.Ts * (plant.G_f @ x.theta)[1] * x.s, 0.0]])
    Ah = plant.D @ A @ np.linalg.inv(plant.D)
    cat = np.block if xp is np else bmat
    return cat([[(1.0 + plant.Ts * growth) * P, Ah.T @ P], [P @ Ah, P]])


def _fallback_blocks(prob, plant, P, decay_verts, settings) -> None:
    if settings.fallback_growth is None:
        return
    for x in fallback_vertices(decay_verts):
        prob.require_psd(x.label, fallback_block(plant, x, P, settings.fallback_growth, LMIProblem),
                         margin=settings.margin, hint="raise fallback_growth")


def _decay_feasible(plant, verts, rate, L_scaled, settings) -> bool:
    prob = LMIProblem("nonlinear-tyre observer: decay rate (analysis)", design=False)
    P = prob.symmetric("P", 2)
    Y = prob.matrix("Y", 2, 2) if L_scaled is None else P @ L_scaled
    prob.require_psd("P >= I", P, margin=1.0)
    for x in verts:
        prob.require_psd(f"decay {x.label}", decay_block(plant, x, P, Y, rate, LMIProblem), margin=settings.margin)
    _fallback_blocks(prob, plant, P, verts, settings)
    try:
        prob.solve(tol=settings.tol, unique=False)
    except (SolverError, CertificateError):
        return False
    return True


def best_decay_rate(plant, verts, settings, L_scaled=None) -> float:
    """The largest decay rate a [1/s] a common Lyapunov matrix certifies at ``verts``, rounded down to
    three significant digits (:func:`_largest_rate`); 0 when none is certified."""
    if not _decay_feasible(plant, verts, 0.0, L_scaled, settings):
        return 0.0
    return _largest_rate(plant, lambda a: _decay_feasible(plant, verts, a, L_scaled, settings))


def lmi_problem(plant, decay_verts, gain_verts, settings, rate, best_rate, L_scaled=None) -> LMIProblem:
    """The design problem: decay ``rate`` at ``decay_verts``, the l2 gain minimized at ``gain_verts``."""
    growth = settings.fallback_growth
    prob = LMIProblem(problem_name(L_scaled is not None), data={"best_decay_rate": best_rate, "decay_rate": rate}
                      | ({} if growth is None else {"fallback_growth": growth}))
    P = prob.symmetric("P", 2)
    Y = prob.matrix("Y", 2, 2) if L_scaled is None else P @ L_scaled
    prob.require_psd("P >= I", P, margin=1.0)
    hint = "lower sliding_fraction or decay_fraction: the tyre slope is too small at a vertex"
    for x in decay_verts:
        prob.require_psd(f"decay {x.label}", decay_block(plant, x, P, Y, rate, LMIProblem), margin=settings.margin,
                         hint=hint)
    _fallback_blocks(prob, plant, P, decay_verts, settings)
    if getattr(settings, "objective", "gamma") == "noise_bound" and L_scaled is None:
        # one multiplier per channel, their sum minimized: the RMS bound at the levels (level_bound_problem)
        # with the gains free. eta = max(mu) then certifies the uniform gain with the same P (the block
        # grows with its multiplier block).
        W, total = _multipliers(prob)
        for x in gain_verts:
            prob.require_psd(f"l2 gain {x.label}", gain_block(plant, x, P, Y, W, LMIProblem), margin=settings.margin,
                             hint="lower gain_sliding_fraction")
        prob.minimize(total)
        return prob
    eta = prob.scalar("eta")
    for x in gain_verts:
        prob.require_psd(f"l2 gain {x.label}", gain_block(plant, x, P, Y, eta, LMIProblem), margin=settings.margin,
                         hint="lower gain_sliding_fraction")
    prob.minimize(eta)
    return prob


def _multipliers(prob):
    """(diag(mu_i), sum mu_i) over the CHANNELS, the mu_i scalars of ``prob``."""
    nw = len(CHANNELS)
    M, total = None, None
    for i, c in enumerate(CHANNELS):
        m = prob.scalar(f"mu_{c}")
        E = np.zeros((nw, nw))
        E[i, i] = 1.0
        M = m * E if M is None else M + m * E
        total = m if total is None else total + m
    return M, total


@dataclass(frozen=True)
class Design:
    """The designed (or given) gains with their certificate's constants."""

    L: np.ndarray            # (2, 2): rows v_y, r; columns a_y, r (physical units)
    P: np.ndarray            # Lyapunov matrix in the scaled coordinates
    eta: float
    best_rate: float         # a* [1/s]
    rate: float              # a [1/s] required
    given: bool
    solution: object


def synthesize(plant, decay_verts, gain_verts, settings, solver) -> Design:
    """Bisection for a*, then the design problem (see the module docstring), answered by ``solver``
    (:mod:`codegen.design.solver`); a replay's committed constants stand in for the search."""
    given = settings.given_gains
    D = plant.D
    L_scaled = None if not given else D @ settings.gain @ np.linalg.inv(D)
    committed = solver.committed_data(problem_name(given))
    if committed is not None:
        best, rate = float(committed["best_decay_rate"]), float(committed["decay_rate"])
    else:
        best = best_decay_rate(plant, decay_verts, settings, L_scaled)
        if best <= 0:
            raise CertificateError(
                "nonlinear-tyre observer: no common Lyapunov matrix makes the error contract at the "
                + ("given gains" if given else "designed gains") + " over the certified set's vertices; lower "
                "sliding_fraction (the tyre slope near sliding leaves v_y unobservable)")
        if settings.decay is not None:
            rate = rates.round_down((1.0 - settings.decay ** 2) / plant.Ts, 6)
            if rate > best:
                raise CertificateError(f"nonlinear-tyre observer: decay = {settings.decay:g} per step needs the rate "
                                       f"{rate:.4g} 1/s; the largest a common Lyapunov matrix certifies on the set is "
                                       f"{best:.4g} 1/s (decay {np.sqrt(1 - plant.Ts * best):.6f})")
        else:
            rate = rates.round_down(settings.decay_fraction * best, RATE_DIGITS)
        # [design] precision = "float32": sqrt(1 - Ts rate) <= 1 - float32_margin
        m = required_margin(settings)
        need = (1.0 - (1.0 - m) ** 2) / plant.Ts if m else 0.0
        if need > best:
            raise CertificateError(f"nonlinear-tyre observer: [design] precision = \"float32\" needs the decay rate "
                                   f"{need:.4g} 1/s (contraction margin {m:g} per step); the largest a common Lyapunov "
                                   f"matrix certifies on the set is {best:.4g} 1/s (margin "
                                   f"{1 - np.sqrt(1 - plant.Ts * best):.4g}): lower sliding_fraction, or a smaller "
                                   f"[design] float32_margin")
        rate = max(rate, need)
    sol = solver.solve(lmi_problem(plant, decay_verts, gain_verts, settings, rate, best, L_scaled), tol=settings.tol)
    P = decimal_round(0.5 * (sol["P"] + sol["P"].T))
    if given:
        L = settings.gain
    else:
        L = decimal_round(np.linalg.inv(D) @ np.linalg.solve(P, sol["Y"]) @ D)
    # the certified gain: the solver's eta rounded up to three significant digits (re-checked in certify);
    # a noise-bound design certifies eta = its largest multiplier
    eta = objective_bound(float(sol["eta"]) if "eta" in sol.values else max(float(sol[f"mu_{c}"]) for c in CHANNELS))
    return Design(L, P, eta, best, rate, given, sol)


SLIDING_GROWTH = 1e-3
"""epsilon [1/s] by default: V may grow this fast where both axles slide (``[design] sliding_growth``): small
beside any decay the gains certify, and above what the LMI margin on every block resolves."""

THROUGH_PROBLEM = "nonlinear-tyre observer: decay through sliding (rate proportional to the axle slopes, gains fixed)"


def through_vertices(rep) -> list:
    """(Vertex, phi) at the vertices of (s, theta_f, theta_r) over the through-sliding bounds (every slip:
    0 is inside each axle's box). phi = the mean over the axles of theta_k / theta_k,full, theta_k,full the
    box end farthest from 0 (the full slope): 1 with both axles at full slope, 0 with both sliding. The rate
    claimed at a vertex is a phi - epsilon (1 - phi), affine in theta; the blocks are then multi-affine in
    (s, theta) and their vertices cover the box."""
    full = [b.theta[0] if abs(b.theta[0]) >= abs(b.theta[1]) else b.theta[1] for b in rep.through_set]
    out = []
    for x in vertices(rep, rep.through_set, with_speed=False):
        out.append((x, float(np.mean([th / f for th, f in zip(x.theta, full)]))))
    return out


def through_rate(phi: float, rate: float, growth: float) -> float:
    """The decay rate [1/s] claimed where the axle slopes make phi: ``rate`` at full slope, ``-growth`` at
    full sliding of both axles (V may grow there: v_y is not observable from (a_y, r))."""
    return rate * phi - growth * (1.0 - phi)


def _through_problem(plant, verts, rate, growth, L_scaled, settings, design: bool) -> LMIProblem:
    prob = LMIProblem(THROUGH_PROBLEM if design else THROUGH_PROBLEM + " (analysis)", design=design,
                      data={"through_rate": rate, "growth": growth} if design else {})
    P = prob.symmetric("P_through", 2)
    prob.require_psd("P_through >= I", P, margin=1.0)
    for x, phi in verts:
        prob.require_psd(f"through {x.label}", decay_block(plant, x, P, P @ L_scaled, through_rate(phi, rate, growth),
                                                           LMIProblem),
                         margin=settings.margin, hint="set through_sliding = false, or raise sliding_growth")
    return prob


@dataclass(frozen=True)
class Through:
    """The decay of the emitted gains at every slip: one Lyapunov matrix, the rate at full slope, the growth at
    full sliding (``through_sliding``)."""

    P: np.ndarray            # scaled coordinates (rounded)
    rate: float              # a [1/s] at full slope on both axles
    growth: float            # epsilon [1/s] allowed where both axles slide
    solution: object


def through_sliding(plant, verts, settings, design: Design, solver) -> Through:
    """The largest rate a at full slope for which one P gives V(e+) <= (1 - T_s (a phi - epsilon (1 - phi))) V(e)
    at every vertex of the through-sliding bounds, the emitted gains fixed (three significant digits:
    :func:`_largest_rate`); the problem at that rate answered by ``solver`` (recorded in the design lock). A
    CertificateError when not even a = 0 (V growing at most at epsilon everywhere) is certified."""
    L_scaled = plant.D @ design.L @ np.linalg.inv(plant.D)
    growth = SLIDING_GROWTH if settings.sliding_growth is None else settings.sliding_growth
    committed = solver.committed_data(THROUGH_PROBLEM)
    if committed is not None:
        rate, growth = float(committed["through_rate"]), float(committed["growth"])
    else:
        def feasible(a):
            try:
                _through_problem(plant, verts, a, growth, L_scaled, settings, design=False).solve(
                    tol=settings.tol, unique=False)
            except (SolverError, CertificateError):
                return False
            return True
        if not feasible(0.0):
            raise CertificateError(
                f"nonlinear-tyre observer: through_sliding: no Lyapunov matrix keeps V from growing faster than "
                f"sliding_growth = {growth:g} 1/s at every slip with the {'given' if design.given else 'designed'} "
                f"gains (at full sliding of both axles v_y is unobservable, and the gains' r correction must not "
                f"drive it); raise sliding_growth, or set through_sliding = false (the kinematic fallback beyond "
                f"sliding_fraction, not certified there)")
        rate = _largest_rate(plant, feasible)
    sol = solver.solve(_through_problem(plant, verts, rate, growth, L_scaled, settings, design=True),
                       tol=settings.tol)
    return Through(decimal_round(0.5 * (sol["P_through"] + sol["P_through"].T)), rate, growth, sol)


def level_bound_problem(plant, gain_verts, settings, L_scaled) -> LMIProblem:
    """min sum(mu) over Q and the per-channel multipliers at ``gain_verts``, the (scaled) gains fixed."""
    prob = LMIProblem(LEVEL_PROBLEM)
    Q = prob.symmetric("Q", 2)
    M, total = _multipliers(prob)
    prob.require_psd("Q > 0", Q, margin=settings.margin)
    for x in gain_verts:
        prob.require_psd(f"level bound {x.label}", gain_block(plant, x, Q, Q @ L_scaled, M, LMIProblem),
                         margin=settings.margin, hint="lower gain_sliding_fraction")
    prob.minimize(total)
    return prob


@dataclass(frozen=True)
class LevelBound:
    """The RMS bound at the noise levels of the emitted gains (see the module docstring)."""

    Q: np.ndarray            # its Lyapunov matrix, scaled coordinates (rounded)
    mu: np.ndarray           # per-channel multipliers (CHANNELS order), each rounded up
    solution: object


def level_bound(plant, gain_verts, settings, design: Design, solver) -> LevelBound:
    """The per-channel multipliers of the emitted L (answered by ``solver``, recorded in the design lock)."""
    L_scaled = plant.D @ design.L @ np.linalg.inv(plant.D)
    sol = solver.solve(level_bound_problem(plant, gain_verts, settings, L_scaled), tol=settings.tol)
    Q = decimal_round(0.5 * (sol["Q"] + sol["Q"].T))
    mu = np.array([objective_bound(float(sol[f"mu_{c}"])) for c in CHANNELS])
    return LevelBound(Q, mu, sol)


def certify(plant, decay_verts, gain_verts, design: Design, level: LevelBound, through: Through | None = None,
            through_verts=(), fallback_growth: float | None = None) -> dict:
    """Independent numpy re-check of every block on the emitted (rounded) P, L, Q and multipliers (and the
    through-sliding P); the contraction per step at the decay vertices, the certified gain and the bound at
    the levels."""
    D = plant.D
    Y = design.P @ (D @ design.L @ np.linalg.inv(D))
    # the certificate needs P > 0; P >= I only normalizes the solve, and an optimum may rest on it
    blocks = {"P > 0": design.P}
    blocks.update({f"decay {x.label}": decay_block(plant, x, design.P, Y, design.rate) for x in decay_verts})
    blocks.update({f"l2 gain {x.label}": gain_block(plant, x, design.P, Y, design.eta) for x in gain_verts})
    if fallback_growth is not None:
        blocks.update({x.label: fallback_block(plant, x, design.P, fallback_growth) for x in fallback_vertices(decay_verts)})
    blocks["Q > 0"] = level.Q
    YQ = level.Q @ (D @ design.L @ np.linalg.inv(D))
    blocks.update({f"level bound {x.label}": gain_block(plant, x, level.Q, YQ, np.diag(level.mu)) for x in gain_verts})
    if through is not None:
        blocks["P_through > 0"] = through.P
        Yt = through.P @ (D @ design.L @ np.linalg.inv(D))
        blocks.update({f"through {x.label}": decay_block(plant, x, through.P, Yt,
                                                         through_rate(phi, through.rate, through.growth))
                       for x, phi in through_verts})
    checks = check_blocks(blocks)
    worst = worst_block(checks)
    failed = uncertified(checks)
    if failed is not None:
        raise CertificateError(f"nonlinear-tyre observer: LMI {failed.label!r} fails the numpy re-check on the emitted "
                               f"P and L: {failed.failure()}")
    # contraction: the largest generalized eigenvalue of (A'PA, P) over the decay vertices (physical P)
    P_phys = D.T @ design.P @ D
    Li = np.linalg.inv(np.linalg.cholesky(P_phys))
    ratio, slowest = 0.0, None
    for x in decay_verts:
        A0, J, *_ = plant.matrices(x)
        A = A0 - design.L @ J
        q = float(np.linalg.eigvalsh(Li @ A.T @ P_phys @ A @ Li.T).max())
        if q > ratio:
            ratio, slowest = q, x.label
    if ratio >= 1.0:
        raise CertificateError(f"nonlinear-tyre observer: V(e+)/V(e) reaches {ratio:.9f} >= 1 at {slowest}")
    gamma = float(np.sqrt(design.eta * plant.Ts))
    extra = {} if through is None else {"through_rate": through.rate, "sliding_growth": through.growth,
                                        "through_time_constant_s": 2.0 / through.rate if through.rate > 0 else None}
    if fallback_growth is not None:
        extra["fallback_growth"] = fallback_growth
    return {**extra, "blocks": len(checks), "worst_block": worst.label, "worst_min_eig": worst.min_eig,
            "worst_relative_margin": worst.relative_margin, "max_ratio": ratio,
            "contraction_per_step": float(np.sqrt(ratio)), "slowest_vertex": slowest,
            "time_constant_s": float(-plant.Ts / np.log(np.sqrt(ratio))),
            "decay_rate": design.rate, "best_decay_rate": design.best_rate,
            "gamma_deg": gamma, "bound_deg_at_levels": float(np.sqrt(plant.Ts * level.mu.sum())),
            "bound_deg_by_channel": {c: float(np.sqrt(plant.Ts * m)) for c, m in zip(CHANNELS, level.mu)}}
