"""Two-stage interconnected LPV unknown-input observer of seed 003 (NI-UIO), Sec. 4.

Per subsystem (longitudinal bar, lateral check) of the T-S model (8) built by
:mod:`codegen.interconnected`:

* decoupling (26): H = -B (C B)^+, after the matching condition (16) rank(CB) = rank(B);
  T = I + H C (B, C constant: see that module for the kappa' = v_x kappa input), so T' = 0;
* the ISS LMIs (27b), (27d), (27e) at every vertex i with a common P per subsystem, one
  problem for both subsystems with the weighted objective a eta_1 + (1 - a) eta_2 (27a);
* gains (28): K_i = P^-1 Omega_i, N_i = Gamma_i - K_i C, L_i = K_i - N_i H, G_i = T D_i;
* the observer (17): z' = N(eta) z + L(eta) y~ + G(eta) zeta_hat, x_hat = z - H y~,
  with y~ = y - E zeta_hat (output feedthrough of the coupling signals);
* the unknown inputs by the algebraic inversion (30),
  u'_hat = (C B)^+ (y'_hat - C A(eta) x_hat - C D(eta) zeta_hat), y'_hat from Levant
  differentiators (:mod:`codegen.differentiators`), kappa = kappa'/v_x.

Choices the seed leaves open (all here, and in the README's seed-003 section):

1. *T_eta'* (20): B and C are constant after the kappa' substitution, so H, T are constant
   and T' = 0 exactly; no T' term is dropped.
2. *Matching (16) for the lateral subsystem.* With the printed outputs [r, psi_L, y_L, a_y, delta]
   T_s has relative degree 2 (it reaches delta''), so rank(CB) = 1 < rank(B) = 2 and no UIO
   exists. We add delta_dot to the lateral outputs, taken from the HOSMD of delta
   (``derivative_outputs`` of the configuration); the seed's own HOSMD makes it available.
3. *Coordinates.* Forces (N) and speeds (m/s) differ by 10^4 and Clarabel fails on the raw
   problem, so the LMIs are posed in scaled coordinates x_s = S^-1 x, y_s = W^-1 y (each row of
   C S of unit largest entry) and zeta_s = Z^-1 zeta (each column of S^-1 T D of unit largest
   entry). S starts from the state box and is refined by diagonal balancing (LAPACK gebal) of the
   box-scaled mean |A_i| + I: the box alone puts v_x and the wheel speeds on a scale where one unit
   of slip-velocity error is ~10^3 units of force error, and P then needs eigenvalues ~10^4 that
   Clarabel cannot resolve. All scales are powers of two (exact). P >= I, eta, the weight g I and
   the gain bound are read in these units.
4. *Gain bound.* (27) does not bound the gains; Omega_i' P^-1 Omega_i <= ell^2 I is added (an LMI by
   Schur), which with P >= I gives ||K_i|| <= ell in scaled coordinates, like the seed-000
   family's bound. (A bound on ||Omega_i|| itself is infeasible here: the slip stiffness couples a
   wheel-speed error into the force errors with ~1.1e3 s^-1 in scaled units, so P must weigh the
   wheel-speed errors heavily and Omega = P K grows with it.)
5. *Unmeasured premises.* v_x is not measured: the observer schedules on its own estimate
   (clamped to the box) and on the measured wheel speeds for q_i. Theorem 1 (like its proof,
   eq. (19)) assumes the observer's eta equals the plant's; the premise mismatch is not in
   the certificate, which covers the error dynamics for matched premises.
6. *Discrete step.* Backward Euler on z at the configured T_s, premises of the latest estimate;
   with the common P of (27), V(e_{k+1}) <= V(e_k)/(1 + alpha T_s) for every membership
   sequence (checked numerically, :func:`discrete_certificate`), and the decoupling TB = 0 is
   exact for the backward-Euler plant. In scaled coordinates the step solves
   M(eta) w = P r with M = P (I - T_s N_s) = sum eta_i M_i, whose symmetric part is positive
   definite by (27b): the unrolled LU without pivoting cannot meet a zero pivot.
7. *Units of (C B)^+.* The left pseudo-inverse of (26) and (30) is a least-squares inverse and
   depends on the output units: in the model's units (rad, m) the y_L row of kappa' (which carries
   the v_y estimate) outweighs the psi_L row l_s^2 = 25 : 1 and the curvature error is that of
   v_y / l_s. We take both pseudo-inverses in the normalized output units of the LMI design
   (choice 3), (C B)^+ = (W^-1 C B)^+ W^-1, where the psi_L row dominates (16 : 1.6);
   T B = 0 holds either way.
8. *Gain structure.* By default Omega_i = Omega_0 + sum_k theta_k(i) Omega_k, the vertex values of
   a gain affine in the premises. (27b) is then affine in theta, so its vertex conditions still
   cover the whole box exactly, and N, L and M are affine in theta: the step evaluates
   V_0 + sum_k theta_k V_k (q + 1 terms) instead of sum_i eta_i V_i (2^q terms), which halves the
   step's cost. It restricts the seed's free Omega_i; ``gain_structure = "vertex"`` is the
   printed form.
9. *Which H.* T B = 0 has the general solution H = -B (CB)^+ + Y (I - CB (CB)^+); (26) is Y = 0.
   ``decoupling = "measured_rows"`` takes the member whose T has zero rows for every state an
   output reads directly (H_j = -e_k' there: r, psi_L, y_L, delta, delta_dot, w_f, w_r). T B = 0
   still holds (B only reaches measured states here), and since the model error w enters the
   estimation error as T w, it no longer drives the errors of those states: x_hat_j follows y_k
   up to an error that decays with the (27) dynamics. With (26) the r estimate filters model
   mismatch (1.7 % RMSE on the CommonRoad track), and through C A x_hat in (30) that error
   becomes the curvature error (kappa' = r_hat - psi_L'); ``"minimum_norm"`` (the default of
   the settings) is the printed (26).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
import scipy.linalg
import sympy as sp

from .. import interconnected as icm
from ..differentiators import MAX_ORDER, HosmdSpec, hosmd_step_numpy, hosmd_step_sx
from ..discrete import solve_unpivoted
from ..errors import CertificateError, DiscretizationError, ModelDefinitionError, RankConditionError
from ..lmi import LMIProblem, LMISolution, bmat, check_blocks
from ..polytope import sector_weights_product
from ..settings import Rule, parse_settings, parse_table, setting
from .. import canonical
from .linf_uio import round_significant

FAMILY = "interconnected_uio"
_CA_MODULES = [{"Max": ca.fmax, "Min": ca.fmin, "Abs": ca.fabs, "sqrt": ca.sqrt}, "math"]


@dataclass(frozen=True)
class ICDesignSettings:
    """Tuning of Theorem 1 and of the step (all in the configuration's ``[design]`` table).

    Attributes
    ----------
    alpha : float
        alpha of (27b): V' <= -alpha V + Delta' G^-1 Delta.
    weight : float
        a of (27a), in [0, 1].
    coupling_gain : float
        g of the weight G = g I on the (normalized) coupling signals in (27b)-(27c).
    gain_bound : float
        ell: Omega_i' P^-1 Omega_i <= ell^2 I, hence ||K_i||_2 <= ell in scaled coordinates (our addition;
        see the module docstring).
    margin, tol : float
        Every LMI block >= margin I; Clarabel tolerance.
    gain_structure : str
        ``"affine"`` (default): Omega_i are the vertex values of an affine function of the premises,
        so N, L and the step matrix are affine in the premises and the step combines q + 1 matrices
        instead of 2^q (choice 8 of the module docstring); ``"vertex"``: free Omega_i, as printed.
    decoupling : str
        ``"minimum_norm"`` (default): H of (26); ``"measured_rows"``: choice 9 of the module docstring.
    """

    alpha: float = setting(2.0, gt=0, doc="alpha of (27b)")
    weight: float = setting(0.5, ge=0, le=1, doc="a of (27a)")
    coupling_gain: float = setting(1.0, gt=0, doc="g of G = g I")
    gain_bound: float = setting(100.0, gt=0, doc="ell: ||K_i|| <= ell")
    margin: float = setting(1e-6, ge=0)
    tol: float = setting(1e-7, gt=0)
    gain_structure: str = setting("affine", choices=("affine", "vertex"))
    decoupling: str = setting("minimum_norm", choices=("minimum_norm", "measured_rows"))

    def __post_init__(self):
        if self.gain_structure not in ("affine", "vertex"):
            raise ModelDefinitionError(f"gain_structure must be 'affine' or 'vertex', got {self.gain_structure!r}")
        if self.decoupling not in ("minimum_norm", "measured_rows"):
            raise ModelDefinitionError(f"decoupling must be 'minimum_norm' or 'measured_rows', got {self.decoupling!r}")
        if not (self.alpha > 0 and 0.0 <= self.weight <= 1.0 and self.coupling_gain > 0
                and self.gain_bound > 0 and self.margin >= 0 and self.tol > 0):
            raise ModelDefinitionError(f"invalid interconnected-UIO design settings {self}")


@dataclass(frozen=True)
class StepSettings:
    """What the step needs beyond the gains: differentiators, pseudo-outputs, flags, start."""

    differentiators: tuple       # (signal name, HosmdSpec)
    derivative_outputs: tuple    # (pseudo-output name, source signal name): first derivative
    flag_outside_box: tuple      # measured signals flagged outside their state box
    initial: tuple               # (state name, sympy expr in measured outputs + parameters)


@dataclass(frozen=True)
class SubsystemDesign:
    """Gains of one subsystem, physical units; ``P``, ``Omega`` in the scaled coordinates."""

    name: str
    H: np.ndarray
    T: np.ndarray
    S: np.ndarray            # state scale (diagonal entries)
    W: np.ndarray            # output scale
    Z: np.ndarray            # coupling-signal scale
    P: np.ndarray
    Omega: tuple
    eta: float
    K: tuple
    N: tuple
    L: tuple
    G: tuple
    CBp: np.ndarray          # (C B)^+ of (30)

    def M(self, Ts: float) -> tuple:
        """M_i = P (I - Ts S^-1 N_i S) of the backward-Euler step (scaled coordinates)."""
        S, Si = np.diag(self.S), np.diag(1.0 / self.S)
        # emitted: exact arithmetic (codegen.canonical); S is diagonal, so S^-1 N S is exact as it is
        return tuple(canonical.matmul(self.P, np.eye(len(self.S)) - Ts * (Si @ n @ S)) for n in self.N)


@dataclass(frozen=True)
class ICDesign:
    settings: ICDesignSettings
    subsystems: tuple        # SubsystemDesign, in the model's subsystem order
    solution: LMISolution | None


def decoupling(sub: icm.SubsystemTS, W: np.ndarray | None = None, rank_tol: float = 1e-10,
               mode: str = "minimum_norm") -> tuple:
    """(H, T, (CB)^+) of (26) after the matching condition (16).

    The left pseudo-inverse is taken in the output units y_s = W^-1 y (choice 7 of the module
    docstring): (CB)^+ = (W^-1 C B)^+ W^-1; W = None uses the model's units. ``mode``
    ``"minimum_norm"`` is (26), H = -B (CB)^+ (Y = 0 in the general solution
    H = -B (CB)^+ + Y (I - CB (CB)^+) of T B = 0); ``"measured_rows"`` is the member of the same
    family whose T has zero rows for the states an output measures directly (choice 9).

    Raises
    ------
    RankConditionError
        naming the subsystem and the ranks.
    """
    CB = canonical.matmul(sub.C, sub.B)      # (26)-(30) are emitted: exact arithmetic (codegen.canonical)
    r_cb = np.linalg.matrix_rank(CB, tol=rank_tol * max(np.abs(CB).max(), 1e-300))
    r_b = np.linalg.matrix_rank(sub.B, tol=rank_tol * max(np.abs(sub.B).max(), 1e-300))
    if r_cb != r_b:
        raise RankConditionError(
            f"{sub.name}: matching condition (16) fails, rank(CB) = {r_cb} != rank(B) = {r_b}; an unknown input "
            f"does not reach the outputs in one integration (relative degree > 1): measure, or take from a "
            f"differentiator, the derivative that it reaches")
    Wi = np.diag(1.0 / (np.ones(sub.ny) if W is None else np.asarray(W, float)))
    CBs = Wi @ CB
    CBp = canonical.matmul(canonical.solve(canonical.matmul(CBs.T, CBs), CBs.T), Wi)
    H = -canonical.matmul(sub.B, CBp)
    if mode == "measured_rows":
        for k in range(sub.ny):
            row = sub.C[k]
            nz = np.flatnonzero(row)
            if len(nz) == 1 and row[nz[0]] == 1.0:
                H[nz[0], :] = 0.0
                H[nz[0], k] = -1.0
    elif mode != "minimum_norm":
        raise ModelDefinitionError(f"decoupling must be 'minimum_norm' or 'measured_rows', got {mode!r}")
    T = np.eye(sub.n) + canonical.matmul(H, sub.C)
    if np.abs(T @ sub.B).max() > 1e-9 * max(1.0, np.abs(sub.B).max()):
        raise RankConditionError(f"{sub.name}: T B != 0 after (26)")
    return H, T, CBp


def _pow2(x: np.ndarray) -> np.ndarray:
    """Nearest powers of two (exact scaling)."""
    x = np.where(np.asarray(x, float) > 0, x, 1.0)
    return 2.0 ** np.round(np.log2(x))


def scaling(ts: icm.InterconnectedTS, sub: icm.SubsystemTS, T: np.ndarray | None = None) -> tuple:
    """(S, W, Z) of choice 3 of the module docstring (Z needs T; without it Z is empty)."""
    missing = [str(s) for s in sub.states if s not in ts.state_box]
    if missing:
        raise ModelDefinitionError(f"{sub.name}: [state_bounds] lacks {', '.join(missing)}; the design scales its "
                                   f"coordinates by the state box")
    box = _pow2([max(abs(v) for v in ts.state_box[s]) for s in sub.states])
    # refine by diagonal balancing of the box-scaled mean |A_i| (+ I against zero columns, e.g. y_L)
    Am = np.abs(sub.A).mean(axis=0) / box[:, None] * box[None, :]
    _, (bal, _) = scipy.linalg.matrix_balance(Am + np.eye(sub.n), permute=False, separate=True)
    bal = np.clip(bal / np.exp(np.mean(np.log(bal))), 2.0 ** -10, 2.0 ** 10)
    S = _pow2(box * bal)
    CS = sub.C * S[None, :]
    W = _pow2(np.abs(CS).max(axis=1))
    if T is None:
        return S, W, np.zeros(0)
    G = (T @ sub.D) / S[None, :, None]
    Z = _pow2(1.0 / np.maximum(np.abs(G).max(axis=(0, 1)), 1e-300)) if sub.nzeta else np.zeros(0)
    Z = np.where(np.abs(G).max(axis=(0, 1)) > 0, Z, 1.0) if sub.nzeta else Z
    return S, W, Z


def _blocks(sub, T, S, W, Z, P, Om, settings, xp):
    """(27b) per vertex, (27e); numbers (``xp`` numpy, the re-check) or Affine decision matrices of
    :mod:`codegen.lmi` (the problem). (27d) and the gain bound are added by the caller."""
    cat = np.block if xp is np else bmat
    Si = np.diag(1.0 / S)
    Cs = np.diag(1.0 / W) @ sub.C @ np.diag(S)
    out = []
    nz = sub.nzeta
    for i in range(sub.n_vertices):
        Gam = Si @ T @ sub.A[i] @ np.diag(S)
        b11 = Gam.T @ P + P @ Gam - Cs.T @ Om[i].T - Om[i] @ Cs + settings.alpha * P
        if nz:
            Gs = Si @ T @ sub.D[i] @ np.diag(Z)
            blk = cat([[b11, P @ Gs], [Gs.T @ P, -np.eye(nz) / settings.coupling_gain]])
        else:
            blk = b11
        out.append((f"(27b) {sub.name} vertex {i + 1}", -blk))
    return out


def build_problem(ts: icm.InterconnectedTS, settings: ICDesignSettings):
    prob = LMIProblem(f"{ts.definition.name}: seed 003 Theorem 1")
    parts, etas = [], []
    for k, sub in enumerate(ts.subsystems):
        S, W, _ = scaling(ts, sub)
        H, T, CBp = decoupling(sub, W, mode=settings.decoupling)
        S, W, Z = scaling(ts, sub, T)
        n, ny = sub.n, sub.ny
        P = prob.symmetric(f"P_{sub.name}", n)
        eta = prob.scalar(f"eta_{sub.name}")
        if settings.gain_structure == "affine":
            # Omega_i = Omega(theta_i) of an affine Omega(theta) = Omega_0 + sum_k theta_k Omega_k
            parts_ = [prob.matrix(f"Omega_{sub.name}_affine_{k}", n, ny) for k in range(len(sub.premises) + 1)]
            Om = [parts_[0] + sum((th * pk for th, pk in zip(theta, parts_[1:])), np.zeros((n, ny)))
                  for theta in vertex_premises(sub)]
        else:
            Om = [prob.matrix(f"Omega_{sub.name}_{i + 1}", n, ny) for i in range(sub.n_vertices)]
        for label, blk in _blocks(sub, T, S, W, Z, P, Om, settings, LMIProblem):
            prob.require_psd(label, blk, margin=settings.margin,
                             hint="lower alpha or the coupling weight g, or widen the gain bound")
        a = settings.alpha * eta
        prob.require_psd(f"(27d) {sub.name}", bmat([[a * np.eye(n), P], [P, a * np.eye(n)]]),
                         margin=settings.margin)
        prob.require_psd(f"(27e) {sub.name}", P - np.eye(n), margin=settings.margin)
        ell = settings.gain_bound
        for i in range(sub.n_vertices):
            # [[ell I, Omega'], [Omega, ell P]] >= 0 <=> Omega' P^-1 Omega <= ell^2 I; with P >= I:
            # ||K_i||_2 = ||P^-1 Omega_i|| <= ell (scaled coordinates)
            prob.require_psd(f"gain bound {sub.name} vertex {i + 1}",
                             bmat([[ell * np.eye(ny), Om[i].T], [Om[i], ell * P]]), margin=0.0)
        parts.append((sub, H, T, CBp, S, W, Z))
        etas.append(eta)
    w = settings.weight
    objective = w * etas[0] + (1.0 - w) * etas[1] if len(etas) == 2 else sum(etas)
    prob.minimize(objective)
    return prob, parts


def design(ts: icm.InterconnectedTS, settings: ICDesignSettings = ICDesignSettings()) -> ICDesign:
    """Theorem 1: (26), LMIs (27) on Clarabel, rounded, gains (28)."""
    prob, parts = build_problem(ts, settings)
    sol = prob.solve(tol=settings.tol)
    designs = []
    for sub, H, T, CBp, S, W, Z in parts:
        P = round_significant(0.5 * (sol[f"P_{sub.name}"] + sol[f"P_{sub.name}"].T))
        if settings.gain_structure == "affine":
            aff = [round_significant(np.atleast_2d(sol[f"Omega_{sub.name}_affine_{k}"]).reshape(sub.n, sub.ny))
                   for k in range(len(sub.premises) + 1)]
            Om = tuple(aff[0] + sum(th * a for th, a in zip(theta, aff[1:])) for theta in vertex_premises(sub))
        else:
            Om = tuple(round_significant(np.atleast_2d(sol[f"Omega_{sub.name}_{i + 1}"]).reshape(sub.n, sub.ny))
                       for i in range(sub.n_vertices))
        designs.append(_gains(sub, H, T, CBp, S, W, Z, P, Om, float(sol[f"eta_{sub.name}"])))
    return ICDesign(settings, tuple(designs), sol)


def vertex_premises(sub: icm.SubsystemTS) -> list:
    """Premise values theta at each vertex, in the vertex order of the T-S matrices (bit j of the
    vertex index: 0 = lower, 1 = upper end of premise j)."""
    q = len(sub.premises)
    return [[(p.upper if (idx >> (q - 1 - j)) & 1 else p.lower) for j, p in enumerate(sub.premises)]
            for idx in range(2 ** q)]


def affine_parts(sub: icm.SubsystemTS, mats) -> tuple:
    """(V_0, V_1, ..., V_q) with V_i = V_0 + sum_k theta_k(i) V_k at every vertex, or None when the
    vertex matrices are not those of an affine function of the premises."""
    mats = np.asarray(mats, float)
    X = np.array([[1.0, *th] for th in vertex_premises(sub)])
    flat = mats.reshape(mats.shape[0], -1)
    coef = canonical.matmul(canonical.pinv(X), flat)     # emitted: machine-independent
    if np.abs(X @ coef - flat).max() > 1e-9 * max(1.0, np.abs(flat).max()):
        return None
    return tuple(c.reshape(mats.shape[1:]) for c in coef)


def _gains(sub, H, T, CBp, S, W, Z, P, Om, eta) -> SubsystemDesign:
    Sd = np.diag(S)
    # the emitted gains (28): exact arithmetic (codegen.canonical), the same on every machine
    K = tuple(canonical.matmul(Sd, canonical.solve(P, o), np.diag(1.0 / W)) for o in Om)
    N = tuple(canonical.matmul(T, sub.A[i]) - canonical.matmul(K[i], sub.C) for i in range(sub.n_vertices))
    L = tuple(K[i] - canonical.matmul(N[i], H) for i in range(sub.n_vertices))
    G = tuple(canonical.matmul(T, sub.D[i]) for i in range(sub.n_vertices))
    return SubsystemDesign(sub.name, H, T, S, W, Z, P, Om, eta, K, N, L, G, CBp)


def certify(ts: icm.InterconnectedTS, d: ICDesign) -> dict:
    """Independent numpy re-check of (27b), (27d), (27e) and the gain bound on the emitted (rounded) P,
    Omega_i; no solver involved. Raises CertificateError on any failure."""
    out = {}
    worst_all = None
    for sub, sd in zip(ts.subsystems, d.subsystems):
        blocks = dict(_blocks(sub, sd.T, sd.S, sd.W, sd.Z, sd.P, sd.Omega, d.settings, np))
        n = sub.n
        # (27d) <=> alpha eta I - P > 0 (P > 0); the solver's eta is not rounded, so re-check it
        blocks[f"(27d) {sub.name}"] = d.settings.alpha * sd.eta * np.eye(n) - sd.P
        blocks[f"(27e) {sub.name}"] = sd.P - np.eye(n)
        checks = check_blocks(blocks)
        gain = max(float(np.linalg.norm(np.linalg.solve(sd.P, o), 2)) for o in sd.Omega)
        worst = min(checks, key=lambda c: c.min_eig)
        if worst.min_eig <= 0:
            raise CertificateError(f"seed-003 LMI {worst.label!r} fails the numpy re-check on the emitted matrices: "
                                   f"smallest eigenvalue {worst.min_eig:.3e}")
        if gain > d.settings.gain_bound * (1 + 1e-6):
            raise CertificateError(f"{sub.name}: ||K_i|| = {gain:.6g} (scaled) exceeds the bound {d.settings.gain_bound}")
        iss = float(np.sqrt(np.linalg.eigvalsh(sd.P)[-1] / (np.linalg.eigvalsh(sd.P)[0] * d.settings.alpha)))
        out[sub.name] = {"blocks": len(checks), "worst_block": worst.label, "worst_min_eig": worst.min_eig,
                         "worst_relative_margin": worst.relative_margin, "eta": sd.eta,
                         "iss_gain_sqrt_cond_over_alpha": iss, "max_scaled_gain_norm": gain}
        if worst_all is None or worst.min_eig < worst_all[1]:
            worst_all = (worst.label, worst.min_eig)
    out["worst_block"], out["worst_min_eig"] = worst_all
    return out


def discrete_certificate(ts: icm.InterconnectedTS, d: ICDesign, Ts: float, samples: int = 2000,
                         seed: int = 0) -> dict:
    """The backward-Euler step contracts: for V = e_s' P e_s and every membership vector,
    (I - Ts N_s)' P (I - Ts N_s) >= (1 + alpha Ts) P (implied by (27b); checked at the vertices
    and ``samples`` random points of the simplex), and M_i + M_i' > 0 at every vertex (so
    unpivoted LU of M(eta) is safe on the whole simplex). Raises DiscretizationError."""
    rng = np.random.default_rng(seed)
    kappa = 1.0 + d.settings.alpha * Ts
    out = {"Ts": Ts, "kappa": kappa}
    for sub, sd in zip(ts.subsystems, d.subsystems):
        S, Si = np.diag(sd.S), np.diag(1.0 / sd.S)
        Ns = [Si @ n @ S for n in sd.N]
        nv = len(Ns)
        Lc = np.linalg.cholesky(sd.P)
        Li = np.linalg.inv(Lc)
        worst_ratio, worst_margin = 0.0, np.inf
        etas = [np.eye(nv)[i] for i in range(nv)] + [rng.dirichlet(np.ones(nv)) for _ in range(samples)]
        for e in etas:
            N = sum(w * m for w, m in zip(e, Ns))
            G = np.eye(sub.n) - Ts * N
            Q = G.T @ sd.P @ G - kappa * sd.P
            worst_margin = min(worst_margin, float(np.linalg.eigvalsh(Li @ Q @ Li.T).min()))
            # V(e+)/V(e) = max eig of (G^-1)' P G^-1 in the P metric
            Gi = np.linalg.inv(G)
            R = Li @ (Gi.T @ sd.P @ Gi) @ Li.T
            worst_ratio = max(worst_ratio, float(np.linalg.eigvalsh(0.5 * (R + R.T)).max()))
        sym = min(float(np.linalg.eigvalsh(m + m.T).min()) for m in sd.M(Ts))
        if worst_margin < -1e-9 or worst_ratio >= 1.0:
            raise DiscretizationError(f"{sub.name}: the Ts = {Ts:g} s step does not contract (V ratio {worst_ratio:.6f}, "
                                      f"margin {worst_margin:.3e})")
        if sym <= 0:
            raise DiscretizationError(f"{sub.name}: M_i + M_i' is not positive definite ({sym:.3e}); unpivoted LU unsafe")
        out[sub.name] = {"max_V_ratio": worst_ratio, "contraction_per_step": float(np.sqrt(worst_ratio)),
                         "certified_contraction": float(1.0 / np.sqrt(kappa)), "min_margin": worst_margin,
                         "min_eig_M_sym": sym, "membership_samples": len(etas)}
    return out


# --- the step --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StepLayout:
    """Index bookkeeping of the step's vectors."""

    ts: icm.InterconnectedTS
    step: StepSettings

    @cached_property
    def measured(self) -> tuple:
        """Sensor outputs (inputs of the step), in model output order."""
        pseudo = {p for p, _ in self.step.derivative_outputs}
        return tuple(n for n in self.ts.definition.output_names if n not in pseudo)

    @cached_property
    def state_outputs(self) -> dict:
        """{output name: state symbol} for outputs that read one state directly."""
        out = {}
        for name, e in self.ts.definition.outputs:
            e = sp.sympify(e)
            if e in self.ts.definition.states:
                out[name] = e
        return out

    @cached_property
    def reconstructed(self) -> tuple:
        """Outputs that are not a plain state (a_x, a_y): re-computed from the estimates."""
        return tuple(n for n in self.ts.definition.output_names if n not in self.state_outputs)

    @cached_property
    def hosmd(self) -> tuple:
        return self.step.differentiators

    def z_names(self) -> list:
        names = [f"z_{s}" for sub in self.ts.subsystems for s in sub.states]
        for sig, spec in self.hosmd:
            names += [f"d{i}_{sig}" for i in range(spec.n_state)]
        return names + ["primed"]

    def output_names(self) -> list:
        return ([str(s) for s in self.ts.definition.states] + [str(u) for sub in self.ts.subsystems
                                                              for u in sub.unknown_inputs]
                + list(self.reconstructed))

    def state_names(self) -> list:
        return self.z_names() + self.output_names()


