"""LPV L-infinity unknown-input observer, Nguyen et al. 2019 Theorem 1 (eqs. (19)-(23)).

Observer (15): x_hat' = A(th) x_hat + B u + D d_hat + M(th)(C x_hat + Dd d_hat - y), with
M(th) = P(th)^-1 L(th), P(th) = sum eta_i (P_i + X), L(th) = sum eta_i L_i.

Beyond the paper, unknown inputs may reach the outputs (y = C x + Du u + Dd d: a lateral
force seen by the accelerometer) and D, Dd may depend on the scheduling. The error then obeys
e' = (A + M C) e + (D + M Dd)(d_hat - d), so the paper's block P D of (21) becomes
P_i D_j + L_i Dd_j: still affine in the decision variables, and the same theorem holds.

Two deliberate, documented choices (README, "Nguyen et al. 2019 design"):

* Rate vertices. The paper's (21) pairs the bounds phi_kl of every membership
  derivative with the same index l. Because sum_i eta_i' = 0, only *consistent*
  corners (derivatives summing to zero) are reachable, so the conditions are
  imposed at the corners returned by :attr:`Polytope.rate_vertices`, with the
  literal Psi of (22)/(25) evaluated there.
* Well-posedness. Theorem 1 is homogeneous in (P_i, X, L_i, nu, 1/mu), and gamma
  can be driven to 0 by unbounded gains. We normalize mu = 1 (so (20) gives
  P_i + X >= I) and bound ||L_i|| <= gain_bound; together they guarantee
  ||M(th)||_2 <= gain_bound for every th. Minimizing nu then minimizes
  gamma = sqrt(mu nu), which is what "minimize mu + nu" reaches at optimum.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ...representation.canonical import decimal_round
from ...errors import ConfigurationError, RankConditionError
from ...errors import SolverError
from ...design.lmi import BlockCheck, LMIProblem, LMISolution, bmat, check_blocks, uncertified
from ...representation.polytope import Polytope
from ...settings import Rule, setting
from ...design.precision import margin_field, precision_field


@dataclass(frozen=True)
class LinfDesignSettings:
    """Tuning of a Theorem-1 design.

    Attributes
    ----------
    alpha : float
        Decay rate of the Lyapunov function (paper: 5).
    lyapunov : {"pdlf", "quadratic"}
        Parameter-dependent (P_i, slack X) or common quadratic (X = 0, P_i = P).
    gain_bound : float
        Guaranteed bound on ||M(theta)||_2 in 1/s (implementability constraint).
    margin : float
        Strictness margin added to every LMI block, so the numpy re-check has slack.
    tol : float
        Clarabel gap/feasibility tolerance.
    taylor_error_limit : float
        Largest relative error of a Taylor-reduced polytope's A(theta) against the exact A(rho)
        (at the entry of the largest absolute error) that is accepted; beyond it the design is
        refused with a pointer to ``polytope = "sector"`` (the exact form).
    """

    alpha: float = setting(5.0, gt=0, doc="decay rate")
    lyapunov: str = setting("pdlf", choices=("pdlf", "quadratic"))
    gain_bound: float = setting(100.0, gt=0, doc="bound on ||M(theta)|| in 1/s")
    margin: float = setting(1e-5, ge=0)
    tol: float = setting(1e-8, gt=0)
    taylor_error_limit: float = setting(0.25, gt=0, doc="relative error a Taylor-reduced polytope may have")
    performance: tuple = setting((), items=Rule(str), doc="states of the performance output z = F e of (17); empty: all (Remark 4, z = e)")
    precision: str = precision_field()
    float32_margin: float = margin_field()


def performance_matrix(states, performance: tuple = ()) -> np.ndarray | None:
    """F of the performance output z = F e (17): the rows of the identity that pick the named
    states, or None (F = I, Remark 4's z = e) for an empty selection. A name that is not a state
    is a ``ValueError`` naming the states (the build turns it into a ConfigurationError)."""
    if not performance:
        return None
    names = [str(x) for x in states]
    unknown = [p for p in performance if p not in names]
    if unknown:
        raise ValueError(f"{', '.join(map(repr, unknown))} {'is not a state' if len(unknown) == 1 else 'are not states'}"
                         f" of the model (states: {', '.join(names)})")
    if len(set(performance)) != len(performance):
        raise ValueError(f"a state is named twice in {list(performance)}")
    return np.eye(len(names))[[names.index(p) for p in performance]]


def ui_feedthrough(poly: Polytope) -> np.ndarray:
    """Dd at every vertex, (N, ny, nd): zeros for a model whose unknown inputs stay out of the outputs."""
    if poly.Dd is not None:
        return poly.Dd
    return np.zeros((poly.n_vertices, poly.C.shape[1], poly.D.shape[2]))


def _check_assumptions(poly: Polytope, states: tuple = ()) -> None:
    n = poly.A.shape[1]
    names = [str(x) for x in states] if len(states) == n else [f"x{k + 1}" for k in range(n)]
    Dd = ui_feedthrough(poly)
    for i in range(poly.n_vertices):
        D = poly.D[i]
        if np.linalg.matrix_rank(D) < D.shape[1]:
            if np.linalg.matrix_rank(np.vstack([D, Dd[i]])) == D.shape[1]:
                raise RankConditionError(
                    f"vertex {i + 1}: an unknown input reaches the outputs only (D has a zero or dependent "
                    f"column): the UI filter (47) reconstructs unknown inputs through the dynamics, d = D^+ (x' - A x "
                    f"- B u). Model it as a state with zero dynamics (b' = 0, a sensor offset) seen by the "
                    f"output, and estimate it with the states")
            raise RankConditionError(f"vertex {i + 1}: D is not of full column rank (assumption of "
                                     f"Theorem 1); the unknown inputs cannot be reconstructed")
        A, C = poly.A[i], poly.C[i]
        # Hautus test of detectability at every eigenvalue with Re >= 0
        for lam in np.linalg.eigvals(A):
            if lam.real >= 0:
                pbh = np.vstack([A - lam * np.eye(n), C])
                if np.linalg.matrix_rank(pbh, tol=1e-9 * max(1.0, np.abs(pbh).max())) < n:
                    vec = np.abs(np.linalg.svd(pbh)[2][-1])          # the unobservable direction
                    along = ", ".join(names[k] for k in np.flatnonzero(vec >= 0.1 * vec.max()))
                    mode = f"{lam.real:.4g}" if abs(lam.imag) < 1e-12 else f"{lam:.4g}"
                    raise RankConditionError(
                        f"vertex {i + 1}: (A, C) is not detectable (mode {mode} unobservable, along {along}); "
                        f"measure an output that sees {along}, or drop it from the states")


def ui_scaling(poly: Polytope) -> np.ndarray:
    """Unknown-input units for the LMIs: each column of D scaled to a largest entry of 1.

    Theorem 1 is invariant under d -> c d up to nu -> nu / c^2 in exact arithmetic, but not its
    strictness margins, nor the solver: a driver torque in N m or a force in N (entries of D
    ~1e-3) puts nu near 1e-12, under the margins, and the design then depends on the unit (a
    force in N gave a UI-filter loop at spectral radius 1.66 where the same force in kN gave 0.94).
    The design is solved for d_s = d * c; gamma is reported in the model's units.
    """
    c = np.abs(poly.D).max(axis=(0, 1))
    return np.where(c > 0, 1.0 / np.where(c > 0, c, 1.0), 1.0)


def output_scaling(poly: Polytope) -> np.ndarray:
    """Output units for the LMIs: each output scaled to a largest entry of 1 in its row of
    [C, Dd] (over the vertices), so a yaw rate in deg/s or an acceleration in g gives the same
    observer as in rad/s and m/s^2: the gain bound ||L|| <= gain_bound acts on these units.
    Outputs that measure a state directly (a row of C with largest entry 1) are unchanged."""
    rows = np.abs(np.concatenate([poly.C, ui_feedthrough(poly)], axis=2)).max(axis=(0, 2))
    return np.where(rows > 0, 1.0 / np.where(rows > 0, rows, 1.0), 1.0)


def decay_bound(poly: Polytope, gain_bound: float) -> tuple:
    """(bound, vertex): no decay rate alpha >= bound satisfies Theorem 1 with ||M|| <= ``gain_bound``.

    The diagonal block (21) Y_ii at a zero membership rate (the quadratic design always has it; the PDLF
    design at every rate box that holds 0) has the state part He(Q_i (A_i + M_i C_i)) + 2 alpha Q_i < 0,
    M_i = Q_i^-1 L_i. Its trace in the Q_i metric gives tr(A_i + M_i C_i) < -n alpha, and
    |tr(M C)| <= ||M||_2 ||C||_* (C in the design's output units, :func:`output_scaling`): hence
    alpha < (gain_bound ||C_i||_* - tr A_i) / n at every vertex i."""
    C = poly.C * output_scaling(poly)[None, :, None]
    n = poly.A.shape[1]
    bounds = [(gain_bound * float(np.linalg.norm(C[i], "nuc")) - float(np.trace(poly.A[i]))) / n
              for i in range(poly.n_vertices)]
    i = int(np.argmin(bounds))
    return bounds[i], i


def _scaled(poly: Polytope, scale: np.ndarray, out_scale: np.ndarray | None = None) -> Polytope:
    t = np.ones(poly.C.shape[1]) if out_scale is None else out_scale
    return dataclasses.replace(poly, D=poly.D * scale[None, None, :], C=poly.C * t[None, :, None],
                               Dd=ui_feedthrough(poly) * scale[None, None, :] * t[None, :, None])


def build_problem(poly: Polytope, settings: LinfDesignSettings, performance: np.ndarray | None = None,
                  states: tuple = (), ui_gain: float = 1.0, design: bool = True):
    """LMI problem of Theorem 1 under ``settings``, in the unknown-input units of :func:`ui_scaling`
    times ``ui_gain`` (see :func:`ui_gain`); returns (problem, variables). ``states`` names the
    states in the errors; ``performance`` is F of (17) (None: the identity)."""
    poly = _scaled(poly, ui_scaling(poly) * ui_gain, output_scaling(poly))
    _check_assumptions(poly, states)
    if settings.lyapunov == "pdlf" and poly.rate_bound_mode == "none":
        raise ConfigurationError("the parameter-dependent design needs membership rate bounds; with "
                         "rate_bounds = 'none' use lyapunov = 'quadratic'")
    N, nx, ny = poly.n_vertices, poly.A.shape[1], poly.C.shape[1]
    F = np.eye(nx) if performance is None else np.asarray(performance, dtype=float)
    prob = LMIProblem(problem_name(settings), design=design, data={"ui_gain": ui_gain} if design else {})
    if settings.lyapunov == "pdlf":
        X = prob.symmetric("X", nx)
        P = [prob.symmetric(f"P{i + 1}", nx) for i in range(N)]
    elif settings.lyapunov == "quadratic":
        X = np.zeros((nx, nx))
        common = prob.symmetric("P", nx)
        P = [common] * N
    else:
        raise ConfigurationError(f"lyapunov must be 'pdlf' or 'quadratic', got {settings.lyapunov!r}")
    L = [prob.matrix(f"L{i + 1}", nx, ny) for i in range(N)]
    nu = prob.scalar("nu")
    mu = 1.0  # normalization (homogeneity), see module docstring
    Q = [P[i] + X for i in range(N)]
    m, a = settings.margin, settings.alpha
    # ||M|| = ||Q(th)^-1 L(th)|| <= ||L|| / lambda_min(Q). With F = I, (20) and mu = 1 give Q >= I,
    # and ||L_i|| <= g bounds ||M|| by g. A performance output of fewer states leaves Q free in the
    # other directions (measured: ||M|| ~ 1e6-1e7 1/s with gamma -> 0 for z = beta); the bound
    # then takes a scalar sigma: Q_i >= sigma I and ||L_i|| <= g sigma (both affine).
    full = performance is None
    sigma = 1.0 if full else prob.scalar("sigma")
    g = settings.gain_bound
    for i in range(N):
        if full:
            prob.require_psd(f"(19) P{i + 1}+X > 0", Q[i], m, "Lyapunov matrix at a vertex")
        else:
            prob.require_psd(f"(19) P{i + 1}+X >= sigma I", Q[i] - sigma * np.eye(nx), m,
                             "Lyapunov matrix at a vertex (sigma: gain bound with z = F e)")
        prob.require_psd(f"(20) i={i + 1}", bmat([[Q[i], F.T], [F, mu * np.eye(F.shape[0])]]), m,
                         "performance output bound (mu)")
        prob.require_psd(f"gain bound ||L{i + 1}|| <= {g:g}" + ("" if full else " sigma"),
                         bmat([[g * sigma * np.eye(nx), L[i]], [L[i].T, g * sigma * np.eye(ny)]]),
                         m, "raise gain_bound (faster observer) or lower alpha")
    # products shared by many blocks, formed once
    PA = [[P[i] @ poly.A[j] for j in range(N)] for i in range(N)]
    LC = [[L[i] @ poly.C[j] for j in range(N)] for i in range(N)]
    Dd = ui_feedthrough(poly)
    QD = [[Q[i] @ poly.D[j] + L[i] @ Dd[j] if poly.has_ui_feedthrough else Q[i] @ poly.D[j] for j in range(N)]
          for i in range(N)]
    XA = [2 * X @ poly.A[j] + 2 * a * X for j in range(N)]
    nd = poly.D.shape[2]
    corner = bmat([[np.zeros((nd, nx)), -a * nu * np.eye(nd)]])

    def upsilon(i, j, rate_term):
        top_left = PA[i][j] + LC[i][j] + a * P[i] + 0.5 * (rate_term + XA[j])
        blk = bmat([[top_left, QD[i][j]], [corner]])
        return blk + blk.T

    for v, rates in enumerate(poly.rate_vertices):
        rate_term = sum(rates[k] * (P[k] + X) for k in range(N))   # the phi_kl terms of Psi, (22)/(25)
        for j in range(N):
            for i in range(j + 1):
                if i == j:
                    blk = upsilon(i, i, rate_term)
                    label = f"(21) Y_{i + 1}{i + 1}, rate vertex {v + 1}"
                else:
                    blk = upsilon(i, j, rate_term) + upsilon(j, i, rate_term)
                    label = f"(21) Y_{i + 1}{j + 1}+Y_{j + 1}{i + 1}, rate vertex {v + 1}"
                prob.require_nsd(label, blk, m, "lower alpha, widen the gain bound, or narrow the "
                                               "scheduling/acceleration box")
    prob.minimize(nu)
    return prob, {"P": P, "X": X, "L": L, "nu": nu}


@dataclass(frozen=True)
class LinfDesign:
    """Result of a Theorem-1 design: decision matrices, gamma and certificate."""

    settings: LinfDesignSettings
    P: tuple
    X: np.ndarray
    L: tuple
    mu: float
    nu: float
    solution: LMISolution | None
    fallback: str = ""           # set when the PDLF design is the quadratic one it contains
    ui_gain: float = 1.0         # the solver's unknown-input units (see ui_gain)
    performance: np.ndarray | None = None     # F of (17); None: the identity

    @property
    def gamma(self) -> float:
        return float(np.sqrt(self.mu * self.nu))

    @property
    def Q(self) -> tuple:
        return tuple(p + self.X for p in self.P)

    def gains_json(self) -> dict:
        out = {f"P{i + 1}": p.tolist() for i, p in enumerate(self.P)}
        out.update({f"L{i + 1}": l.tolist() for i, l in enumerate(self.L)})
        out.update({"X": self.X.tolist(), "mu": self.mu, "nu": self.nu, "gamma": self.gamma,
                    "performance": list(self.settings.performance) or "all states (z = e)",
                    "ui_gain": self.ui_gain})
        if self.fallback:
            out["fallback"] = self.fallback
        return out


def problem_name(settings: LinfDesignSettings) -> str:
    return f"Theorem 1 ({settings.lyapunov})"


def ui_gain(poly: Polytope, settings: LinfDesignSettings, solver, performance: np.ndarray | None = None,
            states: tuple = ()) -> float:
    """Factor on the unknown-input units of :func:`ui_scaling` that puts the solver's nu near 1.

    Theorem 1 is invariant under d -> k d with nu -> nu / k^2, the solver is not: with mu = 1, nu
    is gamma^2 ~ 1e-4..1e-5 in the units of :func:`ui_scaling`, the corner -2 alpha nu of every
    (21) block sits 1e7 below its state part, and the interior-point method stops at its tolerance
    up to 2x above the optimum at high gain bounds (measured: gamma 0.0051 instead of 0.0028 at
    10^4 1/s, 0.0097 at 763 1/s where the published design certifies 0.0095), non-monotone in the
    gain bound, while the strictness margin on those blocks costs up to 1 % of gamma. An analysis
    solve in those units gives nu_0 and k_1 = 2^round(-log2(nu_0)/2); a second one at k_1 gives nu_1
    (now accurate) and k = k_1 2^floor(-log2(nu_1)/2), which puts the solver's nu in (1/4, 1]:
    there the least-norm stage's bound (the optimum rounded up to three significant digits,
    codegen.design.lmi.objective_bound) gives up at most 0.4 % of nu. k is a power of two: exact, and the
    same on machines whose nu differ in the last digits; any k within 8x of it gives the same
    gamma to 3 digits (tests/families/linf_uio/test_design.py). Committed with the design (design lock) and read
    back on replay (``solver.committed_data``)."""
    committed = solver.committed_data(problem_name(settings))
    if committed is not None and "ui_gain" in committed:
        return float(committed["ui_gain"])
    k = 1.0
    for rounding in (np.round, np.floor):
        try:
            prob, _ = build_problem(poly, settings, performance, states, k, design=False)
            nu = float(prob.solve(tol=settings.tol, unique=False, refine=True)["nu"])   # the optimum, accurately
        except SolverError:
            return k            # the design's own solve reports what fails
        if not (np.isfinite(nu) and nu > 0):
            return k
        k = float(k * 2.0 ** rounding(-0.5 * np.log2(nu)))
    return k


def design(poly: Polytope, settings: LinfDesignSettings, solver, states: tuple = ()) -> LinfDesign:
    """Solve Theorem 1 (``solver``: :mod:`codegen.design.solver`); the rounded matrices are
    re-certified independently. ``settings.performance`` names the states of z (17); ``states``
    are the model's."""
    try:
        F = performance_matrix(states, settings.performance)
    except ValueError as exc:
        raise ConfigurationError(f"[design] performance: {exc}", key="performance") from None
    k = ui_gain(poly, settings, solver, F, states)
    prob, var = build_problem(poly, settings, F, states, k)
    sol = solver.solve(prob, tol=settings.tol)
    N = poly.n_vertices
    if settings.lyapunov == "pdlf":
        P = tuple(decimal_round(sol[f"P{i + 1}"]) for i in range(N))
        X = decimal_round(sol["X"])
    else:
        P = tuple(decimal_round(sol["P"]) for _ in range(N))
        X = np.zeros_like(P[0])
    # back to the model's output units: L (T y) = (L T) y, column by column (exact per element)
    t = output_scaling(poly)
    L = tuple(decimal_round(np.asarray(sol[f"L{i + 1}"]) * t[None, :]) for i in range(N))
    P = tuple(0.5 * (p + p.T) for p in P)
    X = 0.5 * (X + X.T)
    # back to the model's units: D d = (D / c)(c d), so nu = nu_s / c^2 (one unknown input; the
    # largest c bounds it for several)
    c = float(np.max(1.0 / (ui_scaling(poly) * k)))
    nu = float(decimal_round(sol["nu"] * c * c))
    return LinfDesign(settings, P, X, L, 1.0, nu, sol, ui_gain=k, performance=F)


def certify(poly: Polytope, P, X, L, alpha: float, performance=None) -> dict:
    """Independent numpy check of Theorem 1 for given matrices (no solver involved).

    Returns the smallest mu and nu for which (20)-(21) hold, gamma = sqrt(mu nu),
    and per block the largest eigenvalue of its nu-free part (must be < 0).
    """
    N, nx = poly.n_vertices, poly.A.shape[1]
    F = np.eye(nx) if performance is None else np.asarray(performance, dtype=float)
    P = [np.asarray(p, dtype=float) for p in P]
    L = [np.asarray(l, dtype=float) for l in L]
    X = np.asarray(X, dtype=float)
    Q = [p + X for p in P]
    Dd = ui_feedthrough(poly)
    blocks = {f"(19) P{i + 1}+X > 0": Q[i] for i in range(N)}
    checks = list(check_blocks(blocks))
    if uncertified(checks) is not None:
        return {"feasible": False, "gamma": float("inf"), "mu": float("inf"), "nu": float("inf"),
                "blocks": [_check_json(c) for c in checks], "reason": "P_i + X not positive definite"}
    mu = max(float(np.linalg.eigvalsh(F @ np.linalg.solve(q, F.T)).max()) for q in Q)
    nu_needed, rows, feasible = 0.0, [], True
    for v, rates in enumerate(poly.rate_vertices):
        def S(i, j):
            psi = sum(rates[k] * (P[k] + X) for k in range(N)) + 2 * X @ poly.A[j] + 2 * alpha * X
            top = P[i] @ poly.A[j] + L[i] @ poly.C[j] + alpha * P[i] + 0.5 * psi
            return top + top.T, Q[i] @ poly.D[j] + L[i] @ Dd[j]
        for j in range(N):
            for i in range(j + 1):
                if i == j:
                    s, b = S(i, i)
                    count, label = 1, f"(21) Y_{i + 1}{i + 1}, rate vertex {v + 1}"
                else:
                    s1, b1 = S(i, j)
                    s2, b2 = S(j, i)
                    s, b, count = s1 + s2, b1 + b2, 2
                    label = f"(21) Y_{i + 1}{j + 1}+Y_{j + 1}{i + 1}, rate vertex {v + 1}"
                state_block = check_blocks({label: -s})[0]
                lam_max = -state_block.min_eig
                if not state_block.certified:   # s must be negative definite beyond rounding
                    feasible, need = False, float("inf")
                else:
                    # [[s, b], [b', -2 count alpha nu I]] <= 0  <=>  nu >= lmax(b' (-s)^-1 b)/(2 count alpha)
                    need = float(np.linalg.eigvalsh(b.T @ np.linalg.solve(-s, b)).max()) / (2 * count * alpha)
                nu_needed = max(nu_needed, need)
                rows.append({"label": label, "max_eig_state_block": lam_max, "nu_needed": need})
    gamma = float(np.sqrt(mu * nu_needed)) if feasible else float("inf")
    return {"feasible": feasible, "gamma": gamma, "mu": mu, "nu": nu_needed,
            "blocks": [_check_json(c) for c in checks] + rows}


def _check_json(c: BlockCheck) -> dict:
    return {"label": c.label, "min_eig": c.min_eig, "relative_margin": c.relative_margin}


def gain_at(poly: Polytope, Q, L, rho: float) -> np.ndarray:
    """M(rho) = P(rho)^-1 L(rho) (eq. (23))."""
    eta = poly.eta(rho)
    Qt = sum(e * q for e, q in zip(eta, Q))
    Lt = sum(e * l for e, l in zip(eta, L))
    return np.linalg.solve(Qt, Lt)
