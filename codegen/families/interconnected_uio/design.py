"""Two-stage interconnected LPV unknown-input observer of Sentouh et al. 2023 (NI-UIO), Sec. 4.

Per subsystem (longitudinal bar, lateral check) of the T-S model (8) built by
:mod:`codegen.families.interconnected_uio.representation`:

* decoupling (26): H = -B (C B)^+, after the matching condition (16) rank(CB) = rank(B);
  T = I + H C (B, C constant: see that module for the kappa' = v_x kappa input), so T' = 0;
* the ISS LMIs (27b), (27d), (27e) at every vertex i with a common P per subsystem, one
  problem for both subsystems with the weighted objective a eta_1 + (1 - a) eta_2 (27a);
* gains (28): K_i = P^-1 Omega_i, N_i = Gamma_i - K_i C, L_i = K_i - N_i H, G_i = T D_i;
* the observer (17): z' = N(eta) z + L(eta) y~ + G(eta) zeta_hat, x_hat = z - H y~,
  with y~ = y - E zeta_hat (output feedthrough of the coupling signals);
* the unknown inputs by the algebraic inversion (30),
  u'_hat = (C B)^+ (y'_hat - C A(eta) x_hat - C D(eta) zeta_hat), y'_hat from Levant
  differentiators (:mod:`codegen.representation.differentiators`), kappa = kappa'/v_x.

Choices the paper leaves open (all here, and in the README's Sentouh et al. 2023 section):

1. *T_eta'* (20): B and C are constant after the kappa' substitution, so H, T are constant
   and T' = 0 exactly; no T' term is dropped.
2. *Matching (16) for the lateral subsystem.* With the printed outputs [r, psi_L, y_L, a_y, delta]
   T_s has relative degree 2 (it reaches delta''), so rank(CB) = 1 < rank(B) = 2 and no UIO
   exists. We add delta_dot to the lateral outputs, taken from the HOSMD of delta
   (``derivative_outputs`` of the configuration); the paper's own HOSMD makes it available.
3. *Coordinates.* Forces (N) and speeds (m/s) differ by 10^4 and Clarabel fails on the raw
   problem, so the LMIs are posed in scaled coordinates x_s = S^-1 x, y_s = W^-1 y (each row of
   C S of unit largest entry) and zeta_s = Z^-1 zeta (each column of S^-1 T D of unit largest
   entry). S starts from the state box and is refined by diagonal balancing (LAPACK gebal) of the
   box-scaled mean |A_i| + I: the box alone puts v_x and the wheel speeds on a scale where one unit
   of slip-velocity error is ~10^3 units of force error, and P then needs eigenvalues ~10^4 that
   Clarabel cannot resolve. All scales are powers of two (exact). P >= I, eta, the weight g I and
   the gain bound are read in these units.
4. *Gain bound.* (27) does not bound the gains; Omega_i' P^-1 Omega_i <= ell^2 I is added (an LMI by
   Schur), which with P >= I gives ||K_i|| <= ell in scaled coordinates, like the Nguyen et al. 2019
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
   step's cost. It restricts the paper's free Omega_i; ``gain_structure = "vertex"`` is the
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

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from . import representation as icm
from ...errors import CertificateError, DiscretizationError, ModelDefinitionError, RankConditionError
from ...design.lmi import LMIProblem, LMISolution, bmat, check_blocks, uncertified, worst_block
from ...settings import setting
from ...design.precision import margin_field, precision_field
from ...representation import canonical
from ...representation.canonical import decimal_round

FAMILY = "interconnected_uio"


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
    precision: str = precision_field()
    float32_margin: float = margin_field()

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
        # emitted: exact arithmetic (codegen.representation.canonical); S is diagonal, so S^-1 N S is exact as it is
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
    CB = canonical.matmul(sub.C, sub.B)      # (26)-(30) are emitted: exact arithmetic (codegen.representation.canonical)
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
    :mod:`codegen.design.lmi` (the problem). (27d) and the gain bound are added by the caller."""
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


def decay_bound(ts: icm.InterconnectedTS, settings: ICDesignSettings) -> tuple:
    """(bound, subsystem name, vertex): no alpha >= bound satisfies (27b) with the gain bound ||K_i|| <= ell.

    The state block of (27b) at vertex i is Gamma' P + P Gamma - C_s' Omega' - Omega C_s + alpha P < 0; its
    trace in the P metric, with K = P^-1 Omega, is 2 tr(Gamma) - 2 tr(K C_s) + n alpha < 0, and
    |tr(K C_s)| <= ||K||_2 ||C_s||_* <= ell ||C_s||_* (the gain bound with (27e) P >= I), all in the scaled
    coordinates of :func:`build_problem`: hence alpha < 2 (ell ||C_s||_* - tr Gamma) / n."""
    best = (np.inf, "", 0)
    for sub in ts.subsystems:
        S, W, _ = scaling(ts, sub)
        H, T, CBp = decoupling(sub, W, mode=settings.decoupling)
        S, W, Z = scaling(ts, sub, T)
        Cs = np.diag(1.0 / W) @ sub.C @ np.diag(S)
        nuc = float(np.linalg.norm(Cs, "nuc"))
        for i in range(sub.n_vertices):
            gam = np.diag(1.0 / S) @ T @ sub.A[i] @ np.diag(S)
            bound = 2.0 * (settings.gain_bound * nuc - float(np.trace(gam))) / sub.n
            if bound < best[0]:
                best = (bound, sub.name, i)
    return best


def build_problem(ts: icm.InterconnectedTS, settings: ICDesignSettings):
    prob = LMIProblem(f"{ts.definition.name}: Sentouh et al. 2023 Theorem 1")
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


def design(ts: icm.InterconnectedTS, settings: ICDesignSettings, solver) -> ICDesign:
    """Theorem 1: (26), LMIs (27) by ``solver`` (:mod:`codegen.design.solver`), rounded, gains (28)."""
    prob, parts = build_problem(ts, settings)
    sol = solver.solve(prob, tol=settings.tol)
    designs = []
    for sub, H, T, CBp, S, W, Z in parts:
        P = decimal_round(0.5 * (sol[f"P_{sub.name}"] + sol[f"P_{sub.name}"].T))
        if settings.gain_structure == "affine":
            aff = [decimal_round(np.atleast_2d(sol[f"Omega_{sub.name}_affine_{k}"]).reshape(sub.n, sub.ny))
                   for k in range(len(sub.premises) + 1)]
            Om = tuple(aff[0] + sum(th * a for th, a in zip(theta, aff[1:])) for theta in vertex_premises(sub))
        else:
            Om = tuple(decimal_round(np.atleast_2d(sol[f"Omega_{sub.name}_{i + 1}"]).reshape(sub.n, sub.ny))
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
    # the emitted gains (28): exact arithmetic (codegen.representation.canonical), the same on every machine
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
        worst = worst_block(checks, "min_eig")
        failed = uncertified(checks)
        if failed is not None:
            raise CertificateError(f"Sentouh et al. 2023 LMI {failed.label!r} fails the numpy re-check on the emitted matrices: "
                                   f"{failed.failure()}")
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
