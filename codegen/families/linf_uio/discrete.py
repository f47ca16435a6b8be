"""Discrete-time observer step and its stability certificates.

The continuous observer of Nguyen et al. 2019, eqs. (15), (23) and the UI filter (47),
acts on z = [x_hat; d_hat]:

    z' = Aa(th) z + Ba u + By(th) y,
    Aa = [[A + M C, D + M Dd], [Dp M C / Tf, Dp M Dd / Tf]],  By = [[-M], [-Dp M / Tf]],
    Ba = [[B + M Du], [Dp M Du / Tf]]

with M(th) = P(th)^-1 L(th), Dp = pinv(D(th)) and Dd the unknown inputs' feedthrough to the
outputs (zero in the paper). Its error poles reach several hundred rad/s, so forward Euler at
100 Hz would diverge. The step is backward Euler with the scheduling of the new sample
(L-stable, no extra tuning):

    (I - Ts Aa(th+)) z+ = z + Ts (Ba u+ + By(th+) y+).

Certificates (:func:`certify_step`), both over the whole scheduling box:

* the continuous Theorem-1 certificate carried over to the sampled state error by a vertex
  check (kappa), for any scheduling sequence inside the box and rate bounds;
* the full error of the step *with the UI filter loop*, by a common quadratic Lyapunov
  function of the continuous error matrix Aa(th) over the polytope (:func:`certify_ui_loop`):
  backward Euler keeps it contracting at every sample time and for every scheduling sequence.

A dense-grid spectral radius of the full step is reported beside them, as evidence.
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
import sympy as sp
from scipy.linalg import eigh

from ...design import rates
from ...representation import canonical
from ...errors import CertificateError, ConfigurationError, DiscretizationError, SolverError, UILoopError
from ...design.lmi import LMIProblem
from ...representation.polytope import Polytope, sector_weights_product
from ...emit.stepgen import TAIL, lambdify, clamp, const_times, solve_unpivoted, sum_in_order
from .design import ui_feedthrough, ui_scaling


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
    def Dd(self) -> np.ndarray:
        """The unknown inputs' feedthrough to the outputs at every vertex (zeros in the paper)."""
        return ui_feedthrough(self.poly)

    @property
    def eliminated(self) -> bool:
        """The paper's structure (constant D, no feedthrough): the step eliminates d_hat (see
        :func:`step_casadi`); otherwise it solves the full (nx + nd) system."""
        return not self.poly.D_varies and not self.poly.has_ui_feedthrough

    @cached_property
    def Dp(self):
        """pinv(D) for a constant D (emitted: machine-independent, see codegen.representation.canonical)."""
        return canonical.pinv(self.poly.D[0])

    def Dp_at(self, eta) -> np.ndarray:
        return self.Dp if not self.poly.D_varies else np.linalg.pinv(_blend(eta, self.poly.D))

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
        return {sym: lambdify(args, expr, xp) for sym, expr in self.derived}

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
        return lambdify(args, [expr for _, expr in self.derived_inputs], xp, cse=True)

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
    A, B, C, Du, D, Dd = (_blend(eta, m) for m in (data.poly.A, data.poly.B, data.poly.C, data.poly.Du,
                                                    data.poly.D, data.Dd))
    M = np.linalg.solve(_blend(eta, data.Q), _blend(eta, data.L))
    Dp = data.Dp_at(eta)
    Aa = np.block([[A + M @ C, D + M @ Dd], [Dp @ M @ C / data.Tf, Dp @ M @ Dd / data.Tf]])
    Ba = np.vstack([B + M @ Du, Dp @ M @ Du / data.Tf])
    By = np.vstack([-M, -Dp @ M / data.Tf])
    return Aa, Ba, By


def _grid_premises(poly: Polytope, grid: np.ndarray) -> np.ndarray:
    """The premises at every grid point, point by point (a premise such as v_x**-2 evaluated on a whole
    array takes numpy's vectorized power, which can differ from the scalar one in the last bit)."""
    return np.array([premise_of_signal(poly, s) for s in grid], dtype=float)


