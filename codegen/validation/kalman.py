"""Kalman filters generated from a symbolic model: the linear KF and the EKF baselines.

One builder for both. :func:`kalman_model` takes a :class:`~codegen.model.ModelDefinition`
(``x_dot = f(x, u, w; rho)``, outputs ``y = h(x, u; rho)``), substitutes the parameter values,
converts the sympy expressions to CasADi and differentiates them there, once:

* ``A = df/dx``, ``B = df/du``, ``G = df/dw`` (process-noise inputs), ``C = dh/dx``, ``D = dh/du``;
* the unknown inputs ``w`` of the definition are zero-mean process noise (``w = 0`` in the mean
  propagation and in ``h``); a known input may also carry process noise (the source repository's
  KF puts it on the steering angle).

:func:`linear_kalman_filter` and :func:`extended_kalman_filter` then build one filter step as a
CasADi function and run it over the whole record with ``mapaccum`` (one call, no Python loop).
Both discretize at the record's sample time ``dt`` on the *previous* sample's inputs and scheduling
signals (``u[k-1]``, ``rho[k-1]``), as the source repository's MATLAB filter does:

* prediction: forward Euler ``x + dt f(x, u[k-1], 0; rho[k-1])`` (linear KF: ``A_d x + B_d u`` with
  ``A_d = I + dt A``, ``B_d = dt B``), or one Heun (RK2) step whose second stage uses
  ``u[k]``, ``rho[k]`` (EKF);
* covariance: ``P- = F P F^T + dt^2 G Sigma G^T`` with ``F = I + dt A`` at ``(x, u[k-1], rho[k-1])``
  and ``G`` there (linear KF with noise on an input: ``Q_d = B_d q B_d^T``);
* correction with ``y[k]`` and ``u[k]``, ``rho[k]``: ``S = H P- H^T + R``, ``K = P- H^T S^-1``,
  ``x = x- + K (y - h(x-))``, ``P = (I - K H) P-`` (symmetrized for the EKF);
* the estimate at sample 0 is ``x0``.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np
import sympy as sp

from ..emit.stepgen import CASADI_FUNCTIONS
from ..errors import ModelDefinitionError, SampleError
from ..model import ModelDefinition

__all__ = ["KalmanModel", "kalman_model", "FilterResult", "linear_kalman_filter", "extended_kalman_filter",
           "unscented_kalman_filter",
           "to_casadi"]

_CASADI_NAMESPACE = CASADI_FUNCTIONS     # the toolchain's one table (codegen.emit.stepgen)


def to_casadi(exprs, symbols, values) -> list:
    """sympy expressions -> CasADi expressions, with ``symbols`` replaced by ``values`` (SX).

    Raises
    ------
    ModelDefinitionError
        An expression uses a function with no CasADi counterpart here (e.g. Piecewise, sign).
    """
    fn = _compiled(tuple(symbols), tuple(sp.sympify(e) for e in exprs))
    try:
        out = fn(*values)
    except (TypeError, RuntimeError, NotImplementedError) as exc:
        raise ModelDefinitionError(
            f"cannot convert to CasADi ({exc}); the models of the Kalman baselines may use "
            f"{', '.join(sorted(_CASADI_NAMESPACE))} and arithmetic") from None
    return [ca.SX(o) for o in out]


@functools.lru_cache(maxsize=16)
def _compiled(symbols: tuple, exprs: tuple):
    """The expressions compiled once per process: the parameters are arguments (``kalman_model`` passes
    their values), so the Kalman runs of ``uiogen fit``, one per tyre set and noise level, print a tyre law
    once (sympy's printing is most of a Kalman model's time) and give the same CasADi graph."""
    return sp.lambdify(list(symbols), list(exprs), [_CASADI_NAMESPACE, "math"])


@dataclass(frozen=True, eq=False)
class KalmanModel:
    """A symbolic model with its numbers substituted, as CasADi functions built once.

    Attributes
    ----------
    name : str
        Name of the model definition.
    states, inputs, noise, scheduling, outputs : tuple of str
        Signal names in vector order; ``noise`` are the process-noise inputs (the definition's
        unknown inputs, then any known inputs named as noisy).
    f : casadi.Function
        ``(x, u, w, rho) -> x_dot``.
    h : casadi.Function
        ``(x, u, rho) -> y`` (at ``w = 0``).
    jacobians : casadi.Function
        ``(x, u, rho) -> (A, B, G, C, D)`` at ``w = 0``: derivatives of f with respect to x, u and the
        noise inputs, of h with respect to x and u.
    linear : bool
        True when f and h are affine in (x, u, w), i.e. A, B, G, C, D depend on rho only (checked on
        the CasADi expressions).
    """

    name: str
    states: tuple
    inputs: tuple
    noise: tuple
    scheduling: tuple
    outputs: tuple
    f: ca.Function
    h: ca.Function
    jacobians: ca.Function
    linear: bool

    @property
    def nx(self) -> int:
        return len(self.states)

    @property
    def ny(self) -> int:
        return len(self.outputs)

    def matrices(self, rho) -> tuple:
        """Numeric (A, B, G, C, D) of a linear model at one scheduling point ``rho``."""
        if not self.linear:
            raise ModelDefinitionError(f"model {self.name!r} is not linear in its states and inputs")
        zx, zu = np.zeros(self.nx), np.zeros(len(self.inputs))
        return tuple(np.array(m.full()) for m in self.jacobians(zx, zu, np.atleast_1d(np.asarray(rho, float))))


def kalman_model(definition: ModelDefinition, values, outputs=None, noisy_inputs=()) -> KalmanModel:
    """Substitute ``values`` into ``definition`` and compile f, h and their Jacobians with CasADi.

    Parameters
    ----------
    definition : ModelDefinition
        States, known inputs, unknown inputs (process noise), scheduling signals (measured inputs,
        not derived ones), outputs, parameters.
    values : mapping of str to float
        A value for every parameter of the definition (extra keys are ignored).
    outputs : sequence of str, optional
        Measured outputs, in the order of the measurement vector; default: all, in definition order.
    noisy_inputs : sequence of str, optional
        Known inputs that also carry process noise (their columns of B join G).

    Returns
    -------
    KalmanModel

    Raises
    ------
    ModelDefinitionError
        Missing parameter values, unknown output or input names, derived scheduling signals,
        or an expression CasADi cannot take.
    """
    missing = [str(p) for p in definition.parameters if str(p) not in values]
    if missing:
        raise ModelDefinitionError(f"model {definition.name!r}: no value for parameter(s) {', '.join(missing)}")
    derived = [str(s.symbol) for s in definition.scheduling if s.derived is not None]
    if derived:
        raise ModelDefinitionError(f"model {definition.name!r}: derived scheduling signal(s) {', '.join(derived)} "
                                   f"are not supported by the Kalman baselines; pass them as measured signals")
    names = dict(definition.outputs)
    outputs = tuple(outputs) if outputs is not None else definition.output_names
    unknown = [o for o in outputs if o not in names]
    if unknown or not outputs:
        raise ModelDefinitionError(f"model {definition.name!r} has outputs {definition.output_names}, "
                                   f"not {unknown or 'none'}")
    known = [str(u) for u in definition.known_inputs]
    bad = [n for n in noisy_inputs if n not in known]
    if bad:
        raise ModelDefinitionError(f"model {definition.name!r}: noisy input(s) {bad} are not known inputs {known}")
    nx, nu, nw = len(definition.states), len(definition.known_inputs), len(definition.unknown_inputs)
    x, u = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    w, rho = ca.SX.sym("w", nw), ca.SX.sym("rho", len(definition.scheduling))
    symbols = [*definition.states, *definition.known_inputs, *definition.unknown_inputs,
               *(s.symbol for s in definition.scheduling), *definition.parameters]
    args = [*ca.vertsplit(x), *ca.vertsplit(u), *ca.vertsplit(w), *ca.vertsplit(rho),
            *(float(values[str(p)]) for p in definition.parameters)]
    f = ca.vertcat(*to_casadi(list(definition.dynamics), symbols, args))
    h = ca.vertcat(*to_casadi([names[o] for o in outputs], symbols, args))
    h = ca.substitute(h, w, ca.DM.zeros(nw))
    noise = ca.vertcat(w, *(u[known.index(n)] for n in noisy_inputs))
    A, B, G = ca.jacobian(f, x), ca.jacobian(f, u), ca.jacobian(f, noise)
    C, D = ca.jacobian(h, x), ca.jacobian(h, u)
    # affine in (x, u, w) <=> no first derivative depends on them
    linear = not any(ca.depends_on(mat, ca.vertcat(x, u, w)) for mat in (A, B, ca.jacobian(f, w), C, D))
    at_zero_w = [ca.substitute(mat, w, ca.DM.zeros(nw)) for mat in (A, B, G, C, D)]
    return KalmanModel(
        name=definition.name, states=definition.state_names, inputs=tuple(known),
        noise=(*(str(s) for s in definition.unknown_inputs), *noisy_inputs),
        scheduling=tuple(str(s.symbol) for s in definition.scheduling), outputs=outputs,
        f=ca.Function(f"{definition.name}_f", [x, u, w, rho], [f], ["x", "u", "w", "rho"], ["x_dot"]),
        h=ca.Function(f"{definition.name}_h", [x, u, rho], [h], ["x", "u", "rho"], ["y"]),
        jacobians=ca.Function(f"{definition.name}_jac", [x, u, rho], at_zero_w, ["x", "u", "rho"],
                              ["A", "B", "G", "C", "D"]),
        linear=linear)


@dataclass(frozen=True, eq=False)
class FilterResult:
    """Estimates of a Kalman filter over a record.

    Attributes
    ----------
    x : ndarray, shape (n, nx)
        State estimate per sample (``x0`` at sample 0).
    P : ndarray, shape (n, nx, nx)
        Its covariance (``P0`` at sample 0).
    """

    x: np.ndarray
    P: np.ndarray


def _column(a, n: int, width: int, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.size == n * width:
        a = a.reshape(n, width)
    if a.shape != (n, width):
        raise SampleError(f"{what}: expected {n} samples of {width} value(s), got shape {np.shape(a)}")
    if not np.all(np.isfinite(a)):
        raise SampleError(f"{what}: non-finite values")
    return a


def _covariance(m, k: int, what: str) -> np.ndarray:
    m = np.atleast_2d(np.asarray(m, dtype=float))
    if m.shape != (k, k) or not np.all(np.isfinite(m)) or not np.allclose(m, m.T):
        raise ModelDefinitionError(f"{what} must be a finite symmetric {k}x{k} matrix, got {m.tolist()}")
    if k and np.linalg.eigvalsh(m).min() < 0:
        raise ModelDefinitionError(f"{what} must be positive semi-definite")
    return m


def _filter(model: KalmanModel, u, y, rho, dt, R, Sigma, x0, P0, update, name: str, what: str) -> FilterResult:
    """Check a record and run one symbolic filter step over it with ``mapaccum``.

    ``update(x, P, u0, r0, u1, r1, yk, R, Sigma, dt)`` builds the CasADi expressions of the next
    (x, P) from the previous sample's inputs (u0, r0), the current ones (u1, r1) and y[k]; the
    filters differ only there."""
    y = np.asarray(y, dtype=float)
    n = y.shape[0] if y.ndim else 0
    if n < 2:
        raise SampleError(f"a Kalman filter run needs at least 2 samples, got {n}")
    nx, nu, ny, nw = model.nx, len(model.inputs), model.ny, len(model.noise)
    u, y = _column(u, n, nu, "inputs"), _column(y, n, ny, "measurements")
    rho = _column(rho, n, len(model.scheduling), "scheduling signals")
    if not (np.isfinite(dt) and dt > 0):
        raise SampleError(f"sample time must be > 0, got {dt!r}")
    R, Sigma, P0 = _covariance(R, ny, "R"), _covariance(Sigma, nw, "Sigma"), _covariance(P0, nx, "P0")
    x0 = _column(x0, 1, nx, "x0")[0]
    # one step, symbolic: z = (x, vec P), inputs (u[k-1], rho[k-1], u[k], rho[k], y[k])
    z = ca.SX.sym("z", nx + nx * nx)
    nr = rho.shape[1]
    u0, r0, u1, r1 = ca.SX.sym("u0", nu), ca.SX.sym("rho0", nr), ca.SX.sym("u1", nu), ca.SX.sym("rho1", nr)
    yk = ca.SX.sym("y", ny)
    x, P = z[:nx], ca.reshape(z[nx:], nx, nx)
    xn, Pn = update(x, P, u0, r0, u1, r1, yk, R, Sigma, dt)
    step = ca.Function(name, [z, ca.vertcat(u0, r0, u1, r1, yk)], [ca.vertcat(xn, ca.vec(Pn))])
    columns = np.hstack([u[:-1], rho[:-1], u[1:], rho[1:], y[1:]]).T
    z0 = np.concatenate([x0, P0.reshape(-1, order="F")])
    zs = np.array(step.mapaccum(n - 1)(z0, columns).full()).T
    xs = np.vstack([x0, zs[:, :nx]])
    Ps = np.concatenate([P0[None], zs[:, nx:].reshape(n - 1, nx, nx).transpose(0, 2, 1)])
    if not np.all(np.isfinite(xs)):
        raise SampleError(f"{what} on {model.name!r} diverged (non-finite estimate)")
    return FilterResult(x=xs, P=Ps)


def _heun(model: KalmanModel, s, u0, r0, u1, r1, dt):
    """The Heun (RK2) prediction from sample k-1 to k, without process noise."""
    zero_w = ca.DM.zeros(model.f.size1_in(2), 1)
    k1 = model.f(s, u0, zero_w, r0)
    return s + 0.5 * dt * (k1 + model.f(s + dt * k1, u1, zero_w, r1))


def _run(model: KalmanModel, u, y, rho, dt, R, Sigma, x0, P0, heun: bool, symmetrize: bool) -> FilterResult:
    """The (extended) Kalman filter: Jacobians from CasADi, Euler covariance prediction."""
    nx = model.nx

    def update(x, P, u0, r0, u1, r1, yk, R, Sigma, dt):
        A, B, G, _, _ = model.jacobians(x, u0, r0)
        F = ca.DM.eye(nx) + dt * A
        if heun:
            xp = _heun(model, x, u0, r0, u1, r1, dt)
        else:                                         # linear model: A_d x + B_d u (forward Euler)
            xp = F @ x + (dt * B) @ u0
        Pp = F @ P @ F.T + (dt * G) @ ca.DM(Sigma) @ (dt * G).T
        H = model.jacobians(xp, u1, r1)[3]
        S = H @ Pp @ H.T + ca.DM(R)
        K = ca.solve(S.T, (Pp @ H.T).T).T
        xn = xp + K @ (yk - model.h(xp, u1, r1))
        Pn = (ca.DM.eye(nx) - K @ H) @ Pp
        if symmetrize:
            Pn = 0.5 * (Pn + Pn.T)
        return xn, Pn
    return _filter(model, u, y, rho, dt, R, Sigma, x0, P0, update, "kalman_step", "Kalman filter")


def linear_kalman_filter(model: KalmanModel, u, y, rho, dt: float, R, Sigma, x0, P0) -> FilterResult:
    """Linear Kalman filter on a linear symbolic model (forward Euler on the previous sample).

    ``A_d = I + dt A(rho[k-1])``, ``B_d = dt B(rho[k-1])``, prediction ``A_d x + B_d u[k-1]``,
    ``Q_d = dt^2 G Sigma G^T`` (``= B_d q B_d^T`` for noise on an input), correction with
    ``C(rho[k])``, ``D(rho[k])``; see the module docstring.

    Parameters
    ----------
    model : KalmanModel
        Must be linear (:attr:`KalmanModel.linear`).
    u : array, shape (n, n_u)
        Known inputs per sample.
    y : array, shape (n, n_y)
        Measurements in ``model.outputs`` order.
    rho : array, shape (n, n_rho)
        Scheduling signals.
    dt : float
        Sample time [s].
    R, Sigma, P0 : array
        Measurement-noise covariance, process-noise covariance (of ``model.noise``), initial covariance.
    x0 : array
        Initial state (the estimate reported at sample 0).

    Returns
    -------
    FilterResult

    Raises
    ------
    ModelDefinitionError
        Nonlinear model, bad covariance.
    SampleError
        Bad signal shapes or values, fewer than 2 samples, divergence.
    """
    if not model.linear:
        raise ModelDefinitionError(f"model {model.name!r} is not linear in its states and inputs; "
                                   f"use extended_kalman_filter")
    return _run(model, u, y, rho, dt, R, Sigma, x0, P0, heun=False, symmetrize=False)


def extended_kalman_filter(model: KalmanModel, u, y, rho, dt: float, R, Sigma, x0, P0) -> FilterResult:
    """Extended Kalman filter on a symbolic model: Heun prediction, Jacobians from CasADi.

    Same arguments and errors as :func:`linear_kalman_filter`; any model. The covariance uses the
    Euler part of the step (``F = I + dt A(x, u[k-1], rho[k-1])``) and is symmetrized after the
    correction.
    """
    return _run(model, u, y, rho, dt, R, Sigma, x0, P0, heun=True, symmetrize=True)


def unscented_kalman_filter(model: KalmanModel, u, y, rho, dt: float, R, Sigma, x0, P0) -> FilterResult:
    """Unscented Kalman filter on a symbolic model (Julier & Uhlmann 2004; Wan & van der Merwe 2000).

    Same arguments and errors as :func:`extended_kalman_filter`, no Jacobian of the dynamics or
    the outputs in the update: 2 n + 1 sigma points of (x, P) with alpha = 1, beta = 0,
    kappa = 3 - n (weights W_0 = (3 - n)/3, W_i = 1/6), each propagated by the same Heun step on
    ``u[k-1], rho[k-1]`` -> ``u[k], rho[k]``; additive process noise ``dt^2 G Sigma G^T`` with
    ``G`` at the mean; sigma points redrawn from the prediction for the correction with ``y[k]``.
    One CasADi step run with ``mapaccum`` over the record.
    """
    nx, ny = model.nx, model.ny
    lam = 3.0 - nx                                    # alpha = 1, kappa = 3 - n: n + lambda = 3
    w0, wi = lam / (nx + lam), 1.0 / (2.0 * (nx + lam))
    weights = [w0] + [wi] * (2 * nx)

    def sigma_points(m, C):
        Lc = ca.chol(0.5 * (C + C.T)).T * np.sqrt(nx + lam)     # lower factor: Lc Lc' = (n + lambda) C
        return [m] + [m + Lc[:, i] for i in range(nx)] + [m - Lc[:, i] for i in range(nx)]

    def update(x, P, u0, r0, u1, r1, yk, R, Sigma, dt):
        X = [_heun(model, s, u0, r0, u1, r1, dt) for s in sigma_points(x, P)]
        xp = sum((w * s for w, s in zip(weights, X)), ca.DM.zeros(nx, 1))
        G = model.jacobians(x, u0, r0)[2]
        Pp = sum((w * (s - xp) @ (s - xp).T for w, s in zip(weights, X)), ca.DM.zeros(nx, nx)) \
            + (dt * G) @ ca.DM(Sigma) @ (dt * G).T
        Xc = sigma_points(xp, Pp)
        Y = [model.h(s, u1, r1) for s in Xc]
        yp = sum((w * s for w, s in zip(weights, Y)), ca.DM.zeros(ny, 1))
        S = sum((w * (s - yp) @ (s - yp).T for w, s in zip(weights, Y)), ca.DM(R))
        Pxy = sum((w * (a - xp) @ (b - yp).T for w, a, b in zip(weights, Xc, Y)), ca.DM.zeros(nx, ny))
        K = ca.solve(S.T, Pxy.T).T
        Pn = Pp - K @ S @ K.T
        return xp + K @ (yk - yp), 0.5 * (Pn + Pn.T)
    return _filter(model, u, y, rho, dt, R, Sigma, x0, P0, update, "ukf_step", "unscented Kalman filter")