# [design] keys read by step_settings, not ICDesignSettings fields (checked by parse_settings in build)
STEP_KEYS = {"differentiators": Rule(dict, items=Rule(dict)), "derivative_outputs": Rule(dict, items=Rule(str)),
             "flag_outside_box": Rule(list, items=Rule(str)), "initial": Rule(dict, items=Rule(str))}
DIFFERENTIATOR_RULES = {"order": Rule(int, ge=1, le=MAX_ORDER), "lipschitz": Rule(float, gt=0)}


def step_settings(ts: icm.InterconnectedTS, design_table: dict, sample_time: float, source: str) -> StepSettings:
    outs = ts.definition.output_names
    diffs = []
    for sig, spec in sorted((design_table.get("differentiators") or {}).items()):
        if sig not in outs:
            raise ModelDefinitionError(f"{source}: differentiator for {sig!r}, which is not a model output")
        spec = parse_table(spec, DIFFERENTIATOR_RULES, source=source, section=f"design.differentiators.{sig}")
        diffs.append((sig, HosmdSpec(int(spec.get("order", 2)), float(spec.get("lipschitz", 1.0)), sample_time,
                                     name=f"hosmd_{sig}")))
    derived = []
    for name, src in sorted((design_table.get("derivative_outputs") or {}).items()):
        if name not in outs or src not in outs:
            raise ModelDefinitionError(f"{source}: derivative output {name} = d/dt {src}: both must be model outputs")
        derived.append((name, src))
    flags = tuple(design_table.get("flag_outside_box", ()))
    boxed = {str(s) for s in ts.state_box}
    for f in flags:
        if f not in outs or f not in boxed:
            raise ModelDefinitionError(f"{source}: flag_outside_box {f!r} must be a measured state with a box")
    init = []
    params = {str(p): p for p in ts.definition.parameters}
    for state, expr in sorted((design_table.get("initial") or {}).items()):
        e = sp.sympify(expr, locals={**params, **{o: sp.Symbol(o) for o in outs}})
        stray = {str(s) for s in e.free_symbols} - set(outs) - set(params)
        if stray:
            raise ModelDefinitionError(f"{source}: initial {state} = {expr} uses {sorted(stray)}")
        init.append((state, e.subs(ts.subs)))
    return StepSettings(tuple(diffs), tuple(derived), flags, tuple(init))