def augmented_state_matrices(data: ObserverData, theta: np.ndarray) -> np.ndarray:
    """Aa of :func:`augmented_matrices` at every row of ``theta`` (points, premises) at once: the dense
    evidence grids. Each matrix is formed by the same operations in the same order as one call of
    :func:`augmented_matrices` (the blends term by term, one LAPACK solve per point), so every entry
    is the same to the last bit, without a Python loop over the points."""
    eta = sector_weights_product(np.asarray(theta, float), data.poly.premises)

    def blend(mats):
        total = eta[:, 0, None, None] * mats[0]
        for k in range(1, len(mats)):
            total = total + eta[:, k, None, None] * mats[k]
        return total
    A, C, D, Dd = (blend(m) for m in (data.poly.A, data.poly.C, data.poly.D, data.Dd))
    M = np.linalg.solve(blend(data.Q), blend(data.L))
    Dp = np.linalg.pinv(D) if data.poly.D_varies else np.broadcast_to(data.Dp, (len(eta), *data.Dp.shape))
    top = np.concatenate([A + M @ C, D + M @ Dd], axis=2)
    bottom = np.concatenate([Dp @ M @ C / data.Tf, Dp @ M @ Dd / data.Tf], axis=2)
    return np.concatenate([top, bottom], axis=1)


def derived_input_matrix(data: ObserverData, theta: np.ndarray) -> np.ndarray:
    """Bwa at premise values ``theta``: z' = ... + Bwa w for the derived known inputs w."""
    eta = sector_weights_product(np.asarray(theta, float), data.poly.premises)
    Bw, Duw = _blend(eta, data.poly.Bw), _blend(eta, data.poly.Duw)
    M = np.linalg.solve(_blend(eta, data.Q), _blend(eta, data.L))
    return np.vstack([Bw + M @ Duw, data.Dp_at(eta) @ M @ Duw / data.Tf])


def premise_of_signal(poly: Polytope, rho, xp=np):
    """Premise values theta(rho); ``rho`` is a scalar (one signal) or a list in ``poly.signals`` order."""
    rho = list(rho) if isinstance(rho, (list, tuple, np.ndarray)) and np.ndim(rho) > 0 else [rho]
    if xp is np:
        return [f(*rho) for f in poly.premise_functions]
    return [lambdify(poly.signals, p.expr)(*rho) for p in poly.premises]


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
    lam, V = canonical.eigh(Q1, Q0)     # emitted: machine-independent (see codegen.representation.canonical)
    return lam, V, canonical.matmul(V.T, L0), canonical.matmul(V.T, L1)


GRID_POINTS = 10_000
"""The most points of a dense evidence grid over three or more scheduling signals: n_multi per axis is
n_multi^m points (41^4 = 2.8 million for four signals, an hour of evaluation), so the axes get
floor(GRID_POINTS^(1/m)) points each (three signals 21, four 10, five 6). The grids are evidence beside
the certificates, never the proof; the figures record how many points they had."""


