"""Discrete-time observer step and its stability certificate.

The continuous observer of Nguyen et al. 2019, eqs. (15), (23) and the UI filter (47),
acts on z = [x_hat; d_hat]:

    z' = Aa(th) z + Ba u + By(th) y,
    Aa = [[A + M C, D], [Dp M C / Tf, 0]],  By = [[-M], [-Dp M / Tf]],  Ba = [[B], [0]]

with M(th) = P(th)^-1 L(th) and Dp = pinv(D). Its error poles reach several hundred
rad/s, so forward Euler at 100 Hz would diverge. The step is backward Euler with
the scheduling of the new sample (L-stable, no extra tuning):

    (I - Ts Aa(th+)) z+ = z + Ts (Ba u+ + By(th+) y+).

Certificate (:func:`certify_step`): the continuous Theorem-1 certificate is carried
over to the sampled error dynamics by a vertex check (see the function), valid for
any scheduling sequence inside the box; a dense-grid spectral radius of the full
step (with the UI filter) is reported beside it.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
import sympy as sp
from scipy.linalg import eigh

from ... import canonical
from ...errors import ConfigurationError, DiscretizationError, ModelDefinitionError
from ...polytope import Polytope, sector_weights_product
from ...stepgen import CASADI_MODULES, TAIL, clamp, const_times, solve_unpivoted, sum_in_order


@dataclass(frozen=True)
class ObserverData:
    """Numbers the discrete step needs: polytope vertices, Lyapunov/gain vertex matrices."""

    poly: Polytope
    Q: tuple          # P_i + X
    L: tuple
    Tf: float
    Ts: float
    derived: tuple = ()         # (signal symbol, expression in the output symbols y_<name>)
    output_symbols: tuple = ()
    derived_inputs: tuple = ()  # (input symbol, expression in y_<name> and the raw signals)

    def __post_init__(self):
        if np.ptp(self.poly.D, axis=0).max(initial=0) > 0:
            raise ModelDefinitionError("D depends on the scheduling signal; this observer family needs "
                                       "a constant D (its pseudo-inverse drives the UI filter (47))")
        if not self.Ts > 0 or not self.Tf > 0:
            raise ConfigurationError(f"sample time and filter constant must be positive (Ts={self.Ts}, Tf={self.Tf})")

    @property
    def nx(self):
        return self.poly.A.shape[1]

    @property
    def nd(self):
        return self.poly.D.shape[2]

    @property
    def nz(self):
        return self.nx + self.nd

    @cached_property
    def Dp(self):
        return canonical.pinv(self.poly.D[0])

    @cached_property
    def raw_signals(self) -> tuple:
        """Scheduling signals that are observer inputs (the others are derived from y)."""
        derived = {sym for sym, _ in self.derived}
        return tuple(sym for sym in self.poly.signals if sym not in derived)

    @cached_property
    def quadratic(self) -> bool:
        return all(np.array_equal(q, self.Q[0]) for q in self.Q)

    def _derived_functions(self, xp):
        args = (*self.output_symbols, *self.raw_signals)
        mods = CASADI_MODULES if xp is ca else "numpy"
        return {sym: sp.lambdify(args, expr, mods) for sym, expr in self.derived}

    @cached_property
    def _derived_numpy(self) -> dict:
        """Derived-signal functions compiled once: the numpy step calls them every sample."""
        return self._derived_functions(np)

    @property
    def nw(self) -> int:
        return len(self.derived_inputs)

    def _derived_inputs_function(self, xp):
        """All derived inputs as one function, common subexpressions shared (one slip inversion
        serves several inputs)."""
        args = (*self.output_symbols, *self.raw_signals)
        mods = CASADI_MODULES if xp is ca else "numpy"
        return sp.lambdify(args, [expr for _, expr in self.derived_inputs], mods, cse=True)

    @cached_property
    def _derived_inputs_numpy(self):
        return self._derived_inputs_function(np)

    def derived_input_values(self, rho_raw, y, xp=np) -> list:
        """Derived known inputs w (model order), from the measurements y and the raw signals."""
        f = self._derived_inputs_numpy if xp is np else self._derived_inputs_function(ca)
        values = [y[k] for k in range(len(self.output_symbols))] + list(rho_raw)
        return list(f(*values))

    def signal_values(self, rho_raw, y, xp=np):
        """All scheduling signals in polytope order: raw ones from the input, derived ones from y."""
        raw = dict(zip(self.raw_signals, rho_raw))
        funcs = self._derived_numpy if xp is np else self._derived_functions(ca)
        values = [y[k] for k in range(len(self.output_symbols))] + [raw[sym] for sym in self.raw_signals]
        return [raw[sym] if sym in raw else funcs[sym](*values) for sym in self.poly.signals]


def _blend(eta, mats):
    total = eta[0] * mats[0]
    for e, m in zip(eta[1:], mats[1:]):
        total = total + e * m
    return total


def augmented_matrices(data: ObserverData, theta: np.ndarray):
    """(Aa, Ba, By) at premise values ``theta`` (numpy): z' = Aa z + Ba u + By y, with the
    correction M (C x + Du u - y) of eq. (15) and the UI filter (47)."""
    eta = sector_weights_product(np.asarray(theta, float), data.poly.premises)
    A, B, C, Du = (_blend(eta, m) for m in (data.poly.A, data.poly.B, data.poly.C, data.poly.Du))
    M = np.linalg.solve(_blend(eta, data.Q), _blend(eta, data.L))
    D, Dp = data.poly.D[0], data.Dp
    Aa = np.block([[A + M @ C, D], [Dp @ M @ C / data.Tf, np.zeros((data.nd, data.nd))]])
    Ba = np.vstack([B + M @ Du, Dp @ M @ Du / data.Tf])
    By = np.vstack([-M, -Dp @ M / data.Tf])
    return Aa, Ba, By


def derived_input_matrix(data: ObserverData, theta: np.ndarray) -> np.ndarray:
    """Bwa at premise values ``theta``: z' = ... + Bwa w for the derived known inputs w."""
    eta = sector_weights_product(np.asarray(theta, float), data.poly.premises)
    Bw, Duw = _blend(eta, data.poly.Bw), _blend(eta, data.poly.Duw)
    M = np.linalg.solve(_blend(eta, data.Q), _blend(eta, data.L))
    return np.vstack([Bw + M @ Duw, data.Dp @ M @ Duw / data.Tf])