def _needed_derivatives(ts, d: ICDesign, layout: StepLayout) -> dict:
    """{output name: (signal, derivative order)} of the outputs whose derivative (30) uses."""
    diff = dict(layout.hosmd)
    derived = dict(layout.step.derivative_outputs)
    need = {}
    for sub, sd in zip(ts.subsystems, d.subsystems):
        for j, name in enumerate(sub.output_names):
            if np.any(sd.CBp[:, j] != 0):
                sig, order = (derived[name], 2) if name in derived else (name, 1)
                if sig not in diff or diff[sig].order < order:
                    raise ModelDefinitionError(f"(30) needs d/dt {name}: give a differentiator of {sig} of order "
                                               f">= {order}")
                need[name] = (sig, order)
    for name, src in derived.items():
        if src not in diff:
            raise ModelDefinitionError(f"derivative output {name} needs a differentiator of {src}")
    return need


class _Ops:
    """numpy / CasADi primitives for the shared step code."""

    def __init__(self, xp):
        self.xp = xp
        self.fmin = ca.fmin if xp is ca else min
        self.fmax = ca.fmax if xp is ca else max
        self.fabs = ca.fabs if xp is ca else abs


def _lambdas(layout: StepLayout, xp):
    """Compiled premise, coupling and initial-state functions."""
    ts = layout.ts
    mods = _CA_MODULES if xp is ca else "numpy"
    states = ts.definition.states
    exo = ts.definition.exogenous
    prem = []
    for sub in ts.subsystems:
        prem.append([sp.lambdify(states, sp.sympify(p.expr).subs(ts.switched), mods) for p in sub.premises])
    zeta = [[sp.lambdify((states, exo), c.expr, mods) for c in sub.coupling] for sub in ts.subsystems]
    outs = [sp.Symbol(n) for n in layout.measured]
    init = {state: sp.lambdify(outs, e, mods) for state, e in layout.step.initial}
    return prem, zeta, init