def signal_grid(poly: Polytope, n_single: int = 401, n_multi: int = 41) -> np.ndarray:
    """Dense grid over the box of all scheduling signals, shape (points, n_signals): ``n_single`` points
    for one signal, ``n_multi`` per axis for two, at most :data:`GRID_POINTS` in all beyond."""
    m = len(poly.signals)
    n = n_single if m == 1 else n_multi if m == 2 else max(2, min(n_multi, int(GRID_POINTS ** (1.0 / m) + 1e-9)))
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

    Beyond the paper's structure (D depending on the scheduling, or unknown inputs in the
    outputs) the d-block is no longer the identity: the full (nx + nd) system is solved
    (:func:`_step_casadi_full`).
    """
    if not data.eliminated:
        return _step_casadi_full(data, name)
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
        num_den = [sp.fraction(sp.cancel(1 / (1 + sp.Float(float(l), 17) * poly.premises[0].expr)))
                   for l in lam]
        scale = [lambdify(poly.signals, n_)(*clamped) / lambdify(poly.signals, d_)(*clamped)
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


def _gain_casadi(data: ObserverData, eta):
    """M(th) = Q(th)^-1 L(th) in CasADi: blended directly for a common Lyapunov matrix."""
    if data.quadratic:
        return _blend(eta, [ca.DM(canonical.solve(data.Q[0], l)) for l in data.L])
    return ca.solve(_blend(eta, [ca.DM(q) for q in data.Q]), _blend(eta, [ca.DM(l) for l in data.L]))


def _step_casadi_full(data: ObserverData, name: str) -> ca.Function:
    """The step for D(th) or Dd != 0: (I - Ts Aa(th+)) z+ = z + Ts (Ba u + By y + Bwa w), solved
    as one (nx + nd) system, with Dp(th) = (D' D)^-1 D' formed at run time where D varies."""
    poly = data.poly
    nz, nu, ny, nx, nd = data.nz, poly.B.shape[2], poly.C.shape[1], data.nx, data.nd
    z, u, y = ca.SX.sym("z", nz), ca.SX.sym("u", nu), ca.SX.sym("y", ny)
    rho = ca.SX.sym("rho", len(data.raw_signals))
    values = data.signal_values([rho[k] for k in range(rho.shape[0])], [y[k] for k in range(ny)], xp=ca)
    clamped = [clamp(v, lo, hi) for v, lo, hi in zip(values, poly.lowers, poly.uppers)]
    excess = sum(ca.fabs(v - c) for v, c in zip(values, clamped))
    eta = sector_weights_product(premise_of_signal(poly, clamped, xp=ca), poly.premises, xp=ca)
    blend = (lambda mats: ca.DM(mats[0]) if np.ptp(mats, axis=0).max(initial=0) == 0
             else _blend(eta, [ca.DM(m) for m in mats]))
    A, B, C, Du, D, Dd = (blend(m) for m in (poly.A, poly.B, poly.C, poly.Du, poly.D, data.Dd))
    M = _gain_casadi(data, eta)
    Dp = ca.DM(data.Dp) if not poly.D_varies else ca.solve(D.T @ D, D.T)
    K = Dp @ M / data.Tf
    Aa = ca.vertcat(ca.horzcat(A + M @ C, D + M @ Dd), ca.horzcat(K @ C, K @ Dd))
    Ts = data.Ts
    # the innovation's known part: M (Du u - y) drives x_hat, K (Du u - y) drives d_hat
    known = Du @ u - y
    drive = ca.vertcat(B @ u + M @ known, K @ known)
    if data.nw:
        w = ca.vertcat(*data.derived_input_values([rho[k] for k in range(rho.shape[0])],
                                                  [y[k] for k in range(ny)], xp=ca))
        Bw, Duw = blend(poly.Bw), blend(poly.Duw)
        drive = drive + ca.vertcat(Bw @ w + M @ (Duw @ w), K @ (Duw @ w))
    # CasADi's symbolic solve factors without pivoting, so it loses what the badly scaled system
    # loses: the d-rows carry 1/Tf and every entry the units of its signal (newtons beside
    # radians), a condition number of 1e10 where the equilibrated one is below 1e2. Constant
    # power-of-two row and column scales (exact: they round nothing) undo that before the solve.
    rows, cols = full_system_scaling(data)
    G = ca.diag(ca.DM(rows)) @ (ca.DM.eye(nz) - Ts * Aa) @ ca.diag(ca.DM(cols))
    z_next = ca.DM(cols) * ca.solve(G, ca.DM(rows) * (z + Ts * drive))
    return ca.Function(name, [z, u, y, rho], [z_next, excess], ["z", "u", "y", "rho"], ["z_next", "excess"])


def full_system_scaling(data: ObserverData) -> tuple:
    """(rows, cols): powers of two that equilibrate I - Ts Aa(th) over the scheduling box.

    The column scales bring each column's largest entry (over the box's corners and centre) near
    1, then the row scales do the same for the rows of the column-scaled matrix. Powers of two
    keep the scaled system's entries exact, so the solve is unchanged up to its conditioning.
    """
    grid = signal_grid(data.poly, n_single=5, n_multi=3)
    G = np.array([np.abs(np.eye(data.nz) - data.Ts * augmented_matrices(
        data, np.array(premise_of_signal(data.poly, rho), float))[0]) for rho in grid]).max(axis=0)

    def power_of_two(v):
        return np.array([2.0 ** -np.frexp(x)[1] if x > 0 else 1.0 for x in v])

    cols = power_of_two(G.max(axis=0))
    rows = power_of_two((G * cols).max(axis=1))
    return rows, cols


@dataclass(frozen=True)
class UILoopCertificate:
    """A common quadratic Lyapunov function V = e_z' P e_z of the observer's full error (state
    and unknown-input estimate, UI filter loop closed) over the whole polytope.

    He(P Aa(th)) <= -2 beta P for every th gives, for the backward-Euler step at any sample time
    and any scheduling sequence, V_k >= (1 + 2 beta Ts) V_{k+1} (homogeneous part): see
    :func:`certify_ui_loop`.
    """

    beta: float                     # certified decay rate of V, 1/s
    Ts: float
    blocks: int
    worst_relative_margin: float
    P: np.ndarray = dataclasses.field(default=None, compare=False, repr=False)   # over [x; d], in their units
    multipliers: str = "affine"     # the Finsler multipliers over the polytope: ui_loop_multipliers

    @property
    def contraction(self) -> float:
        return float(1.0 / np.sqrt(1.0 + 2.0 * self.beta * self.Ts))


UI_LOOP_PROBLEM = "UI-filter loop (common Lyapunov function)"
UI_LOOP_BACKOFF = 0.9       # the committed decay rate, as a fraction of the largest one found


UI_LOOP_CUBIC_LIMIT = 220
"""The most cubic blocks (one per multiset of three vertices, C(N + 2, 3)) the certificate solves with
multipliers affine in the memberships: N <= 10 vertices. Beyond, one feasibility problem grows as N^3
(measured: 5,984 blocks at 32 vertices, 93 s each, about 15 of them in the bisection) and the
multipliers are taken constant over the polytope: N (N + 1) / 2 quadratic blocks, a special case of
the affine ones (so never a wrong proof, at most a smaller certified rate)."""


def ui_loop_multipliers(n_vertices: int) -> str:
    """"affine" or "constant": the Finsler multipliers :func:`certify_ui_loop` uses for a polytope of
    ``n_vertices`` vertices (see :data:`UI_LOOP_CUBIC_LIMIT`)."""
    cubic = n_vertices * (n_vertices + 1) * (n_vertices + 2) // 6
    return "affine" if cubic <= UI_LOOP_CUBIC_LIMIT else "constant"


def _ui_loop_problem(data: ObserverData, beta: float, Tf: float, design: bool, margin: float = 1e-6):
    """The LMIs of :func:`certify_ui_loop` at decay ``beta`` and filter constant ``Tf``.

    The error e_z = [x_hat - x; d_hat - d] obeys e_z' = A0 e_z + [I; 0] c + [0; I/Tf] g with
    A0 = [[A, D], [0, 0]], the correction c = M (C e + Dd e_d), i.e. Q c = L (C e + Dd e_d), and
    g = Dp c, i.e. D'D g = D' c. In xi = [e_z; c; g] the decrease of V is the quadratic form
    Phi(eta) on the null space of those constraints; Finsler's lemma with multipliers affine in
    the memberships, Lambda(eta) = sum_k eta_k Lambda_k, turns it into

        Psi(eta) = Phi + He(Lambda_1(eta) [-L Cm, Q, 0]) + He(Lambda_2(eta) [0, -D', D'D]) < 0,

    a cubic form in eta = sum_{i,j,k} eta_i eta_j eta_k T_ijk (homogenized with sum eta = 1):
    the sum of T over the distinct orderings of every multiset {i, j, k} negative proves it for
    every eta of the simplex, hence the whole box. The gain's rational dependence M = Q^-1 L
    needs no bound. For a constant D, g = Dp c is substituted (no Lambda_2). Unknown inputs in
    the units of :func:`ui_scaling`.

    With multipliers constant over the polytope (:func:`ui_loop_multipliers`, many vertices) Psi
    is quadratic in eta and one block per pair {i, j} proves it.
    """
    poly = data.poly
    N, nx, nd, nz = poly.n_vertices, data.nx, data.nd, data.nz
    c = 1.0 / ui_scaling(poly)
    D = poly.D / c[None, None, :]
    Dd = data.Dd / c[None, None, :]
    varies = poly.D_varies
    ng = nd if varies else 0
    n = nz + nx + ng
    multipliers = ui_loop_multipliers(N)
    # the lock records the form only where it is not the affine one, which earlier locks hold
    prob = LMIProblem(UI_LOOP_PROBLEM, design=design,
                      data={"beta": beta, "Tf": Tf} | ({} if multipliers == "affine" else {"multipliers": multipliers}))
    P = prob.symmetric("P", nz)
    m = N if multipliers == "affine" else 1
    L1 = [prob.matrix(f"Lambda1_{k + 1}", n, nx) for k in range(m)]
    L2 = [prob.matrix(f"Lambda2_{k + 1}", n, nd) for k in range(m)] if varies else None
    E = np.hstack([np.eye(nz), np.zeros((nz, nx + ng))])
    if varies:
        drive = np.block([[np.eye(nx), np.zeros((nx, nd))], [np.zeros((nd, nx)), np.eye(nd) / Tf]])
    else:
        drive = np.vstack([np.eye(nx), canonical.pinv(D[0]) / Tf])
    W = 2.0 * beta * (E.T @ P @ E)
    lyap = [E.T @ (P @ np.hstack([np.block([[poly.A[j], D[j]], [np.zeros((nd, nz))]]), drive])) for j in range(N)]
    B1 = [[np.hstack([-data.L[i] @ np.hstack([poly.C[j], Dd[j]]), data.Q[i], np.zeros((nx, ng))]) for j in range(N)]
          for i in range(N)]
    B2 = [[np.hstack([np.zeros((nd, nz)), -D[i].T, D[i].T @ D[j]]) for j in range(N)] for i in range(N)] if varies else None

    def T(i, j, k):
        terms = lyap[j] + L1[k] @ B1[i][j]
        if varies:
            terms = terms + L2[k] @ B2[i][j]
        return terms + terms.T + W

    prob.require_psd("P >= I", P - np.eye(nz), margin, "normalization of the Lyapunov matrix")
    if multipliers == "constant":
        for pair in itertools.combinations_with_replacement(range(N), 2):
            orders = sorted(set(itertools.permutations(pair)))
            total = T(*orders[0], 0)
            for o in orders[1:]:
                total = total + T(*o, 0)
            prob.require_nsd("Psi_" + "_".join(str(v + 1) for v in pair), total, margin, "the UI filter loop")
        return prob
    for triple in itertools.combinations_with_replacement(range(N), 3):
        orders = sorted(set(itertools.permutations(triple)))
        total = T(*orders[0])
        for o in orders[1:]:
            total = total + T(*o)
        prob.require_nsd("Psi_" + "".join(str(v + 1) for v in triple), total, margin, "the UI filter loop")
    return prob


def _ui_loop_feasible(data: ObserverData, beta: float, Tf: float, solver=None) -> bool:
    """Whether the loop's LMIs hold at ``beta``, ``Tf``; ``solver``: the design's, which sees (and
    reports) the analysis solves too."""
    prob = _ui_loop_problem(data, beta, Tf, design=False)
    try:
        prob.solve(tol=1e-9) if solver is None else solver.solve(prob, tol=1e-9)
        return True
    except (SolverError, CertificateError):
        return False


def slowest_grid_decay(data: ObserverData, Tf: float | None = None, n_grid: int = 401) -> tuple:
    """(min over a dense grid of -max Re eig Aa(th), where): evidence, and the ceiling of the
    certified decay (a common P with He(P Aa) <= -2 beta P forces Re eig Aa <= -beta)."""
    d = data if Tf is None else dataclasses.replace(data, Tf=Tf)
    grid = signal_grid(d.poly, n_single=n_grid)
    decay = -np.linalg.eigvals(augmented_state_matrices(d, _grid_premises(d.poly, grid))).real.max(axis=1)
    k = int(np.argmin(decay))
    return float(decay[k]), grid[k]


UI_LOOP_RESOLUTION = 2.0 ** -14
"""The smallest committable rate, as a fraction of the ceiling (a 14-step bisection's resolution)."""


def certify_ui_loop(data: ObserverData, solver, min_margin: float = 0.0) -> UILoopCertificate:
    """Prove that the observer's full error, UI filter loop closed, contracts over the whole box.

    At design time the decay rate beta committed is the largest number of two significant digits
    that is UI_LOOP_BACKOFF of a rate a common Lyapunov function certifies (analysis solves below
    the dense grid's slowest decay, the ceiling: :func:`codegen.design.rates.largest_holding`), solved once more as a
    design problem: that solution goes to
    the design lock with its beta and Tf, and every later ``generate`` re-checks the committed
    matrices block by block (numpy) instead of solving (``solver``: :mod:`codegen.design.solver`).

    ``min_margin`` > 0 (``[design] precision = "float32"``): the decay must give a contraction
    margin ``1 - c >= min_margin`` per step, else DiscretizationError with the largest one found.

    Raises
    ------
    UILoopError
        when no common Lyapunov function exists at this filter constant: the message gives what
        was measured (the dense-grid decay, the filter constants that do certify).
    """
    from ...design.precision import rate_for_backward_euler
    need = rate_for_backward_euler(min_margin, data.Ts)
    committed = solver.committed_data(UI_LOOP_PROBLEM)
    if committed is not None:
        beta = float(committed["beta"])
    else:
        ceiling, at = slowest_grid_decay(data)
        if ceiling <= 0:
            message, remedy = _ui_loop_advice(data, ceiling, at)
            raise UILoopError(message, remedy=remedy)

        def holds(q):       # the committed rate q is UI_LOOP_BACKOFF of a feasible one
            return _ui_loop_feasible(data, q / UI_LOOP_BACKOFF, data.Tf, solver)
        best = rates.largest_holding(rates.committable_rates(UI_LOOP_BACKOFF * ceiling, 2, UI_LOOP_RESOLUTION), holds)
        # a decay of 0 is proven by any rate that holds: it is asked only when none does
        if best is None and not _ui_loop_feasible(data, 0.0, data.Tf, solver):
            message, remedy = _ui_loop_advice(data, ceiling, at)
            raise UILoopError(message, remedy=remedy)
        lo = 0.0 if best is None else best / UI_LOOP_BACKOFF
        if lo < need and not (need <= ceiling and _ui_loop_feasible(data, need, data.Tf, solver)):
            c = 1.0 / np.sqrt(1.0 + 2.0 * lo * data.Ts)
            raise DiscretizationError(
                f"[design] precision = \"float32\" needs the UI-filter loop to decay at {need:.4g} 1/s (a contraction "
                f"margin {min_margin:g} per step at Ts = {data.Ts:g} s); its common Lyapunov function certifies at most "
                f"{lo:.4g} 1/s (margin {1 - c:.4g}). Options: [design] alpha (the state error's decay), "
                f"[ui_filter] time_constant, or a smaller [design] float32_margin")
        # committed inside the feasible set, not on its edge: the re-check keeps a margin
        beta = max(best or 0.0, need)
    try:
        sol = solver.solve(_ui_loop_problem(data, beta, data.Tf, design=True), tol=1e-9)
    except (SolverError, CertificateError) as exc:
        raise DiscretizationError(f"the UI filter loop's certificate at decay {beta:g} 1/s failed: {exc}") from None
    # the LMIs see the unknown inputs divided by ui_scaling: back to their own units
    scale = np.concatenate([np.ones(data.nx), 1.0 / ui_scaling(data.poly)])
    P = scale[:, None] * np.asarray(sol["P"], dtype=float) * scale[None, :]
    return UILoopCertificate(beta, data.Ts, len(sol.checks), float(sol.worst.relative_margin), 0.5 * (P + P.T),
                             ui_loop_multipliers(data.poly.n_vertices))


def _ui_loop_advice(data: ObserverData, ceiling: float, at) -> tuple:
    """(message, remedy) of what would certify the UI filter loop, measured: the filter constants
    tried, and where the loop is unstable on the dense grid; remedy {"ui_filter.time_constant": T_f}
    the slowest-but-first constant that certifies, or {} when none does."""
    where = ", ".join(f"{sym} = {v:.4g}" for sym, v in zip(data.poly.signals, np.atleast_1d(at)))
    head = (f"the observer's error with the UI filter loop (Tf = {data.Tf:g} s) has no common Lyapunov function "
            f"over the scheduling box")
    if ceiling <= 0:
        head += f" (it is unstable at {where}: eigenvalue with real part {-ceiling:.4g} 1/s)"
    # no box advice: a narrowed box changes the polytope and so the gains, and the slowest point of
    # the new design moves with its edge (issue 42): only what was measured here is said
    for factor in (2, 5, 10, 20, 50):
        Tf = data.Tf * factor
        if slowest_grid_decay(data, Tf, n_grid=101)[0] > 0 and _ui_loop_feasible(data, 0.0, Tf):
            return (f"{head}; measured: [ui_filter] time_constant = {Tf:g} s certifies it (a slower unknown-input "
                    f"estimate)", {"ui_filter.time_constant": float(f"{Tf:g}")})
    return (f"{head}; measured: no filter constant up to {50 * data.Tf:g} s certifies it (the gains close an "
            f"unstable loop through the UI filter)", {})


def loop_is_certifiable(data: ObserverData) -> bool:
    """Whether :func:`certify_ui_loop` would succeed (decay 0), without committing anything."""
    return slowest_grid_decay(data, n_grid=101)[0] > 0 and _ui_loop_feasible(data, 0.0, data.Tf)


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
    ui_loop: UILoopCertificate        # the full step, UI filter loop closed: proven over the box

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
                "dense_grid_points": self.grid_points,
                "ui_loop_certified_decay_rate": self.ui_loop.beta,
                "ui_loop_contraction_per_step": self.ui_loop.contraction,
                "ui_loop_lmi_blocks": self.ui_loop.blocks,
                "ui_loop_multipliers": self.ui_loop.multipliers}