def premise_of_signal(poly: Polytope, rho, xp=np):
    """Premise values theta(rho); ``rho`` is a scalar (one signal) or a list in ``poly.signals`` order."""
    rho = list(rho) if isinstance(rho, (list, tuple, np.ndarray)) and np.ndim(rho) > 0 else [rho]
    if xp is np:
        return [f(*rho) for f in poly.premise_functions]
    mods = CASADI_MODULES
    return [sp.lambdify(poly.signals, p.expr, mods)(*rho) for p in poly.premises]


def step_numpy(data: ObserverData, z, u, y, rho):
    """Reference step in numpy (tests, benchmark peer); ``rho`` holds the raw scheduling inputs.

    Returns (z_next, clamped) with clamped = 1.0 when a scheduling signal (raw or derived)
    left its box. Derived known inputs are computed from ``y`` and ``rho`` as in the C step."""
    rho_raw = np.atleast_1d(np.asarray(rho, float))
    values = data.signal_values(rho_raw, np.asarray(y, float))
    clamped = [min(max(v, lo), hi) for v, lo, hi in zip(values, data.poly.lowers, data.poly.uppers)]
    theta = np.array(premise_of_signal(data.poly, clamped), dtype=float)
    Aa, Ba, By = augmented_matrices(data, theta)
    G = np.eye(data.nz) - data.Ts * Aa
    flag = float(any(c != v for c, v in zip(clamped, values)))
    rhs = z + data.Ts * (Ba @ u + By @ y)
    if data.nw:
        w = np.array(data.derived_input_values(rho_raw, np.asarray(y, float)), dtype=float)
        rhs = rhs + data.Ts * (derived_input_matrix(data, theta) @ w)
    return np.linalg.solve(G, rhs), flag


def _affine_in_scalar_premise(data: ObserverData):
    """(Q0, Q1, L0, L1) with Q(th) = Q0 + th Q1, L(th) = L0 + th L1, if the memberships allow it."""
    poly = data.poly
    if len(poly.premises) != 1 or poly.n_vertices != 2:
        return None
    prem = poly.premises[0]
    mid, half = 0.5 * (prem.lower + prem.upper), 0.5 * (prem.upper - prem.lower)
    # eta_1 = (ub - th)/w, eta_2 = (th - lb)/w  =>  V(th) = V(mid) + (th - mid) (V_2 - V_1)/w
    w = 2 * half
    Q0 = 0.5 * (data.Q[0] + data.Q[1]) - mid * (data.Q[1] - data.Q[0]) / w
    L0 = 0.5 * (data.L[0] + data.L[1]) - mid * (data.L[1] - data.L[0]) / w
    return Q0, (data.Q[1] - data.Q[0]) / w, L0, (data.L[1] - data.L[0]) / w