def step_parts(ts: icm.InterconnectedTS, d: ICDesign, layout: StepLayout, z, y, Ts: float, xp=np):
    """(z_next, outputs, excess, warmup) of one sample; numpy arrays or CasADi SX (``xp``).

    ``z`` = [UIO states (physical), differentiator states, primed, previous outputs];
    ``y`` = the measured outputs of :attr:`StepLayout.measured`.
    """
    ops = _Ops(xp)
    definition = ts.definition
    states = list(definition.states)
    ny_meas = len(layout.measured)
    nzs = sum(sub.n for sub in ts.subsystems)
    diffs = layout.hosmd
    nd = sum(spec.n_state for _, spec in diffs)
    primed = z[nzs + nd]
    prev_out = [z[nzs + nd + 1 + k] for k in range(len(layout.output_names()))]
    prem_fn, zeta_fn, init_fn = _lambdas(layout, xp)
    meas = {name: y[k] for k, name in enumerate(layout.measured)}
    # inputs outside their boxes: finite for finite inputs, kept apart from the estimate part (which
    # is NaN when absurd inputs overflow the step; fmax ignores NaN, so the input flag survives)
    excess_inputs = 0.0
    for name in layout.step.flag_outside_box:
        lo, hi = ts.state_box[sp.Symbol(name)]
        excess_inputs = excess_inputs + ops.fmax(0.0, ops.fmax(lo - meas[name], meas[name] - hi))
    excess = 0.0
    # differentiators: predictor values at this sample (state before the update), then the update
    dvals, dnext, off = {}, [], nzs
    for sig, spec in diffs:
        zi = [z[off + i] for i in range(spec.n_state)]
        first = [meas[sig]] + [0.0] * (spec.n_state - 1)
        zi = [primed * a + (1.0 - primed) * b for a, b in zip(zi, first)]
        dvals[sig] = zi
        if xp is ca:
            nxt = hosmd_step_sx(spec, ca.vertcat(*zi), meas[sig])
            dnext += [nxt[i] for i in range(spec.n_state)]
        else:
            dnext += list(hosmd_step_numpy(spec, np.array(zi, float), float(meas[sig])))
        off += spec.n_state
    yall = dict(meas)
    for name, src in layout.step.derivative_outputs:
        yall[name] = dvals[src][1]
    need = _needed_derivatives(ts, d, layout)
    ydot = {name: dvals[sig][order] for name, (sig, order) in need.items()}
    # previous estimates (for premises and coupling signals), or the start from this sample
    prev_x = dict(zip(states, prev_out[:len(states)]))
    init = {}
    for sub in ts.subsystems:
        for s in sub.states:
            name = next((n for n, st in layout.state_outputs.items() if st == s), None)
            init[s] = yall[name] if name is not None else 0.0
    for state, fn in init_fn.items():
        init[sp.Symbol(state)] = fn(*[meas[n] for n in layout.measured])
    for s in definition.scheduling_states:
        lo, hi = ts.state_box[s]
        init[s] = ops.fmin(ops.fmax(init[s], lo), hi)
    est = {s: primed * prev_x[s] + (1.0 - primed) * init[s] for s in states}
    z_next, x_hat, u_hat, zeta_hat = [], {}, [], {}
    zoff = 0
    for k, (sub, sd) in enumerate(zip(ts.subsystems, d.subsystems)):
        n = sub.n
        # premise values: scheduling states from the latest estimates (clamped), measured states measured
        vals = {}
        for s in states:
            name = next((nm for nm, st in layout.state_outputs.items() if st == s), None)
            vals[s] = yall[name] if name is not None else (x_hat[s] if s in x_hat else est[s])
        for s in definition.scheduling_states:
            lo, hi = ts.state_box[s]
            raw = vals[s]
            vals[s] = ops.fmin(ops.fmax(raw, lo), hi)
            excess = excess + ops.fabs(raw - vals[s])
        theta = []
        for p, fn in zip(sub.premises, prem_fn[k]):
            raw = fn(*[vals[s] for s in states])
            c = ops.fmin(ops.fmax(raw, p.lower), p.upper)
            excess = excess + ops.fabs(raw - c)
            theta.append(c)
        eta = (sector_weights_product(theta, sub.premises, xp=ca) if xp is ca
               else np.asarray(sector_weights_product(np.array(theta, float), sub.premises), float))
        zvals = {**vals, **{s: (x_hat.get(s, est[s]) if s not in layout.state_outputs.values() else vals[s])
                            for s in states}}
        zeta = [fn([zvals[s] for s in states], [ts.exogenous_nominal[e] for e in definition.exogenous])
                for fn in zeta_fn[k]]
        ysub = [yall[nm] for nm in sub.output_names]
        ytil = [ysub[j] - sum(sub.E[j, c] * zeta[c] for c in range(sub.nzeta) if sub.E[j, c] != 0)
                for j in range(sub.ny)]
        zk = [primed * z[zoff + i] + (1.0 - primed) * (init[s] + sum(sd.H[i, j] * ytil[j] for j in range(sub.ny)
                                                                    if sd.H[i, j] != 0))
              for i, s in enumerate(sub.states)]
        blend = _blender(eta, xp, theta, sub)
        L = blend(sd.L)
        G = blend(sd.G) if sub.nzeta else None
        rhs = []
        for i in range(n):
            acc = zk[i]
            for j in range(sub.ny):
                acc = acc + Ts * L[i][j] * ytil[j] if not _is_zero(L[i][j]) else acc
            for c in range(sub.nzeta):
                acc = acc + Ts * G[i][c] * zeta[c] if not _is_zero(G[i][c]) else acc
            rhs.append(acc)
        # scaled: M(eta) w = P S^-1 rhs, z+ = S w
        P = sd.P
        prhs = [sum(P[i, j] / sd.S[j] * rhs[j] for j in range(n)) for i in range(n)]
        M = blend(sd.M(Ts))
        if xp is ca:
            w = solve_unpivoted(ca.vertcat(*[ca.horzcat(*row) for row in M]), ca.vertcat(*prhs))
            znew = [sd.S[i] * w[i] for i in range(n)]
        else:
            w = np.linalg.solve(np.array(M, float), np.array(prhs, float))
            znew = list(sd.S * w)
        z_next += znew
        xs = [znew[i] - sum(sd.H[i, j] * ytil[j] for j in range(sub.ny) if sd.H[i, j] != 0) for i in range(n)]
        for s, v in zip(sub.states, xs):
            x_hat[s] = v
        # (30): u' = (CB)^+ (y' - C A(eta) x_hat - C D(eta) zeta)
        A = blend(sub.A)
        D = blend(sub.D) if sub.nzeta else None
        CA = [[sum(sub.C[r, m] * A[m][c] for m in range(n) if sub.C[r, m] != 0) for c in range(n)]
              for r in range(sub.ny)]
        resid = []
        for r, nm in enumerate(sub.output_names):
            if nm not in ydot:
                resid.append(None)
                continue
            acc = ydot[nm]
            for c in range(n):
                if not _is_zero(CA[r][c]):
                    acc = acc - CA[r][c] * xs[c]
            for c in range(sub.nzeta):
                cd = sum(sub.C[r, m] * D[m][c] for m in range(n) if sub.C[r, m] != 0)
                if not _is_zero(cd):
                    acc = acc - cd * zeta[c]
            resid.append(acc)
        for j, (u, g) in enumerate(zip(sub.unknown_inputs, sub.ui_scales)):
            up = sum(sd.CBp[j, r] * resid[r] for r in range(sub.ny) if sd.CBp[j, r] != 0)
            if g != 1:
                gval = sp.lambdify([s for s in states], g, _CA_MODULES if xp is ca else "numpy")(
                    *[vals[s] for s in states])
                up = up / gval
            u_hat.append(up)
        for c, sig in enumerate(sub.coupling):
            zeta_hat[sig.name] = zeta[c]
        zoff += n
    # reconstructed outputs (a_x, a_y): the model's output expressions at the estimates
    rec = []
    for name in layout.reconstructed:
        sub = next(s for s in ts.subsystems if name in s.output_names)
        j = sub.output_names.index(name)
        acc = sum(sub.C[j, i] * x_hat[s] for i, s in enumerate(sub.states) if sub.C[j, i] != 0)
        for c, sig in enumerate(sub.coupling):
            if sub.E[j, c] != 0:
                acc = acc + sub.E[j, c] * zeta_hat[sig.name]
        rec.append(acc)
    outputs = [x_hat[s] for s in states] + u_hat + rec
    z_new = z_next + dnext + [1.0] + outputs
    if xp is ca:
        excess = ca.fmax(excess_inputs, excess)
    else:
        excess = float(np.fmax(excess_inputs, excess))
    return z_new, outputs, excess, 1.0 - primed


