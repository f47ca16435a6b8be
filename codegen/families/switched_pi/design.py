"""Continuous-time switched H-infinity PI observer, Menhour et al. 2014 (Theorems 1-2, Algorithm 1).

Observer (5), mode i active (alpha_i = 1)::

    z'     = Pi_i z + K_pi y + T_i F_i w_hat + T_i B_i u
    w_hat' = K_Ii (y - C_i x_hat),      x_hat = z + N_i y

Design (Algorithm 1): the assumptions A1 (rank F_i = n_w, rank C_i = m) and A2 (detectability,
checked as the Hautus test of (A_ai, C_ai), Remark 2) with a :class:`RankConditionError` naming
the mode and the failing condition; [T_i N_i] = [I; C_i]^+ (eq. (6)); the LMIs (20) with one
common P for every mode, minimizing gamma; K_ai = [K_i; K_Ii] = -P^-1 Gamma_ai; Pi_i = T_i A_i -
K_i C_i and K_pi = K_i + Pi_i N_i.

Choices the paper leaves open (all documented in the README):

* Well-posedness. (20) alone is not bounded below away from 0: gamma falls without end as the
  gains grow (the error poles run off to -infinity). We add, with the same common P, the
  D-stability region LMI of a disk of radius ``pole_radius`` centred at the origin
  (Chilali & Gahinet, IEEE TAC 41(3), 1996):  [[-r P, (P A_cl)^T], [P A_cl, -r P]] < 0, which
  is affine in (P, Gamma) since P A_cl = P A_a + Gamma C_a. It keeps every mode's error poles
  inside |s| < r. Minimizing gamma^2 (a decision variable) then has a finite optimum.
* Unknown-input convergence. Minimizing gamma alone leaves the integral (unknown-input) pole at
  the origin's doorstep: the proportional part already attenuates omega in beta, so the optimum
  does not need w_hat to move (for the paper's speed rule: |K_I| <= 0.022 and a pole at -1.8e-4 rad/s,
  a bank estimate that never converges, against S1). The region Re s < -``decay_rate``, P A_cl + (P A_cl)^T +
  2 a P < 0 with the same P, makes every error mode, w_hat's included, decay at least as
  exp(-a t) under any switching.
* Strictness. Every block is imposed <= -margin I so the numpy re-check of the rounded matrices
  has slack; P >= margin I.
* Unknown-input units. Theorem 2 is invariant under omega -> k omega (gamma -> gamma / k), the
  solver and the margins are not: a force in N (entries of F ~ 1e-3) puts gamma^2 near 1e-11,
  under the margins, and Clarabel stops (NumericalError, InsufficientProgress) where the same
  model in kN certifies. A problem the solver cannot answer in the model's units is solved for
  omega_s = omega / k, k a power of two per unknown input that puts the solver's gamma near 1
  (:func:`solver_scale`, committed in the design lock; k = 1 for a problem that solves unscaled);
  P, Gamma_ai, gamma and the gains are reported in the model's units, exactly (a power of two
  rounds nothing), and the re-check checks the solved blocks (:func:`certify`).
* Discrete step. Each mode's observer, a linear system in q = [z; w_hat] driven by [u; y], is
  discretized exactly under a zero-order hold at T_s (matrix exponential). Its homogeneous part
  exp((A_ai - K_ai C_ai) T_s) is the sampled error dynamics, so the common P that proves the
  continuous switched error system stable also gives exp(.)^T P exp(.) < P for every mode: the
  sampled error contracts in the P-norm whatever the switching sequence. Both are re-checked
  with numpy (:func:`certify_discrete`).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...errors import CertificateError, ConfigurationError, DiscretizationError, RankConditionError, SolverError
from ...design.lmi import LMIProblem, LMISolution, bmat, check_blocks, uncertified, worst_block
from ...settings import setting
from ...design.precision import margin_field, precision_field
from .representation import SwitchedModel
from ...representation import canonical
from ...representation.canonical import decimal_round


@dataclass(frozen=True)
class SwitchedPIDesignSettings:
    """Tuning of a Menhour et al. 2014 design.

    Attributes
    ----------
    pole_radius : float
        r [rad/s]: every mode's error poles lie in the disk |s| < r (implementability at T_s).
    decay_rate : float
        a [1/s]: V = e^T P e decays at least as exp(-2 a t) in every mode (poles in Re s < -a).
    margin : float
        Every LMI block <= -margin I (and P >= margin I).
    tol : float
        Clarabel gap/feasibility tolerance.
    """

    pole_radius: float = setting(100.0, gt=0, doc="r [rad/s]: error poles in |s| < r")
    decay_rate: float = setting(1.0, ge=0, doc="a [1/s], below pole_radius")
    margin: float = setting(1e-6, ge=0)
    tol: float = setting(1e-9, gt=0)
    precision: str = precision_field()
    float32_margin: float = margin_field()

    def __post_init__(self):
        if not (self.pole_radius > 0 and np.isfinite(self.pole_radius)):
            raise ConfigurationError(f"pole_radius must be positive and finite, got {self.pole_radius}")
        if not (0 <= self.decay_rate < self.pole_radius):
            raise ConfigurationError(f"decay_rate must be in [0, pole_radius), got {self.decay_rate}")
        if not self.margin >= 0 or not self.tol > 0:
            raise ConfigurationError("margin must be >= 0 and tol > 0")


def decoupling_matrices(C: np.ndarray) -> tuple:
    """(T, N) with [T N] = [I; C]^+ (Algorithm 1 step 1); T + N C = I exactly up to round-off."""
    n = C.shape[1]
    TN = canonical.pinv(np.vstack([np.eye(n), C]))     # emitted: machine-independent (codegen.representation.canonical)
    T, N = TN[:, :n], TN[:, n:]
    residual = np.abs(T + N @ C - np.eye(n)).max()
    if residual > 1e-12:
        raise RankConditionError(f"(6) residual {residual:.3g}: T + N C != I")
    return T, N


def augmented(sm: SwitchedModel, i: int, T: np.ndarray) -> tuple:
    """(A_ai, C_ai, F_ai, L_ai) of (19) for mode i."""
    n, nw, m = sm.n, sm.nw, sm.m
    A, F, C = sm.A[i], sm.F[i], sm.C[i]
    Aa = np.block([[T @ A, T @ F], [np.zeros((nw, n)), np.zeros((nw, nw))]])
    Ca = np.hstack([C, np.zeros((m, nw))])
    Fa = np.vstack([-T @ F, np.zeros((nw, nw))])
    La = np.hstack([-sm.L, np.zeros((sm.L.shape[0], nw))])
    return Aa, Ca, Fa, La


def check_assumptions(sm: SwitchedModel, T: np.ndarray, tol: float = 1e-9) -> dict:
    """A1 and A2 (via Remark 2: detectability of (A_ai, C_ai)) for every mode.

    Returns the ranks found; raises :class:`RankConditionError` naming the mode and condition.
    """
    n, nw, m = sm.n, sm.nw, sm.m
    report = []
    for i in range(sm.n_modes):
        F, C, A = sm.F[i], sm.C[i], sm.A[i]
        rF, rC = np.linalg.matrix_rank(F, tol=tol), np.linalg.matrix_rank(C, tol=tol)
        if rF != nw:
            raise RankConditionError(f"mode {i + 1}: assumption A1 fails, rank F_i = {rF} != n_w = {nw} "
                                     f"(the unknown inputs are not linearly independent)")
        if rC != m:
            raise RankConditionError(f"mode {i + 1}: assumption A1 fails, rank C_i = {rC} != m = {m} "
                                     f"(the measurements are not linearly independent)")
        # A2 at every eigenvalue p of the augmented system with Re p >= 0 (elsewhere the rank is full)
        Aa, Ca, _, _ = augmented(sm, i, T)
        worst = None
        for p in np.linalg.eigvals(np.block([[A, F], [np.zeros((nw, n + nw))]])):
            if p.real < -1e-12:
                continue
            mat = np.block([[p * np.eye(n) - A, -F], [np.zeros((nw, n)), p * np.eye(nw)],
                            [C, np.zeros((m, nw))]])
            r = np.linalg.matrix_rank(mat, tol=tol * max(1.0, np.abs(mat).max()))
            if r < n + rF:
                raise RankConditionError(
                    f"mode {i + 1}: assumption A2 fails at p = {p:.4g}: rank = {r} < n + rank F = {n + rF}; "
                    f"the state and the unknown input are not detectable from the outputs")
            pbh = np.vstack([p * np.eye(n + nw) - Aa, Ca])
            r2 = np.linalg.matrix_rank(pbh, tol=tol * max(1.0, np.abs(pbh).max()))
            if r2 < n + nw:
                raise RankConditionError(f"mode {i + 1}: (A_ai, C_ai) is not detectable at p = {p:.4g} "
                                         f"(Remark 2)")
            worst = r if worst is None else min(worst, r)
        report.append({"mode": i + 1, "rank_F": int(rF), "rank_C": int(rC),
                       "A2_min_rank_at_unstable_p": None if worst is None else int(worst)})
    return {"modes": report}


def unit_power(c: float) -> float:
    """The power of two p that brings c > 0 into (1/2, 1] (c p; 1 for c already there)."""
    if not (c > 0 and np.isfinite(c)):
        return 1.0
    mant, e = np.frexp(c)                     # c = mant 2^e, mant in [1/2, 1)
    return float(np.ldexp(1.0, -(int(e) - 1 if mant == 0.5 else int(e))))


def ui_scale(sm: SwitchedModel) -> np.ndarray:
    """Column equilibration of F, the start of :func:`solver_scale`: per unknown input the power
    of two that brings the largest |entry| of its column of F (over the modes) into (1/2, 1]."""
    return np.array([unit_power(c) for c in np.abs(sm.F).max(axis=(0, 1))])


def solver_scale(sm: SwitchedModel, T: np.ndarray, settings: "SwitchedPIDesignSettings", solver) -> np.ndarray:
    """k_j per unknown input: the LMIs are solved for omega_s = omega / k (F_s = F diag(k)), so that
    the solver's gamma_s = gamma min k lies near 1.

    Theorem 2 is invariant under omega -> k omega with gamma -> gamma / k; the solver and the
    strictness margins are not: the (20) block holds -gamma^2 I beside the -I of the performance
    output, both imposed <= -margin I, so a gamma^2 near or under the margin (1e-6) is set by the
    margin, and far under it the solve fails. Measured on a car with a trailer force: in N (F ~
    1e-3, gamma ~ 2e-6 rad/N) Clarabel stops with NumericalError; in kN it certifies 0.00238 rad/kN,
    10 % above the 0.00216 it certifies with gamma_s near 1. Equilibrating F alone does not suffice:
    the same model scaled to F ~ 1 has gamma_s = 0.0015, under the margin's floor (0.0060 rad/kN).
    So: when the problem solves in the model's units, k = 1 (the built-ins, and random models whose
    tiny gamma the margin sets: scaling those broke more than it mended). Otherwise k_0 equilibrates
    F (:func:`ui_scale`: the first solve is posed in unit-size data), then up
    to two analysis solves multiply k by :func:`unit_power` of the gamma_s they find (the first may
    be inflated by the margin's floor, the second is measured clear of it), which puts gamma_s in (1/2, 1].
    Powers of two: the model-unit matrices are the solved ones times powers of two, exactly.
    Committed with the design (design lock, the problem's ``ui_scale``, left out when every k is 1)
    and read back on replay (``solver.committed_data``): a committed solution without it (a lock or
    gains file from before the scale) was solved at k = 1."""
    name = problem_name(sm)
    data = solver.committed_data(name)
    if data is not None and "ui_scale" not in data:
        return np.ones(sm.nw)
    if data is not None:
        k = np.asarray(data["ui_scale"], dtype=float).ravel()
        if k.size != sm.nw or not np.all(np.isfinite(k)) or np.any(k <= 0) or np.any(np.frexp(k)[0] != 0.5):
            from ...errors import DesignLockError
            raise DesignLockError(f"{name}: committed ui_scale {data['ui_scale']!r} is not {sm.nw} power(s) of two; "
                                  f"re-solve with `uiogen design NAME --update`")
        return k
    # the model's own units first: a problem that solves there keeps them (its gamma is a valid
    # bound, set by the margin when tiny); rescaling one that solves gains little and, measured on
    # random models (gamma ~ 1e-3, k up to 2^23), turned solvable problems into NumericalError or
    # PrimalInfeasible ones. The scale is for a problem the solver cannot answer in the model's units.
    try:
        build_problem(sm, T, settings, np.ones(sm.nw), design=False).solve(tol=settings.tol, unique=False, refine=True)
        return np.ones(sm.nw)
    except SolverError:
        pass
    k = ui_scale(sm)
    for _ in range(2):
        try:
            prob = build_problem(sm, T, settings, k, design=False)
            gamma_s = float(np.sqrt(prob.solve(tol=settings.tol, unique=False, refine=True)["gamma2"]))  # the optimum
        except SolverError:
            return k            # the design's own solve reports what fails
        p = unit_power(gamma_s)
        if p == 1.0:
            break
        k = k * p
    return k


def scaled_model(sm: SwitchedModel, k) -> SwitchedModel:
    """``sm`` in the solver's unknown-input units omega_s = omega / k: F_s = F diag(k) (exact)."""
    from dataclasses import replace
    return replace(sm, F=sm.F * np.asarray(k, float)[None, None, :])


def _state_scale(sm: SwitchedModel, k) -> np.ndarray:
    """Diagonal of S, [x; omega] = S [x; omega_s]: the augmented state in model units from the solver's."""
    return np.concatenate([np.ones(sm.n), np.asarray(k, float)])


def _blocks(sm: SwitchedModel, T, P, G, gamma2, r, a, xp):
    """The LMI blocks, each required <= 0: (20), the pole disk and the decay region per mode."""
    # numpy numbers for the re-check; Affine decision matrices (codegen.design.lmi) for the problem
    cat = np.block if xp is np else bmat
    nw, np_ = sm.nw, sm.L.shape[0]
    out = []
    for i in range(sm.n_modes):
        Aa, Ca, Fa, La = augmented(sm, i, T)
        PAcl = P @ Aa + G[i] @ Ca
        blk = cat([[PAcl + PAcl.T, P @ Fa, La.T],
                   [(P @ Fa).T, -gamma2 * np.eye(nw), np.zeros((nw, np_))],
                   [La, np.zeros((np_, nw)), -np.eye(np_)]])
        out.append((f"(20) mode {i + 1}", blk))
        out.append((f"pole disk |s| < {r:g} mode {i + 1}", cat([[-r * P, PAcl.T], [PAcl, -r * P]])))
        out.append((f"decay Re s < -{a:g} mode {i + 1}", PAcl + PAcl.T + 2 * a * P))
    return out


@dataclass(frozen=True)
class SwitchedPIDesign:
    """Everything Algorithm 1 produces, as emitted (rounded) numbers."""

    settings: SwitchedPIDesignSettings
    T: np.ndarray
    N: np.ndarray
    P: np.ndarray
    Gamma: tuple               # Gamma_ai per mode
    gamma: float
    K: tuple                   # K_i (n x m)
    KI: tuple                  # K_Ii (n_w x m)
    Pi: tuple
    Kp: tuple
    solution: LMISolution | None
    ui_scale: tuple = ()       # k_j of :func:`solver_scale` the LMIs were solved with (empty: 1)

    @property
    def scale(self) -> np.ndarray:
        return np.asarray(self.ui_scale or (1.0,) * self.KI[0].shape[0], dtype=float)

    def closed_loop(self, sm: SwitchedModel, i: int) -> np.ndarray:
        """A_ai - K_ai C_ai of (19)."""
        Aa, Ca, _, _ = augmented(sm, i, self.T)
        return Aa - np.vstack([self.K[i], self.KI[i]]) @ Ca

    def gains_json(self) -> dict:
        out = {"T": self.T.tolist(), "N": self.N.tolist(), "P": self.P.tolist(), "gamma": self.gamma,
               "pole_radius": self.settings.pole_radius, "decay_rate": self.settings.decay_rate}
        for i in range(len(self.K)):
            out.update({f"Gamma_a{i + 1}": self.Gamma[i].tolist(), f"K{i + 1}": self.K[i].tolist(),
                        f"KI{i + 1}": self.KI[i].tolist(), f"Pi{i + 1}": self.Pi[i].tolist(),
                        f"Kp{i + 1}": self.Kp[i].tolist()})
        out["ui_scale"] = self.scale.tolist()
        return out


def problem_name(sm: SwitchedModel) -> str:
    return f"{sm.definition.name}: Menhour et al. 2014 Theorem 2 (common P, {sm.n_modes} modes)"


def build_problem(sm: SwitchedModel, T: np.ndarray, settings: SwitchedPIDesignSettings, k=None,
                  design: bool = True) -> LMIProblem:
    """The LMIs (20) with the pole disk and decay region, in the unknown-input units omega / k
    (:func:`solver_scale`; None: 1); ``k`` is the problem's committed data (none when every k is 1)."""
    k = np.ones(sm.nw) if k is None else np.asarray(k, dtype=float)
    committed = design and np.any(k != 1.0)
    prob = LMIProblem(problem_name(sm), design=design, data={"ui_scale": [float(v) for v in k]} if committed else {})
    sm = scaled_model(sm, k)
    n_a, m = sm.n + sm.nw, sm.m
    P = prob.symmetric("P", n_a)
    G = [prob.matrix(f"Gamma_a{i + 1}", n_a, m) for i in range(sm.n_modes)]
    g2 = prob.scalar("gamma2")
    prob.require_psd("P > 0", P, margin=settings.margin)
    for label, blk in _blocks(sm, T, P, G, g2, settings.pole_radius, settings.decay_rate, LMIProblem):
        prob.require_nsd(label, blk, margin=settings.margin,
                         hint="the modes may not share a Lyapunov matrix; widen the pole disk or change the rule")
    prob.minimize(g2)
    return prob


def design(sm: SwitchedModel, settings: SwitchedPIDesignSettings, solver) -> SwitchedPIDesign:
    """Algorithm 1, the LMIs answered by ``solver`` (:mod:`codegen.design.solver`); P, Gamma_ai and
    gamma^2 rounded to 12 digits before anything else."""
    T, N = decoupling_matrices(sm.C[0])
    check_assumptions(sm, T)
    k = solver_scale(sm, T, settings, solver)
    prob = build_problem(sm, T, settings, k)
    sol = solver.solve(prob, tol=settings.tol)
    n_a, m = sm.n + sm.nw, sm.m
    # solved for [x; omega_s] = S^-1 [x; omega]: back to the model's units, P = S^-1 P_s S^-1,
    # Gamma_a = S^-1 Gamma_as (powers of two: exact), gamma = gamma_s / min k (exact for one unknown
    # input; a bound for several, ||omega_s|| <= ||omega|| / min k)
    s = _state_scale(sm, k)
    P = decimal_round(0.5 * (sol["P"] + sol["P"].T)) / np.outer(s, s)
    G = tuple(decimal_round(np.asarray(sol[f"Gamma_a{i + 1}"]).reshape(n_a, m)) / s[:, None]
              for i in range(sm.n_modes))
    gamma = float(np.sqrt(decimal_round(sol["gamma2"]))) / float(k.min())
    K, KI, Pi, Kp = [], [], [], []
    for i in range(sm.n_modes):
        # the emitted gains: exact arithmetic (codegen.representation.canonical), the same on every machine
        Ka = -canonical.solve(P, G[i])
        K.append(Ka[:sm.n])
        KI.append(Ka[sm.n:])
        Pi.append(canonical.matmul(T, sm.A[i]) - canonical.matmul(K[i], sm.C[i]))
        Kp.append(K[i] + canonical.matmul(Pi[i], N))
    return SwitchedPIDesign(settings, T, N, P, G, gamma, tuple(K), tuple(KI), tuple(Pi), tuple(Kp), sol,
                            tuple(float(v) for v in k))


def certify(sm: SwitchedModel, d: SwitchedPIDesign) -> dict:
    """Numpy re-check of (20), the pole disk and the decay region on the emitted P, Gamma_ai, gamma
    (no solver), in the units the LMIs were solved in (:func:`solver_scale`): P_s = S P S,
    Gamma_as = S Gamma_a, gamma_s = gamma min k, each a product by powers of two (exact). In the
    model's units the blocks are W B_s W with W = diag(S^-1, k^-1, I) (exact congruence, the
    same signs) and the gamma^2 k^-2 block bounded by gamma^2, so a pass certifies gamma in the
    model's units (checked there, the unknown-input rows of a force in N are 2^18 times smaller than
    the state rows, and the margins drown in the eigenvalue solver's round-off)."""
    k = d.scale
    s = _state_scale(sm, k)
    Ps = d.P * np.outer(s, s)
    Gs = tuple(g * s[:, None] for g in d.Gamma)
    gamma_s = d.gamma * float(k.min())
    blocks = {"P > 0": Ps}
    for label, blk in _blocks(scaled_model(sm, k), d.T, Ps, Gs, gamma_s ** 2, d.settings.pole_radius,
                              d.settings.decay_rate, np):
        blocks[label] = -blk
    checks = check_blocks(blocks)
    worst = worst_block(checks, "min_eig")
    failed = uncertified(checks)
    if failed is not None:
        raise CertificateError(f"Menhour et al. 2014 LMI {failed.label!r} fails the numpy re-check on the emitted matrices: "
                               f"{failed.failure()}")
    poles = [np.linalg.eigvals(d.closed_loop(sm, i)) for i in range(sm.n_modes)]
    return {"blocks": len(checks), "worst_block": worst.label, "worst_min_eig": worst.min_eig,
            "worst_relative_margin": worst.relative_margin,
            "max_pole_real_part": float(max(p.real.max() for p in poles)),
            "max_pole_modulus": float(max(np.abs(p).max() for p in poles))}


# --- independent H-infinity norm of each mode's error system ----------------------------------------

def hinf_norm(A: np.ndarray, B: np.ndarray, C: np.ndarray, rtol: float = 1e-9) -> tuple:
    """||C (sI - A)^-1 B||_inf of a stable system by Hamiltonian bisection (Boyd, Balakrishnan,
    Kabamba 1989): gamma > norm iff H(gamma) = [[A, B B^T / gamma^2], [-C^T C, -A^T]] has no
    eigenvalue on the imaginary axis. Returns (norm, frequency of the peak [rad/s])."""
    if np.linalg.eigvals(A).real.max() >= 0:
        raise CertificateError("H-infinity norm of an unstable system requested")

    def sigma(w):
        return float(np.linalg.svd(C @ np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, B), compute_uv=False)[0])

    def crossings(g):
        H = np.block([[A, B @ B.T / g ** 2], [-C.T @ C, -A.T]])
        ev = np.linalg.eigvals(H)
        scale = max(1.0, np.abs(ev).max())
        return sorted(abs(e.imag) for e in ev if abs(e.real) < 1e-9 * scale)

    # lower bound from the poles' frequencies and DC, upper by doubling
    cands = [0.0] + [abs(p.imag) for p in np.linalg.eigvals(A)] + [abs(p) for p in np.linalg.eigvals(A)]
    w_best = max(cands, key=sigma)
    lo = sigma(w_best)
    if lo == 0.0:
        return 0.0, 0.0
    hi = 2.0 * lo
    while crossings(hi):
        hi *= 2.0
    while hi - lo > rtol * hi:
        g = 0.5 * (lo + hi)
        ws = crossings(g)
        if ws:
            # the midpoints of consecutive crossings carry sigma >= g (BBK): raise the lower bound
            mids = [0.5 * (a + b) for a, b in zip(ws, ws[1:])] + ws
            w = max(mids, key=sigma)
            if sigma(w) > lo:
                lo, w_best = sigma(w), w
            lo = max(lo, g)
        else:
            hi = g
    return hi, w_best


def hinf_sweep(A, B, C, w_min=1e-3, w_max=1e5, points=4000) -> tuple:
    """Peak of sigma_max(C (jw I - A)^-1 B) on a log grid (a second, simpler estimate)."""
    ws = np.concatenate([[0.0], np.logspace(np.log10(w_min), np.log10(w_max), points)])
    I = np.eye(A.shape[0])
    vals = [np.linalg.svd(C @ np.linalg.solve(1j * w * I - A, B), compute_uv=False)[0] for w in ws]
    k = int(np.argmax(vals))
    return float(vals[k]), float(ws[k])


def hinf_check(sm: SwitchedModel, d: SwitchedPIDesign) -> dict:
    """Each mode's ||L_ai (sI - (A_ai - K_ai C_ai))^-1 F_ai||_inf, by bisection and by sweep, <= gamma."""
    rows = []
    for i in range(sm.n_modes):
        _, _, Fa, La = augmented(sm, i, d.T)
        Acl = d.closed_loop(sm, i)
        norm, w = hinf_norm(Acl, Fa, La)
        sweep, ws = hinf_sweep(Acl, Fa, La)
        rows.append({"mode": i + 1, "hinf_bisection": norm, "peak_rad_s": w, "hinf_sweep": sweep,
                     "sweep_peak_rad_s": ws})
        if norm > d.gamma * (1 + 1e-9) or sweep > d.gamma * (1 + 1e-9):
            raise CertificateError(f"mode {i + 1}: H-infinity norm {max(norm, sweep):.6g} exceeds the certified "
                                   f"gamma = {d.gamma:.6g}")
    return {"gamma": d.gamma, "modes": rows, "max_hinf": max(max(r["hinf_bisection"], r["hinf_sweep"]) for r in rows)}


# --- discrete step -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class DiscreteModes:
    """q_{k+1} = Phi_i q_k + G_i [u_k; y_k] per mode (exact ZOH at T_s), q = [z; w_hat]."""

    Ts: float
    Phi: np.ndarray            # (M, n_a, n_a)
    G: np.ndarray              # (M, n_a, nu + m)


def observer_matrices(sm: SwitchedModel, d: SwitchedPIDesign, i: int) -> tuple:
    """(A_o, B_o) of the continuous observer (5) of mode i: q' = A_o q + B_o [u; y]."""
    T, N, C = d.T, d.N, sm.C[i]
    n, nw, m = sm.n, sm.nw, sm.m
    mm = canonical.matmul
    Ao = np.block([[d.Pi[i], mm(T, sm.F[i])], [-mm(d.KI[i], C), np.zeros((nw, nw))]])
    Bo = np.block([[mm(T, sm.B[i]), d.Kp[i]], [np.zeros((nw, sm.nu)), mm(d.KI[i], np.eye(m) - mm(C, N))]])
    return Ao, Bo


def discretize(sm: SwitchedModel, d: SwitchedPIDesign, Ts: float) -> DiscreteModes:
    Phi, G = [], []
    for i in range(sm.n_modes):
        Ao, Bo = observer_matrices(sm, d, i)
        na, nb = Ao.shape[0], Bo.shape[1]
        E = canonical.expm(np.block([[Ao, Bo], [np.zeros((nb, na + nb))]]) * Ts)   # exact ZOH, machine-independent
        Phi.append(decimal_round(E[:na, :na]))
        G.append(decimal_round(E[:na, na:]))
    return DiscreteModes(Ts, np.array(Phi), np.array(G))


def certify_discrete(sm: SwitchedModel, d: SwitchedPIDesign, dm: DiscreteModes) -> dict:
    """Spectral radius of each mode's sampled error dynamics Phi_i < 1, and the common-Lyapunov
    decrease Phi_i^T P Phi_i < P for every mode (stability under any switching sequence).

    The observer's own state matrix A_o equals the error matrix A_ai - K_ai C_ai (same blocks), so
    Phi_i is also the sampled error transition. Raises :class:`DiscretizationError` otherwise."""
    radii, ratios = [], []
    # in the solver's unknown-input units (exact powers of two; the same ratios and radii)
    s = _state_scale(sm, d.scale)
    P = d.P * np.outer(s, s)
    Lc = np.linalg.cholesky(P)
    Li = np.linalg.inv(Lc)
    for i in range(sm.n_modes):
        Acl = d.closed_loop(sm, i)
        if np.abs(observer_matrices(sm, d, i)[0] - Acl).max() > 1e-9 * max(1.0, np.abs(Acl).max()):
            raise DiscretizationError(f"mode {i + 1}: observer matrix differs from the error matrix")
        Phi = dm.Phi[i] / s[:, None] * s[None, :]
        radii.append(float(np.abs(np.linalg.eigvals(Phi)).max()))
        S = Li @ Phi.T @ P @ Phi @ Li.T
        ratios.append(float(np.linalg.eigvalsh(0.5 * (S + S.T)).max()))
    if max(radii) >= 1.0:
        raise DiscretizationError(f"the T_s = {dm.Ts:g} s step has spectral radius {max(radii):.6f} >= 1 "
                                  f"in mode {int(np.argmax(radii)) + 1}")
    if max(ratios) >= 1.0:
        raise DiscretizationError(f"common Lyapunov check fails at T_s = {dm.Ts:g} s: max V(e+)/V(e) = "
                                  f"{max(ratios):.9f} >= 1 in mode {int(np.argmax(ratios)) + 1}")
    return {"Ts": dm.Ts, "spectral_radius": radii, "spectral_radius_max": max(radii),
            "lyapunov_ratio": ratios, "lyapunov_ratio_max": max(ratios),
            "contraction_per_step": float(np.sqrt(max(ratios)))}


# --- the step: switching logic inside ----------------------------------------------------------------
#
# Step state z = [q_k (z, w_hat: n + n_w), mode, x_hat_k (n), w_hat_k (n_w)]; the last 1 + n + n_w
# entries are the outputs (mode, estimates of the sample just consumed). One call consumes
# w_k = [u_k; y_k] and the scheduling inputs rho_k:
#   1. x_hat_k = z_k + N y_k, w_hat_k (the outputs of this sample);
#   2. the premises from x_hat_k, u_k and rho_k clamped to their boxes; the mode by the rule's
#      thresholds (deterministic, hysteresis-free: every premise value selects exactly one mode);
#   3. q_{k+1} = Phi_i q_k + G_i w_k (exact ZOH of mode i's observer (5)).
# ``excess`` sums how far the scheduling inputs lie outside their boxes and the premises outside
# their ranges (SCHEDULING_CLAMPED in C).

def scheduling_inputs(sm: SwitchedModel) -> tuple:
    """Scheduling signals the premises read (observer inputs after u and y), in model order."""
    return tuple(str(g.symbol) for g in sm.definition.scheduling if str(g.symbol) in sm.scheduling_boxes)


def _premise_functions(sm: SwitchedModel, xp):
    import sympy as sp_
    from ...emit.stepgen import lambdify
    d = sm.definition
    sched = {str(g.symbol): g.symbol for g in d.scheduling}
    args = (*d.states, *d.known_inputs, *(sched[n] for n in scheduling_inputs(sm)))
    if xp is ca:
        return [lambdify(args, a.premise) for a in sm.rule.axes]
    return [sp_.lambdify(args, a.premise, "math") for a in sm.rule.axes]


def mode_indicators(sm: SwitchedModel, premise_values, xp=np) -> list:
    """0/1 indicator of every mode (exactly one is 1), from the premise values (one per axis)."""
    per_axis = []
    for a, p in zip(sm.rule.axes, premise_values):
        if xp is np:
            ge = [1.0 if p >= t else 0.0 for t in a.thresholds]
        else:
            ge = [p >= t for t in a.thresholds]         # CasADi comparison: exactly 0.0 or 1.0
        s = [1 - ge[0]] + [ge[j - 1] - ge[j] for j in range(1, len(ge))] + [ge[-1]] if ge else [1.0]
        per_axis.append(s)
    out = []
    for i in range(sm.n_modes):
        w = 1.0
        for a_s, b in zip(per_axis, sm.rule.bands_of_mode(i)):
            w = w * a_s[b]
        out.append(w)
    return out


def step_parts(sm: SwitchedModel, d: SwitchedPIDesign, dm: DiscreteModes, q, u, y, rho, xp=np):
    """(q_next, mode (1-based), x_hat_k, w_hat_k, excess) on numpy arrays or CasADi SX."""
    n, nw, m, nu = sm.n, sm.nw, sm.m, sm.nu
    fmin, fmax, fabs = (ca.fmin, ca.fmax, ca.fabs) if xp is ca else (min, max, abs)
    N = d.N if xp is np else ca.DM(d.N)
    x_hat = q[:n] + N @ y
    w_hat = q[n:n + nw]
    names = scheduling_inputs(sm)
    clamped = [fmin(fmax(rho[k], sm.scheduling_boxes[s][0]), sm.scheduling_boxes[s][1]) for k, s in enumerate(names)]
    excess = 0.0
    for k in range(len(names)):
        excess = excess + fabs(rho[k] - clamped[k])
    fns = _premise_functions(sm, xp)
    args = [x_hat[k] for k in range(n)] + [u[k] for k in range(nu)] + clamped
    prem = [f(*args) for f in fns]
    for a, p in zip(sm.rule.axes, prem):
        excess = excess + fmax(0.0, fmax(a.lower - p, p - a.upper))
    s = mode_indicators(sm, prem, xp)
    mode = sum(w * (i + 1) for i, w in enumerate(s))
    w_in = np.concatenate([u, y]) if xp is np else ca.vertcat(u, y)

    def blend(mats):
        if np.ptp(mats, axis=0).max(initial=0.0) == 0.0:
            return mats[0] if xp is np else ca.DM(mats[0])
        if xp is np:
            return sum(w * M for w, M in zip(s, mats))
        # entries equal in every mode stay constants; the others select by the 0/1 indicators
        out = ca.SX(mats[0].shape[0], mats[0].shape[1])
        for r_ in range(mats[0].shape[0]):
            for c_ in range(mats[0].shape[1]):
                vals = mats[:, r_, c_]
                if np.all(vals == vals[0]):
                    out[r_, c_] = float(vals[0])
                else:
                    out[r_, c_] = sum(s[i] * float(vals[i]) for i in range(len(vals)) if vals[i] != 0.0)
        return out

    q_next = blend(dm.Phi) @ q + blend(dm.G) @ w_in
    return q_next, mode, x_hat, w_hat, excess


def state_layout(sm: SwitchedModel) -> list:
    """Names of the step's state: [q (z_*, z_<unknown input>), mode, estimates]; the last
    1 + n + n_w entries (mode and the estimates) are the outputs."""
    d = sm.definition
    return ([f"z_{s}" for s in d.states] + [f"z_{w}" for w in d.unknown_inputs] + output_layout(sm))


def output_layout(sm: SwitchedModel) -> list:
    d = sm.definition
    return ["mode"] + [str(s) for s in d.states] + [str(w) for w in d.unknown_inputs]


def step_casadi(sm: SwitchedModel, d: SwitchedPIDesign, dm: DiscreteModes, name: str) -> ca.Function:
    """(z, u, y, rho) -> (z_next, excess); see :func:`state_layout`."""
    n, nw, m, nu = sm.n, sm.nw, sm.m, sm.nu
    z = ca.SX.sym("z", len(state_layout(sm)))
    u = ca.SX.sym("u", nu)
    y = ca.SX.sym("y", m)
    rho = ca.SX.sym("rho", len(scheduling_inputs(sm)))
    q = z[:n + nw]
    q_next, mode, x_hat, w_hat, excess = step_parts(sm, d, dm, q, u, y, [rho[k] for k in range(rho.shape[0])], xp=ca)
    z_next = ca.vertcat(q_next, mode, x_hat, w_hat)
    return ca.Function(name, [z, u, y, rho], [z_next, excess], ["z", "u", "y", "rho"], ["z_next", "excess"])


def step_numpy(sm: SwitchedModel, d: SwitchedPIDesign, dm: DiscreteModes, z, u, y, rho):
    """Reference step in numpy: returns (z_next, excess)."""
    n, nw = sm.n, sm.nw
    z, u, y = (np.asarray(a, float) for a in (z, u, y))
    q_next, mode, x_hat, w_hat, excess = step_parts(sm, d, dm, z[:n + nw], u, y, list(np.atleast_1d(rho)), xp=np)
    return np.concatenate([q_next, [mode], x_hat, w_hat]), float(excess)