def gain_factorization(data: ObserverData):
    """M(th) = V diag(1/(1 + th lam)) V' L(th) for Q(th) = Q0 + th Q1 (generalized eigenvectors,
    V' Q0 V = I). Exact, with four independent divisions instead of a linear solve; None when
    Q is not affine in one premise."""
    parts = _affine_in_scalar_premise(data)
    if parts is None:
        return None
    Q0, Q1, L0, L1 = parts
    lam, V = canonical.eigh(Q1, Q0)     # emitted: machine-independent (see codegen.canonical)
    return lam, V, canonical.matmul(V.T, L0), canonical.matmul(V.T, L1)


def signal_grid(poly: Polytope, n_single: int = 401, n_multi: int = 41) -> np.ndarray:
    """Dense grid over the box of all scheduling signals, shape (points, n_signals)."""
    n = n_single if len(poly.signals) == 1 else n_multi
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(poly.lowers, poly.uppers)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))


def _x_system(data: ObserverData, theta: np.ndarray):
    """Matrix of the eliminated x+ system, G_x(th) (see :func:`step_casadi`)."""
    Aa, _, By = augmented_matrices(data, theta)
    nx = data.nx
    M = -By[:nx]
    K = (data.Ts / data.Tf) * (data.Dp @ M)
    C = _blend(sector_weights_product(np.asarray(theta, float), data.poly.premises), data.poly.C)
    return np.eye(nx) - data.Ts * Aa[:nx, :nx] - data.Ts * (data.poly.D[0] @ K @ C)


def lu_without_pivoting_is_safe(data: ObserverData, min_pivot: float = 1e-3,
                                max_growth: float = 10.0, max_condition: float = 1e4) -> dict:
    """Dense-grid check of the unpivoted solve of G_x(th) (:func:`solve_unpivoted`): the
    eliminated leading pivots are not small and there is no element growth, and the trailing
    TAIL x TAIL Schur complement, solved by its adjugate, is well conditioned (1-norm), so the
    adjugate loses no more than a few digits beyond LU with pivoting."""
    smallest, growth, cond = np.inf, 0.0, 0.0
    for rho in signal_grid(data.poly):
        G = _x_system(data, np.array(premise_of_signal(data.poly, rho), float))
        n = G.shape[0]
        U = G.copy()
        for k in range(max(n - TAIL, 0)):
            smallest = min(smallest, abs(U[k, k]) / max(np.abs(G).max(), 1e-300))
            for i in range(k + 1, n):
                U[i, k:] -= (U[i, k] / U[k, k]) * U[k, k:]
        growth = max(growth, np.abs(U).max() / np.abs(G).max())
        cond = max(cond, float(np.linalg.cond(U[max(n - TAIL, 0):, max(n - TAIL, 0):], 1)))
    safe = bool(smallest >= min_pivot and growth <= max_growth and cond <= max_condition)
    return {"safe": safe, "min_relative_pivot": float(smallest), "growth": float(growth),
            "trailing_condition": cond}