def _is_zero(v) -> bool:
    if isinstance(v, (int, float, np.floating)):
        return v == 0
    if isinstance(v, ca.SX) and v.is_constant():
        return float(v) == 0.0
    return False


def _blender(eta, xp, theta=None, sub=None):
    """sum_i eta_i M_i entrywise; entries constant over the vertices stay constants. With ``theta``
    and in the CasADi step, vertex families that are affine in the premises are evaluated as
    V_0 + sum_k theta_k V_k (the same values, q + 1 terms instead of 2^q)."""
    def blend(mats):
        mats = np.asarray(mats, float)
        parts = affine_parts(sub, mats) if (xp is ca and sub is not None) else None
        if parts is not None:
            rows, cols = mats.shape[1], mats.shape[2]
            out = [[None] * cols for _ in range(rows)]
            for i in range(rows):
                for j in range(cols):
                    acc = float(parts[0][i, j])
                    for th, part in zip(theta, parts[1:]):
                        if part[i, j] != 0:
                            acc = acc + th * float(part[i, j])
                    out[i][j] = acc
            return out
        rows, cols = mats.shape[1], mats.shape[2]
        out = [[None] * cols for _ in range(rows)]
        for i in range(rows):
            for j in range(cols):
                col = mats[:, i, j]
                if np.all(col == col[0]):
                    out[i][j] = float(col[0])
                else:
                    acc = eta[0] * float(col[0])
                    for e, v in zip(eta[1:], col[1:]):
                        if v != 0:
                            acc = acc + e * float(v)
                    out[i][j] = acc
        return out
    return blend


