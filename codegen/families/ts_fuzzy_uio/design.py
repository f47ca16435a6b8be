"""Discrete-time TS fuzzy UIO with unmeasured nonlinear consequents, Nguyen et al. 2021 Theorem 1.

Observer (16):  zeta+ = T Phi_hat + L(h)(y - C x_hat),  x_hat = zeta + N y,
                d_hat_k = (C D)^+ (y_{k+1} - C Phi_hat_k),
with Phi_hat = A(h) x_hat + f(xi, u) + G(h) phi(x_hat, u) and L(h) = M(h)^-1 L(h) (eq. (28)).

Design (Algorithm 1): the rank conditions (15) are checked, [T N] comes from (30), and the
LMIs (27) are imposed for every i, j, l and every vertex theta_p of the DMVT set V_phi (Lemma 3
relaxation). Two choices the paper leaves open, both documented in the README:

* (30) has the free matrix Y; we take Y = 0 (the minimum-norm solution). When the matrix of
  (29) is square and invertible, as for Nguyen et al. 2021, the solution is unique anyway.
* (27) has a block for every rule triple (i, j, l): l indexes P(h_{k+1}) = sum h_l+ P_l. Past the
  size guard's limits (:func:`size_guard`, ``[design] relaxation = "auto"``) the blocks are
  imposed with one bound P_bar >= P_l for every l in place of P_l (``"pairs"``): N^2 blocks
  instead of N^3, a sufficient condition (the (2,2) block with -P_bar is below the one with
  -P(h+) for every h+), so the certificate keeps its meaning.
* (27) is a strict feasibility problem, homogeneous in (P_i, M_i, L_i). We normalize P_i >= I,
  impose every block >= margin I (so the numpy re-check has slack) and minimize sum trace(P_i),
  which keeps the Lyapunov matrices, and with them the gains, from growing without need.
  ``decay`` (lambda <= 1) optionally replaces P_j by lambda^2 P_j in the (1,1) block, which
  certifies V_{k+1} <= lambda^2 V_k instead of V_{k+1} < V_k; 1 is the paper's (27).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...errors import CertificateError, ConfigurationError, RankConditionError, RepresentationError
from ...emit.stepgen import solve_unpivoted
from ...design.lmi import LMIProblem, LMISolution, bmat, check_blocks, trace, uncertified, worst_block
from ...representation.polytope import sector_weights_product
from ...settings import setting
from ...design.precision import margin_field, precision_field
from .representation import TSFuzzyModel
from ...representation import canonical
from ...representation.canonical import decimal_round


@dataclass(frozen=True)
class TSDesignSettings:
    """Tuning of a Nguyen et al. 2021 Theorem-1 design.

    Attributes
    ----------
    decay : float
        lambda in (0, 1]: certified V_{k+1} <= lambda^2 V_k (1 = the paper's strict decrease).
    margin : float
        Every LMI block >= margin I.
    tol : float
        Clarabel gap/feasibility tolerance.
    relaxation : {"auto", "triples", "pairs"}
        The blocks of (27): the paper's rule triples (N^3 per DMVT vertex), rule pairs with a
        common bound of the next Lyapunov matrix (N^2), or "auto": triples when they pass the size
        guard, else pairs.
    bounds_rel_tol, bounds_max_boxes : float, int
        Accuracy of the sound Jacobian bounds (relative to the attained values) and the budget of
        boxes their branch-and-bound may split (:func:`codegen.representation.bounds.range_bound`).
        A bound short of its accuracy when the budget is spent is the sound enclosure reached (a
        larger DMVT box), stated with its gap in the artifact and the certificate, not a refusal.
    max_lmi_blocks, max_memory_gb : int, float
        Size guards, checked before any LMI is built (:func:`size_guard`): the number of blocks
        of (27) and the memory their coefficients need.
    """

    decay: float = setting(1.0, gt=0, le=1, doc="lambda: V_{k+1} <= lambda^2 V_k")
    margin: float = setting(1e-4, ge=0)
    tol: float = setting(1e-8, gt=0)
    bounds_rel_tol: float = setting(1e-3, gt=0, le=1, doc="accuracy of the Jacobian bounds")
    bounds_max_boxes: int = setting(20000, gt=0, doc="boxes the bound refinement may split (then: the sound "
                                                     "enclosure reached, its gap stated)")
    max_lmi_blocks: int = setting(50000, gt=0, doc="largest number of LMI blocks of (27) to build")
    max_memory_gb: float = setting(4.0, gt=0, doc="largest memory the LMI coefficients may take")
    relaxation: str = setting("auto", choices=("auto", "triples", "pairs"), doc="blocks of (27)")
    precision: str = precision_field()
    float32_margin: float = margin_field()

    def __post_init__(self):
        if not 0 < self.decay <= 1:
            raise ConfigurationError(f"decay must be in (0, 1], got {self.decay}")
        if not self.margin >= 0 or not self.tol > 0:
            raise ConfigurationError("margin must be >= 0 and tol > 0")


def decoupling_matrices(ts: TSFuzzyModel, rank_tol: float = 1e-9) -> tuple:
    """(T, N) of eq. (30) with Y = 0, after the rank conditions (15a)-(15b).

    Raises
    ------
    RankConditionError
        naming the condition that fails and the ranks found.
    """
    C, D, nx, nd = ts.C, ts.D, ts.nx, ts.nd
    r_cd, r_d = np.linalg.matrix_rank(C @ D, tol=rank_tol), np.linalg.matrix_rank(D, tol=rank_tol)
    if r_cd != r_d:
        raise RankConditionError(
            f"rank condition (15a) fails: rank(CD) = {r_cd} != rank(D) = {r_d}; some unknown input does "
            f"not reach the measured outputs in one step, so (16c) cannot reconstruct it")
    Xi = np.block([[np.eye(nx), D], [C, np.zeros((C.shape[0], nd))]])
    r_xi = np.linalg.matrix_rank(Xi, tol=rank_tol)
    if r_xi != nx + nd:
        raise RankConditionError(
            f"rank condition (15b) fails: rank [[I, D], [C, 0]] = {r_xi} < n_x + n_d = {nx + nd}; "
            f"T D = 0 and T + N C = I have no common solution")
    TN = canonical.pinv(Xi)[:nx]     # [I 0] pinv(Xi); emitted, so machine-independent
    # entries that are round-off of the pseudo-inverse (|.| < 1e-13 max) are exact zeros
    TN[np.abs(TN) < 1e-13 * np.abs(TN).max()] = 0.0
    T, N = TN[:, :nx], TN[:, nx:]
    residual = max(np.abs(T @ D).max(), np.abs(T + N @ C - np.eye(nx)).max())
    if residual > 1e-9:
        raise RankConditionError(f"(17)/(20) residual {residual:.3g} after (30): the decoupling is not exact")
    return T, N


def problem_size(n_rules: int, nx: int, ny: int, dmvt_vertices: int, relaxation: str) -> dict:
    """Counts of (27) under a relaxation: blocks, variables and the memory of their coefficients.

    Triples: V N^3 blocks (27a for every (p, l, i), 27b for every (p, l, i, j != i)); pairs: V N^2
    and N for P_bar >= P_l. Each is 2 n_x square (n_x for the bounds), with coefficients over
    N (n_x(n_x+1)/2 + n_x^2 + n_x n_y) variables (+ n_x(n_x+1)/2 for P_bar): the memory is that
    of their dense coefficient arrays (and a few copies of them while the blocks are formed).
    """
    n_var = n_rules * (nx * (nx + 1) // 2 + nx * nx + nx * ny) + (nx * (nx + 1) // 2 if relaxation == "pairs" else 0)
    k = 2 * nx
    big = dmvt_vertices * (n_rules ** 3 if relaxation == "triples" else n_rules ** 2)
    blocks = big + n_rules + (n_rules if relaxation == "pairs" else 0)
    memory_gb = 4.0 * big * k * k * n_var * 8 / 1e9    # measured: 3.4 GB peak for an estimated 3.2 (32 rules, pairs)
    return {"relaxation": relaxation, "rules": n_rules, "dmvt_vertices": dmvt_vertices, "lmi_blocks": blocks,
            "variables": n_var, "memory_gb": memory_gb}


def size_guard(n_rules: int, nx: int, ny: int, dmvt_vertices: int, settings: TSDesignSettings,
               source: str = "") -> dict:
    """The counts of (27) before it is built (:func:`problem_size`), under the configured
    relaxation ("auto": the paper's triples if they fit the limits, else pairs); refused past
    the settings' limits with the counts and the options."""
    tried = []
    for relaxation in (("triples", "pairs") if settings.relaxation == "auto" else (settings.relaxation,)):
        counts = problem_size(n_rules, nx, ny, dmvt_vertices, relaxation)
        if counts["lmi_blocks"] <= settings.max_lmi_blocks and counts["memory_gb"] <= settings.max_memory_gb:
            return counts
        tried.append(counts)
    what = "; ".join(f"{c['relaxation']}: {c['lmi_blocks']} LMI blocks over {c['variables']} variables, about "
                     f"{c['memory_gb']:.3g} GB" for c in tried)
    raise RepresentationError(
        f"{source}: the TS design would need {n_rules} rules x {dmvt_vertices} DMVT vertices, blocks of size "
        f"{2 * nx} ({what}); limits: [design] max_lmi_blocks = {settings.max_lmi_blocks}, max_memory_gb = "
        f"{settings.max_memory_gb:g}. Options: fewer premises (each one doubles the rules; measure a signal, or "
        f"move a nonlinearity into the unmeasured consequents phi, whose Jacobian bounds add DMVT vertices "
        f"instead of rules), a smaller state box, or raise the limits")


def _blocks(ts: TSFuzzyModel, T, P, M, L, decay, xp, P_bar=None):
    """All blocks of (27a)-(27b) as (label, matrix): numbers (``xp`` numpy, the re-check) or
    Affine decision matrices of :mod:`codegen.design.lmi` (the problem). With ``P_bar`` the pair
    relaxation: P_bar in place of every P_l, and P_bar >= P_l."""
    N = ts.n_rules
    cat = np.block if xp is np else bmat
    nxt = (lambda l: P[l]) if P_bar is None else (lambda l: P_bar)

    def phi(i, j, l, theta):
        off = M[j] @ (T @ ts.A_theta(i, theta)) - L[j] @ ts.C
        return cat([[decay ** 2 * P[j], off.T], [off, M[j] + M[j].T - nxt(l)]])

    out = []
    if P_bar is not None:
        out += [(f"P_bar >= P{l + 1}", P_bar - P[l]) for l in range(N)]
        for p, theta in enumerate(ts.theta_vertices):
            for i in range(N):
                out.append((f"(27a) i={i + 1} theta_{p + 1} (pairs)", phi(i, i, 0, theta)))
                for j in range(N):
                    if j != i:
                        out.append((f"(27b) i={i + 1} j={j + 1} theta_{p + 1} (pairs)",
                                    (2.0 / (N - 1)) * phi(i, i, 0, theta) + phi(i, j, 0, theta)
                                    + phi(j, i, 0, theta)))
        return out
    for p, theta in enumerate(ts.theta_vertices):
        for l in range(N):
            for i in range(N):
                out.append((f"(27a) i={i + 1} l={l + 1} theta_{p + 1}", phi(i, i, l, theta)))
                for j in range(N):
                    if j != i:
                        out.append((f"(27b) i={i + 1} j={j + 1} l={l + 1} theta_{p + 1}",
                                    (2.0 / (N - 1)) * phi(i, i, l, theta) + phi(i, j, l, theta)
                                    + phi(j, i, l, theta)))
    return out


@dataclass(frozen=True)
class TSDesign:
    """Decision matrices of (27), the decoupling matrices and the solver record."""

    settings: TSDesignSettings
    T: np.ndarray
    N: np.ndarray
    P: tuple
    M: tuple
    L: tuple
    solution: LMISolution | None
    P_bar: np.ndarray | None = None      # the pair relaxation's bound of every P_l (None: triples)

    @property
    def relaxation(self) -> str:
        return "triples" if self.P_bar is None else "pairs"

    def gain_at(self, h) -> np.ndarray:
        """L(h) = M(h)^-1 L(h) (eq. (28))."""
        Mh = sum(w * m for w, m in zip(h, self.M))
        Lh = sum(w * l for w, l in zip(h, self.L))
        return np.linalg.solve(Mh, Lh)

    def gains_json(self) -> dict:
        out = {"T": self.T.tolist(), "N": self.N.tolist(), "decay": self.settings.decay}
        for i, (p, m, l) in enumerate(zip(self.P, self.M, self.L)):
            out.update({f"P{i + 1}": p.tolist(), f"M{i + 1}": m.tolist(), f"L{i + 1}": l.tolist()})
        if self.P_bar is not None:
            out.update({"relaxation": "pairs", "P_bar": self.P_bar.tolist()})
        return out


def build_problem(ts: TSFuzzyModel, T: np.ndarray, settings: TSDesignSettings, relaxation: str = "triples"):
    pairs = relaxation == "pairs"
    prob = LMIProblem(f"{ts.definition.name}: Nguyen et al. 2021 Theorem 1" + (" (pair relaxation)" if pairs else ""))
    nx, ny, N = ts.nx, ts.ny, ts.n_rules
    P = [prob.symmetric(f"P{i + 1}", nx) for i in range(N)]
    M = [prob.matrix(f"M{i + 1}", nx, nx) for i in range(N)]
    L = [prob.matrix(f"L{i + 1}", nx, ny) for i in range(N)]
    P_bar = prob.symmetric("P_bar", nx) if pairs else None
    for i in range(N):
        # normalization of the homogeneous (27); the re-check sees P_i itself (slack 1)
        prob.require_psd(f"P{i + 1} >= I", P[i], margin=1.0)
    for label, block in _blocks(ts, T, P, M, L, settings.decay, LMIProblem, P_bar):
        prob.require_psd(label, block, margin=settings.margin,
                         hint="the DMVT box or the premise ranges may be too wide for this sample time")
    prob.minimize(sum(trace(p) for p in P))
    return prob


def design(ts: TSFuzzyModel, settings: TSDesignSettings, solver) -> TSDesign:
    """Algorithm 1: rank conditions, (30), LMIs (27) by ``solver`` (:mod:`codegen.design.solver`),
    rounded and re-certified."""
    T, N = decoupling_matrices(ts)
    size = size_guard(ts.n_rules, ts.nx, ts.ny, int(ts.theta_vertices.shape[0]), settings, ts.definition.name)
    prob = build_problem(ts, T, settings, size["relaxation"])
    sol = solver.solve(prob, tol=settings.tol)
    n = ts.n_rules
    P = tuple(decimal_round(0.5 * (sol[f"P{i + 1}"] + sol[f"P{i + 1}"].T)) for i in range(n))
    M = tuple(decimal_round(sol[f"M{i + 1}"]) for i in range(n))
    L = tuple(decimal_round(np.atleast_2d(sol[f"L{i + 1}"]).reshape(ts.nx, ts.ny)) for i in range(n))
    P_bar = decimal_round(0.5 * (sol["P_bar"] + sol["P_bar"].T)) if size["relaxation"] == "pairs" else None
    return TSDesign(settings, T, N, P, M, L, sol, P_bar)


def certify(ts: TSFuzzyModel, d: TSDesign) -> dict:
    """Independent numpy check of (27) on the emitted (rounded) matrices; no solver involved."""
    checks = check_blocks({f"P{i + 1} > 0": p for i, p in enumerate(d.P)})
    checks += check_blocks(dict(_blocks(ts, d.T, d.P, d.M, d.L, d.settings.decay, np, d.P_bar)))
    worst = worst_block(checks, "min_eig")
    failed = uncertified(checks)
    if failed is not None:
        raise CertificateError(f"Nguyen et al. 2021 LMI {failed.label!r} fails the numpy re-check on the emitted "
                               f"matrices: {failed.failure()}")
    return {"blocks": len(checks), "worst_block": worst.label, "worst_min_eig": worst.min_eig,
            "worst_relative_margin": worst.relative_margin}


def certified_decay(ts: TSFuzzyModel, d: TSDesign, iterations: int = 40) -> float:
    """The smallest lambda at which the committed matrices pass every block of (27) (numpy, the
    re-check of :func:`certify` with lambda^2 P in the (1,1) blocks): V(e+) <= lambda^2 V(e) is
    proven at it. Bisection; the design's own ``decay`` passes by :func:`certify`."""
    def passes(lam):
        blocks = dict(_blocks(ts, d.T, d.P, d.M, d.L, lam, np, d.P_bar))
        return min(float(np.linalg.eigvalsh(0.5 * (b + b.T)).min()) for b in blocks.values()) > 0
    lo, hi = 0.0, float(d.settings.decay)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if passes(mid) else (mid, hi)
    return hi


def lyapunov_decrease(ts: TSFuzzyModel, d: TSDesign, samples: int = 20000, seed: int = 0) -> dict:
    """Re-check (33) numerically: max over random (h, h+, theta) of V(e+)/V(e).

    h and h+ are drawn both as memberships of random premise values and as random points of
    the simplex (Lemma 3 covers every h in it); theta uniformly in the Jacobian box S_phi.
    All samples are drawn first (in the order of the former per-sample loop) and evaluated as
    one batch of small matrices.
    """
    rng = np.random.default_rng(seed)
    N = ts.n_rules
    box = ts.theta_box
    H, HP, TH = [], [], []
    for k in range(samples):
        if k % 2:
            h, hp = rng.dirichlet(np.ones(N)), rng.dirichlet(np.ones(N))
        else:
            xi = [rng.uniform(p.lower, p.upper, 2) for p in ts.premises]
            h = np.asarray(sector_weights_product(np.array([x[0] for x in xi]), ts.premises))
            hp = np.asarray(sector_weights_product(np.array([x[1] for x in xi]), ts.premises))
        H.append(h)
        HP.append(hp)
        TH.append(rng.uniform(box[:, :, 0], box[:, :, 1]))
    H, HP, TH = np.array(H), np.array(HP), np.array(TH)             # (S, N), (S, N), (S, nphi, nx)
    A = np.einsum("si,ijk->sjk", H, np.asarray(ts.A)) + np.einsum("si,ijl,slk->sjk", H, np.asarray(ts.G), TH)
    Mh = np.einsum("si,ijk->sjk", H, np.asarray(d.M))
    Lh = np.einsum("si,ijk->sjk", H, np.asarray(d.L))
    Acl = np.einsum("jk,skl->sjl", d.T, A) - np.linalg.solve(Mh, Lh) @ ts.C
    Ph = np.einsum("si,ijk->sjk", H, np.asarray(d.P))
    Pp = np.einsum("si,ijk->sjk", HP, np.asarray(d.P))
    Li = np.linalg.inv(np.linalg.cholesky(Ph))
    S = Li @ np.swapaxes(Acl, 1, 2) @ Pp @ Acl @ np.swapaxes(Li, 1, 2)
    worst = float(np.linalg.eigvalsh(0.5 * (S + np.swapaxes(S, 1, 2))).max())
    if worst >= 1.0:
        raise CertificateError(f"(33) fails on a sample: V(e+)/V(e) reaches {worst:.6f} >= 1")
    return {"samples": samples, "max_ratio": worst, "contraction_per_step": float(np.sqrt(worst))}


# --- the discrete step (16) ------------------------------------------------------------------------
#
# One call consumes y_{k+1} and returns x_hat_{k+1} and d_hat_k: (16c) needs the *next* output, so
# the unknown-input estimate is one sample behind the state estimate. The step's state is
# [zeta_k, y_k, primed]; the first call (primed = 0) has no y_k yet and uses y_{k+1} in its place
# (flagged as warm-up).

def step_parts(ts: TSFuzzyModel, d: TSDesign, zeta, y_k, y_next, u, xp=np):
    """(zeta_next, x_hat_next, d_hat_k, excess) of (16) on numpy arrays or CasADi SX.

    The two branches are kept apart on purpose: the numpy one is the independent reference of the
    portability tests (pivoted LAPACK solve, dense blends), the CasADi one is what becomes C
    (constant matrices folded, unrolled unpivoted elimination).

    Measured values are clamped to D_x for the model (the certificate only holds there);
    ``excess`` sums how far they (at k and k+1), and the unmeasured estimates, lie outside D_x.
    """
    # numpy: compiled once per model (the reference step runs per sample); CasADi: traced once
    f_fn, prem_fn, phi_fn = ts.numpy_functions if xp is np else ts.functions(ca)
    fmin, fmax, fabs = (ca.fmin, ca.fmax, ca.fabs) if xp is ca else (min, max, abs)
    nx, ny = ts.nx, ts.ny
    meas = [y_k[k] for k in range(ny)]
    clamped = [fmin(fmax(v, ts.state_box[s][0]), ts.state_box[s][1]) for v, s in zip(meas, ts.measured)]
    # both samples are checked: y_{k+1} is flagged when it arrives, not one call later
    excess = sum(fabs(v - c) for v, c in zip(meas, clamped))
    for k, s in enumerate(ts.measured):
        lo, hi = ts.state_box[s]
        excess = excess + fmax(0.0, fmax(lo - y_next[k], y_next[k] - hi))
    uu = [u[k] for k in range(len(ts.definition.known_inputs))]
    xi = [p(*clamped, *uu) for p in prem_fn]
    h = sector_weights_product(np.array(xi, float), ts.premises) if xp is np else \
        sector_weights_product(xi, ts.premises, xp=ca)
    N, T = d.N, d.T
    if xp is np:
        x_hat = zeta + N @ y_k
        A = sum(w * a for w, a in zip(h, ts.A))
        G = sum(w * g for w, g in zip(h, ts.G))
        full = dict(zip(ts.measured, clamped))
        x_for_phi = [full.get(s, x_hat[k]) for k, s in enumerate(ts.definition.states)]
        phi = np.array([p(*x_for_phi, *uu) for p in phi_fn], dtype=float)
        f = np.array([fn(*clamped, *uu) for fn in f_fn], dtype=float)
        Phi = A @ x_hat + f + G @ phi
        Mh = sum(w * m for w, m in zip(h, d.M))
        Lh = sum(w * l for w, l in zip(h, d.L))
        zeta_next = T @ Phi + np.linalg.solve(Mh, Lh @ (y_k - ts.C @ x_hat))
        d_hat = ts.CD_pinv @ (y_next - ts.C @ Phi)
        x_next = zeta_next + N @ y_next
    else:
        blend = (lambda mats: ca.DM(mats[0]) if np.ptp(mats, axis=0).max(initial=0) == 0
                 else sum((w * ca.DM(m) for w, m in zip(h[1:], mats[1:])), h[0] * ca.DM(mats[0])))
        x_hat = zeta + ca.DM(N) @ y_k
        full = dict(zip(ts.measured, clamped))
        x_for_phi = [full.get(s, x_hat[k]) for k, s in enumerate(ts.definition.states)]
        phi = ca.vertcat(*[p(*x_for_phi, *uu) for p in phi_fn]) if phi_fn else ca.SX(0, 1)
        f = ca.vertcat(*[fn(*clamped, *uu) for fn in f_fn])
        Phi = blend(ts.A) @ x_hat + f + (blend(ts.G) @ phi if phi_fn else 0)
        innovation = blend(d.L) @ (y_k - ca.DM(ts.C) @ x_hat)
        # M(h) + M(h)' > P(h+) > 0 by (27): unpivoted elimination is safe (no zero pivot)
        zeta_next = ca.DM(T) @ Phi + solve_unpivoted(blend(d.M), innovation, tail=0)
        d_hat = ca.DM(ts.CD_pinv) @ (y_next - ca.DM(ts.C) @ Phi)
        x_next = zeta_next + ca.DM(N) @ y_next
    for k, s in enumerate(ts.definition.states):
        if s in ts.unmeasured:
            lo, hi = ts.state_box[s]
            excess = excess + fmax(0.0, fmax(lo - x_hat[k], x_hat[k] - hi))
    return zeta_next, x_next, d_hat, excess


def state_layout(ts: TSFuzzyModel) -> list:
    """Names of the step's state vector: [zeta, y_prev, primed, x_hat, d_hat]; the last
    n_x + n_d entries are the outputs (kept in the state so a held sample repeats them)."""
    d = ts.definition
    return ([f"zeta_{s}" for s in d.states] + [f"y_prev_{n}" for n in d.output_names] + ["primed"]
            + [str(s) for s in d.states] + [str(s) for s in d.unknown_inputs])


def step_casadi(ts: TSFuzzyModel, d: TSDesign, name: str) -> ca.Function:
    """(z, u, y, rho) -> (z_next, excess, warmup) with z = [zeta; y_prev; primed; x_hat; d_hat]
    (see :func:`state_layout`); ``rho`` is empty (the premises are measured states)."""
    nx, ny, nd, nu = ts.nx, ts.ny, ts.nd, len(ts.definition.known_inputs)
    z = ca.SX.sym("z", nx + ny + 1 + nx + nd)
    u = ca.SX.sym("u", nu)
    y = ca.SX.sym("y", ny)
    rho = ca.SX.sym("rho", 0)
    primed = z[nx + ny]
    # primed is exactly 0 or 1 and both outputs are finite (the C wrapper rejects non-finite
    # inputs), so this blend selects exactly; CasADi's if_else would emit a double-as-bool test
    # that clang's -Wfloat-conversion rejects
    y_k = primed * z[nx:nx + ny] + (1.0 - primed) * y
    zeta_next, x_next, d_hat, excess = step_parts(ts, d, z[:nx], y_k, y, u, xp=ca)
    z_next = ca.vertcat(zeta_next, y, 1.0, x_next, d_hat)
    return ca.Function(name, [z, u, y, rho], [z_next, excess, 1.0 - primed],
                       ["z", "u", "y", "rho"], ["z_next", "excess", "warmup"])


def step_numpy(ts: TSFuzzyModel, d: TSDesign, z, u, y):
    """Reference step in numpy (tests, benchmark peer): returns (z_next, excess, warmup)."""
    nx, ny = ts.nx, ts.ny
    z, y = np.asarray(z, float), np.asarray(y, float)
    primed = z[nx + ny] > 0
    y_k = z[nx:nx + ny] if primed else y
    zeta_next, x_next, d_hat, excess = step_parts(ts, d, z[:nx], y_k, y, np.asarray(u, float), xp=np)
    return np.concatenate([zeta_next, y, [1.0], x_next, d_hat]), float(excess), 0.0 if primed else 1.0