def step_casadi(data: ObserverData, name: str) -> ca.Function:
    """The step as a CasADi Function: (z, u, y, rho) -> (z_next, excess).

    ``rho`` holds the raw scheduling inputs; derived signals are computed from ``y``. Every
    signal is clamped to its box for the memberships (the certificate only holds there);
    ``excess`` = sum of |signal - clamped signal| lets the C wrapper flag such samples. With
    y~ = y - Du u, the d-block of I - Ts Aa is the identity, so d is eliminated (Schur
    complement): the x+ system is nx x nx and far better conditioned than the full one (the
    1/Tf row); then d+ = d + (Ts/Tf) Dp M (C x+ - y~). The gain M(th) is blended directly
    for a common Lyapunov matrix, factorized (:func:`gain_factorization`) for two vertices,
    and solved otherwise; it only enters through N = Ts (I + (Ts/Tf) D Dp) M, formed with the
    constants folded in. The x+ system is solved by :func:`solve_unpivoted` where
    :func:`lu_without_pivoting_is_safe` allows it.
    """
    poly = data.poly
    nz, nu, ny = data.nz, poly.B.shape[2], poly.C.shape[1]
    z = ca.SX.sym("z", nz)
    u = ca.SX.sym("u", nu)
    y = ca.SX.sym("y", ny)
    rho = ca.SX.sym("rho", len(data.raw_signals))
    values = data.signal_values([rho[k] for k in range(rho.shape[0])], [y[k] for k in range(ny)], xp=ca)
    clamped = [clamp(v, lo, hi) for v, lo, hi in zip(values, poly.lowers, poly.uppers)]
    excess = sum(ca.fabs(v - c) for v, c in zip(values, clamped))
    theta = premise_of_signal(poly, clamped, xp=ca)
    eta = sector_weights_product(theta, poly.premises, xp=ca)
    fact = gain_factorization(data) if not data.quadratic else None
    nx, Ts, Tf = data.nx, data.Ts, data.Tf
    D, Dp = poly.D[0], data.Dp
    # The gain enters the step only through N = Ts E M (x+ system and right-hand side, with
    # E = I + (Ts/Tf) D Dp), formed directly with the constant factors folded into its
    # coefficients, and K = (Ts/Tf) Dp M = Dp N / (Tf + Ts) (the d update; Dp D = I).
    left_N = Ts * (np.eye(nx) + (Ts / Tf) * canonical.matmul(D, Dp))
    if fact is not None:
        # two vertices: every blended matrix is affine in the premise; entries that do not
        # vary become constants in the generated code
        th = theta[0]
        lo, hi = poly.premises[0].lower, poly.premises[0].upper
        slope = (poly.A[1] - poly.A[0]) * (1.0 / (hi - lo))
        G_0 = ca.DM(np.eye(nx) - Ts * (poly.A[0] - lo * slope)) + th * ca.DM(-Ts * slope)
        lam, V, W0, W1 = fact
        # 1/(1 + lam theta(rho)) as one cancelled rational function of rho, one division each:
        # it does not wait for theta's own division
        mods = CASADI_MODULES
        num_den = [sp.fraction(sp.cancel(1 / (1 + sp.Float(float(l), 17) * poly.premises[0].expr)))
                   for l in lam]
        scale = [sp.lambdify(poly.signals, n_, mods)(*clamped) / sp.lambdify(poly.signals, d_, mods)(*clamped)
                 for n_, d_ in num_den]
        SW = ca.vertcat(*[scale[k] * (ca.DM(W0[k:k + 1]) + th * ca.DM(W1[k:k + 1])) for k in range(nx)])
        N = const_times(canonical.matmul(left_N, V), SW)
    else:
        G_0 = ca.DM.eye(nx) - _blend(eta, [ca.DM(Ts * a) for a in poly.A])
        if data.quadratic:
            # common Lyapunov matrix: M(th) = sum eta_i P^-1 L_i, no solve at run time
            Ms = [canonical.solve(data.Q[0], l) for l in data.L]
            N = _blend(eta, [ca.DM(canonical.matmul(left_N, m)) for m in Ms])
        else:
            M = ca.solve(_blend(eta, [ca.DM(q) for q in data.Q]), _blend(eta, [ca.DM(l) for l in data.L]))
            N = const_times(left_N, M)
    blend_or_const = (lambda mats: ca.DM(mats[0]) if np.ptp(mats, axis=0).max(initial=0) == 0
                      else _blend(eta, [ca.DM(m) for m in mats]))
    B, C, Du = blend_or_const(poly.B), blend_or_const(poly.C), blend_or_const(poly.Du)
    K = const_times(Dp / (Tf + Ts), N)
    x, d = z[:nx], z[nx:]
    y_t = y - Du @ u
    Bu = (Ts * B) @ u
    if data.nw:
        # derived known inputs: computed here from the measurements, enter like u
        w = ca.vertcat(*data.derived_input_values([rho[k] for k in range(rho.shape[0])],
                                                  [y[k] for k in range(ny)], xp=ca))
        y_t = y_t - blend_or_const(poly.Duw) @ w
        Bu = Bu + (Ts * blend_or_const(poly.Bw)) @ w
    G_x = G_0 - N @ C
    rhs = x + Bu + ca.DM(Ts * D) @ d - N @ y_t
    if lu_without_pivoting_is_safe(data)["safe"]:
        x_next = solve_unpivoted(G_x, rhs)
    else:
        x_next = ca.solve(G_x, rhs)
    # d+ = d + K (C x+ - y~), summed so that the innovation the back substitution finishes last
    # (the one reading the lowest-index state) enters last
    innov = C @ x_next - y_t
    first_state = [min(np.flatnonzero(np.any(poly.C[:, j] != 0, axis=0)), default=nx) for j in range(ny)]
    order = sorted(range(ny), key=lambda j: -first_state[j])
    d_next = ca.vertcat(*[sum_in_order([d[i]] + [K[i, j] * innov[j] for j in order]) for i in range(data.nd)])
    z_next = ca.vertcat(x_next, d_next)
    return ca.Function(name, [z, u, y, rho], [z_next, excess], ["z", "u", "y", "rho"], ["z_next", "excess"])