def certify_step(data: ObserverData, alpha: float, solver, n_grid: int = 2001, min_margin: float = 0.0) -> DiscreteCertificate:
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

    The full error with the UI filter loop is proven to contract by :func:`certify_ui_loop`.
    The step is refused unless both certificates hold.
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
    Aa = augmented_state_matrices(data, _grid_premises(poly, sig))
    aug_r = np.abs(np.linalg.eigvals(np.linalg.inv(np.eye(data.nz) - Ts * Aa))).max(axis=1).tolist()
    err_r = np.abs(np.linalg.eigvals(np.linalg.inv(np.eye(nx) - Ts * Aa[:, :nx, :nx]))).max(axis=1).tolist()
    k = int(np.argmax(aug_r))
    if kappa <= 1.0:
        raise DiscretizationError(
            f"cannot certify the Ts={Ts:g} s step: kappa = 1 + 2 alpha Ts - {worst:.4g} = {kappa:.6f} <= 1 "
            f"(the Lyapunov matrix varies too fast between samples); lower Ts, raise alpha, or use "
            f"the quadratic design")
    ui_loop = certify_ui_loop(data, solver, min_margin)
    # the proof implies the evidence (He(P Aa) < 0 makes every backward-Euler step contract)
    if max(err_r) >= 1.0 or aug_r[k] >= 1.0:
        raise CertificateError(f"the certified Ts={Ts:g} s step has a dense-grid spectral radius "
                               f"{max(max(err_r), aug_r[k]):.6f} >= 1: the certificates contradict the evidence")
    return DiscreteCertificate(Ts, kappa, worst, max(err_r), aug_r[k], float(sig[k][0]), len(sig), ui_loop)