def step_casadi(ts, d, layout: StepLayout, Ts: float, name: str) -> ca.Function:
    """(z, u, y, rho) -> (z_next, excess, warmup); u and rho are empty (no known inputs)."""
    nzs = len(layout.state_names())
    z = ca.SX.sym("z", nzs)
    u = ca.SX.sym("u", 0)
    y = ca.SX.sym("y", len(layout.measured))
    rho = ca.SX.sym("rho", 0)
    z_new, _, excess, warm = step_parts(ts, d, layout, [z[i] for i in range(nzs)],
                                        [y[i] for i in range(y.shape[0])], Ts, xp=ca)
    return ca.Function(name, [z, u, y, rho], [ca.vertcat(*z_new), excess, warm],
                       ["z", "u", "y", "rho"], ["z_next", "excess", "warmup"])


def step_numpy(ts, d, layout: StepLayout, Ts: float, z, y):
    """Reference step (numpy; pivoted solve, numpy differentiator): (z_next, excess, warmup)."""
    z = np.asarray(z, float)
    y = np.asarray(y, float)
    z_new, _, excess, warm = step_parts(ts, d, layout, list(z), list(y), Ts, xp=np)
    return np.array(z_new, float), float(excess), float(warm)


# --- the pipeline build -----------------------------------------------------------------------------