@dataclass(frozen=True)
class DiscreteCertificate:
    """Proof that the sampled error dynamics contract, plus dense-grid spectral figures."""

    Ts: float
    kappa: float                      # V_k >= kappa V_{k+1} for e_d = 0, any scheduling sequence
    worst_vertex_term: float          # max_{v,i,j} lambda_max(Delta_v Q_i^-1 Delta_v, Q_j)
    error_radius_max: float           # dense grid: max spectral radius of (I - Ts A_hat)^-1
    augmented_radius_max: float       # dense grid: same for the full step with the UI filter
    augmented_radius_at: float
    grid_points: int

    @property
    def contraction(self) -> float:
        """Certified contraction of sqrt(V) per step: 1/sqrt(kappa)."""
        return float(1.0 / np.sqrt(self.kappa))

    def to_json(self) -> dict:
        return {"Ts": self.Ts, "kappa": self.kappa, "contraction_per_step": self.contraction,
                "worst_vertex_term": self.worst_vertex_term,
                "dense_grid_error_spectral_radius_max": self.error_radius_max,
                "dense_grid_augmented_spectral_radius_max": self.augmented_radius_max,
                "dense_grid_augmented_spectral_radius_at": self.augmented_radius_at,
                "dense_grid_points": self.grid_points}


def certify_step(data: ObserverData, alpha: float, n_grid: int = 2001) -> DiscreteCertificate:
    """Prove the backward-Euler error dynamics contract over the whole scheduling box.

    With V = e' Q(th) e, Q(th) = sum eta_i (P_i + X), the continuous certificate (the
    (1,1) block of (21), which holds for every th and every admissible membership
    rate) gives, for the step (I - Ts A_hat(th+)) e+ = e,

        V_k >= e+' ((1 + 2 alpha Ts) Q(th+) - Delta Q(th)^-1 Delta) e+,  Delta = Q(th+) - Q(th),

    and Delta = Ts sum_k r_k Q_k with r in the rate polytope (mean-value theorem).
    Matrix inversion is operator convex and Delta Q^-1 Delta is convex in Delta, so
    checking the generalized eigenvalues of (Delta_v Q_i^-1 Delta_v, Q_j) at every rate
    vertex v and vertex pair (i, j) bounds the whole box: V_k >= kappa V_{k+1} with

        kappa = 1 + 2 alpha Ts - max_{v,i,j} lambda_max(Delta_v Q_i^-1 Delta_v, Q_j).

    The step is refused unless kappa > 1 and the dense-grid spectral radii are < 1.
    """
    poly, Ts = data.poly, data.Ts
    worst = 0.0
    for rates in poly.rate_vertices:
        delta = Ts * sum(r * q for r, q in zip(rates, data.Q))
        for Qi in data.Q:
            lhs = delta @ np.linalg.solve(Qi, delta)
            lhs = 0.5 * (lhs + lhs.T)
            for Qj in data.Q:
                worst = max(worst, float(eigh(lhs, Qj, eigvals_only=True).max()))
    kappa = 1.0 + 2.0 * alpha * Ts - worst
    sig = signal_grid(poly, n_single=n_grid)
    nx = data.nx
    err_r, aug_r = [], []
    for s in sig:
        Aa = augmented_matrices(data, np.array(premise_of_signal(poly, s), float))[0]
        aug_r.append(float(np.abs(np.linalg.eigvals(np.linalg.inv(np.eye(data.nz) - Ts * Aa))).max()))
        err_r.append(float(np.abs(np.linalg.eigvals(np.linalg.inv(np.eye(nx) - Ts * Aa[:nx, :nx]))).max()))
    k = int(np.argmax(aug_r))
    cert = DiscreteCertificate(Ts, kappa, worst, max(err_r), aug_r[k], float(sig[k][0]), len(sig))
    if kappa <= 1.0:
        raise DiscretizationError(
            f"cannot certify the Ts={Ts:g} s step: kappa = 1 + 2 alpha Ts - {worst:.4g} = {kappa:.6f} <= 1 "
            f"(the Lyapunov matrix varies too fast between samples); lower Ts, raise alpha, or use "
            f"the quadratic design")
    if max(err_r) >= 1.0 or aug_r[k] >= 1.0:
        raise DiscretizationError(
            f"the Ts={Ts:g} s step has spectral radius {max(max(err_r), aug_r[k]):.6f} >= 1 on the "
            f"dense grid (with the UI filter, at {poly.signal}={sig[k][0]:.4g}); raise the filter "
            f"constant Tf or lower Ts")
    return cert