@dataclass(frozen=True)
class InterconnectedBuild:
    """Seed-003 observer: representation, design, certificates, step (the TSFuzzyBuild interface)."""

    config: object
    ts: icm.InterconnectedTS
    design: ICDesign
    layout: StepLayout
    certificate: dict
    discrete: dict
    timings: dict

    @property
    def name(self) -> str:
        return self.config.name

    def step_function(self) -> ca.Function:
        return step_casadi(self.ts, self.design, self.layout, self.config.sample_time, f"{self.name}_kernel")

    def step_numpy(self, z, u, y):
        return step_numpy(self.ts, self.design, self.layout, self.config.sample_time, z, y)

    def reference_step(self, z, u, y, rho):
        """Independent numpy step (tests, the benchmark's numpy peer)."""
        return self.step_numpy(z, u, y)

    def lmi_problem(self):
        """A fresh LMI problem of this design (benchmark: our path vs CVXPY on the same blocks)."""
        return build_problem(self.ts, self.design.settings)[0]

    @property
    def state_names(self) -> list:
        return self.layout.state_names()

    @property
    def output_names(self) -> list:
        return self.layout.output_names()

    @property
    def input_names(self) -> list:
        return [f"y_{n}" for n in self.layout.measured]

    @property
    def nu(self) -> int:
        return 0

    @property
    def ny(self) -> int:
        return len(self.layout.measured)

    def scheduling_boxes(self) -> list:
        import re
        out = []
        for sub in self.ts.subsystems:
            for p in sub.premises:
                label = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", str(p.expr).replace("/", "_over_"))).strip("_")
                out.append((f"{sub.name}_premise_{label}", p.lower, p.upper, True))
        return out

    def input_boxes(self) -> dict:
        return {f"y_{n}": list(self.ts.state_box[sp.Symbol(n)]) for n in self.layout.step.flag_outside_box}

    def signal_docs(self) -> tuple:
        units = self.ts.definition.units
        docs = {f"z_{s}": f"UIO state z of (17) for {s} [{units.get(str(s), '-')}]" for s in self.ts.definition.states}
        for sig, spec in self.layout.hosmd:
            for i in range(spec.n_state):
                docs[f"d{i}_{sig}"] = f"HOSMD of {sig}: derivative {i} (predictor at the next sample)"
        docs["primed"] = "1 once the first sample has initialized the estimate, else 0"
        outs = []
        for n in self.output_names:
            what = ("unknown input (30)" if n in [str(u) for u in self.ts.definition.unknown_inputs] else
                    "reconstructed output (sum of estimated forces)" if n in self.layout.reconstructed else "estimate")
            outs.append({"name": n, "doc": f"{what}: {n} [{units.get(n, '-')}]"})
        state = [{"name": n, "doc": docs[n]} for n in self.layout.z_names()] + outs
        inputs = [{"name": f"y_{n}", "doc": f"measured {n} [{units.get(n, '-')}]"} for n in self.layout.measured]
        return state, inputs, outs

    def emit_notes(self) -> dict:
        cert = self.certificate
        disc = self.discrete
        subs = [s.name for s in self.ts.subsystems]
        contraction = max(disc[s]["contraction_per_step"] for s in subs)
        return {
            "headline": "seed-003 LMIs (27) worst margin " + f"{cert['worst_min_eig']:.3g}, eta " +
                        ", ".join(f"{s} {cert[s]['eta']:.4g}" for s in subs),
            "stability": (f"backward Euler, common P per subsystem from (27): sqrt(V) contracts by "
                          f"<= {contraction:.6f} per step for every membership sequence (matched premises)"),
            "step_notes": [
                "Stages per call: differentiators (predictor values, then update), longitudinal UIO scheduled",
                "on the previous v_x estimate, lateral UIO scheduled on the new one, inversion (30).",
                "The state holds [z, differentiator states, primed, outputs]; the outputs are its last entries.",
            ],
            "clamp_doc": ("The v_x estimate or a premise outside its box (clamped for the memberships), or a measured\n"
                          " * wheel speed or steering angle outside its box: the certificate does not cover this sample."),
            "warmup_doc": ("the estimate and the differentiators start from this sample (v_x from the wheel\n"
                           " * speeds); the unknown-input estimates need a few samples of differentiator convergence."),
            "has_warmup": True,
        }

    def summary(self, path) -> dict:
        """What `uiogen design` prints."""
        subs = {}
        for sub, sd in zip(self.ts.subsystems, self.design.subsystems):
            subs[sub.name] = {
                "states": [str(s) for s in sub.states], "unknown_inputs": [str(u) for u in sub.unknown_inputs],
                "outputs": list(sub.output_names), "coupling_signals": [c.name for c in sub.coupling],
                "premises": [f"{p.expr} in [{p.lower:.6g}, {p.upper:.6g}]" for p in sub.premises],
                "vertices": sub.n_vertices, "eta": sd.eta,
                "error_poles_slowest": float(max(np.linalg.eigvals(n).real.max() for n in sd.N)),
                "error_poles_fastest": float(min(np.linalg.eigvals(n).real.min() for n in sd.N)),
                "discrete_contraction_per_step": self.discrete[sub.name]["contraction_per_step"]}
        sol = self.design.solution
        return {"observer": self.name, "artifact": str(path), "subsystems": subs,
                "lmi_blocks": len(sol.checks), "worst_block": self.certificate["worst_block"],
                "worst_min_eig": self.certificate["worst_min_eig"], "solve_time_s": sol.solve_time_s,
                "build_time_s": sol.build_time_s,
                "total_design_time_s": self.timings["representation_s"] + self.timings["design_s"],
                "certificates_time_s": self.timings["certificates_s"], "sample_time": self.config.sample_time}

    def summary_lines(self, s: dict) -> list:
        lines = [f"observer {self.name}: seed-003 interconnected LPV UIO, {len(s['subsystems'])} subsystems"]
        for name, d in s["subsystems"].items():
            lines += [f"  {name}: states {', '.join(d['states'])}; unknown inputs {', '.join(d['unknown_inputs'])}",
                      f"    outputs {', '.join(d['outputs'])}; coupling zeta_F {', '.join(d['coupling_signals'])}",
                      f"    premises {'; '.join(d['premises'])} ({d['vertices']} vertices)",
                      f"    eta {d['eta']:.6g}; error poles (vertices) {d['error_poles_fastest']:.1f} .. "
                      f"{d['error_poles_slowest']:.2f} 1/s; discrete step: sqrt(V) contracts by "
                      f"{d['discrete_contraction_per_step']:.6f}/step"]
        lines += [f"  LMIs (27)               {s['lmi_blocks']} blocks; worst re-checked margin "
                  f"{s['worst_min_eig']:.3e} in {s['worst_block']}",
                  f"  design time             {s['total_design_time_s']:.2f} s (derivation + LMIs; solve "
                  f"{1e3 * s['solve_time_s']:.0f} ms); certificates {s['certificates_time_s']:.2f} s",
                  f"artifact: {s['artifact']}"]
        return lines

    def artifact(self) -> dict:
        from ..pipeline import _sig, artifact_head, solver_certificate
        gains = {}
        for sd in self.design.subsystems:
            gains[sd.name] = {"H": sd.H.tolist(), "T": sd.T.tolist(), "S": sd.S.tolist(), "W": sd.W.tolist(),
                              "Z": sd.Z.tolist(), "P": sd.P.tolist(), "eta": sd.eta,
                              "Omega": [o.tolist() for o in sd.Omega], "CB_pinv": sd.CBp.tolist()}
        return {
            # the v_x estimate and the premises are flagged too, not only the inputs
            **artifact_head(self, [p.expr for sub in self.ts.subsystems for p in sub.premises],
                            flags_from_inputs_only=False),
            "ts_model": _sig(self.ts.to_json(), 12),
            "settings": {k: getattr(self.design.settings, k) for k in
                         ("alpha", "weight", "coupling_gain", "gain_bound", "margin", "tol")},
            "differentiators": {sig: {"order": s.order, "lipschitz": s.lipschitz, "gains": list(s.gains)}
                                for sig, s in self.layout.hosmd},
            "gains": _sig(gains, 12),
            "certificate": solver_certificate(self.design.solution, recheck=self.certificate, discrete=self.discrete),
        }


def build(config, tol: float | None = None) -> InterconnectedBuild:
    """Seed 003: model -> interconnected T-S form -> (16), (26), LMIs (27), (28) -> certificates -> step."""
    table = dict(config.design)
    settings = parse_settings(ICDesignSettings, table, source=config.source, section="design", extra=STEP_KEYS,
                              **({"tol": tol} if tol is not None else {}))
    t0 = time.perf_counter()
    ts = icm.load(config.model, config.parameter_path)
    step = step_settings(ts, table, config.sample_time, config.source)
    layout = StepLayout(ts, step)
    t1 = time.perf_counter()
    d = design(ts, settings)
    _needed_derivatives(ts, d, layout)
    t2 = time.perf_counter()
    cert = certify(ts, d)
    disc = discrete_certificate(ts, d, config.sample_time)
    t3 = time.perf_counter()
    timings = {"representation_s": t1 - t0, "design_s": t2 - t1, "solve_s": d.solution.solve_time_s,
               "build_s": d.solution.build_time_s, "certificates_s": t3 - t2}
    return InterconnectedBuild(config, ts, d, layout, cert, disc, timings)
