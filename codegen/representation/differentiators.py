"""Levant's arbitrary-order robust exact differentiator (HOSMD) as a discrete-time block.

Seeds 002 (Ichalal & Mammar 2015, ref. [20]) and 003 (Sentouh et al. 2023, ref. [36]) obtain the
output derivatives their observers need from the higher-order sliding-mode differentiator of

    A. Levant, "Higher-order sliding modes, differentiation and output-feedback control",
    Int. J. Control 76(9/10), 924-941, 2003.

In its non-recursive form, for a signal f whose k-th derivative has Lipschitz constant L
(|f^(k+1)| <= L), with sigma = z_0 - f::

    dz_i/dt = -lt_{k-i} L^((i+1)/(k+1)) |sigma|^((k-i)/(k+1)) sign(sigma) + z_{i+1},  i = 0..k-1
    dz_k/dt = -lt_0 L sign(sigma)

z_i converges in finite time to f^(i) and, with measurement noise bounded by eps, keeps
|z_i - f^(i)| = O(L^(i/(k+1)) eps^((k+1-i)/(k+1))).  The non-recursive gains lt follow from Levant's
recursive sequence lambda = (1.1, 1.5, 2, 3, 5, 8) (Levant 2003, valid for k <= 5) by substituting
one recursion level into the next: lt_k = lambda_k, lt_j = lambda_j lt_{j+1}^(j/(j+1)).

Discretization
--------------
Writing the correction as a state-dependent linear gain, lt_{k-i} L^((i+1)/(k+1)) |sigma|^(...) sign
sigma = l_i(sigma) sigma with l_i = lt_{k-i} rho^(i+1), rho = (L/|sigma|)^(1/(k+1)), the frozen error
dynamics have the eigenvalues rho*nu_j, nu_j the roots of p(nu) = nu^(k+1) + lt_k nu^k + ... + lt_0.
We use the eigenvalue-matching discretization of

    S. Koch, M. Reichhartinger, M. Horn, L. Fridman, "Discrete-time implementation of homogeneous
    differentiators", IEEE Trans. Autom. Control 65(2), 757-762, 2020

(the ``m = 1`` mode of the Robust Exact Differentiator Toolbox, Andritsch et al., ICM 2021)::

    z_{j+1} = Phi z_j - ell(sigma_j) sigma_j,    sigma_j = z_{0,j} - f_j,

Phi = exp(A tau) the exact (Taylor) transition of the integrator chain, and ell(sigma) the gain that
gives Phi - ell c^T the eigenvalues exp(tau rho nu_j) (Ackermann's formula).  The toolbox places all
k+1 eigenvalues at one point; here they are Levant's (distinct) gain-polynomial roots, so the
defaults are the standard Levant gains.  Why this scheme and not another:

* explicit Euler, and its Taylor-term refinement (Livne & Levant, "Proper discretization of
  homogeneous differentiators", Automatica 50(8), 2014), keep discretization chattering: z_k jumps
  by +-lt_0 L tau every sample, so a noise-free polynomial is never differentiated exactly;
* implicit discretizations (e.g. R. Seeber, "Proper implicit discretization of arbitrary-order
  robust exact differentiators", arXiv:2404.02770, 2024) remove the chattering but need an
  iterative scalar root solve per sample, i.e. no fixed-cost closed form in the generated C;
* the matching scheme is explicit and fixed-cost (one root of |sigma| -- sqrt for k = 1 and 3, pow
  otherwise -- one division, one exp per real root and one exp and one sin per complex pair),
  reduces to the explicit Euler step of Levant's differentiator when tau*rho -> 0 (large errors),
  and becomes dead-beat as sigma -> 0.  Noise free, on polynomials of degree <= k, the errors
  contract faster than any exponential and sit at the round-off floor after finitely many samples
  (exactly dead-beat once every exp(tau rho nu_j) underflows); with bounded noise the errors
  follow the accuracy asymptotics above.  ``tests/representation/test_differentiators.py`` checks both (the noise
  exponents are fitted, not assumed).

The estimate convention: the state z_j (before the update with f_j) estimates
(f, f', ..., f^(k)) at t_j from f_0..f_{j-1}, a one-sample predictor; it is exact for polynomials.

Numerics
--------
* the coefficients of the discrete characteristic polynomial are built around z = 1
  (w = z - 1, roots delta_j = 1 - exp(tau rho nu_j)), and the gain as sum_j b_j (Phi - I)^j O^-1 e_k,
  so no O(1) terms cancel when the eigenvalues approach 1.  The step computes exp(x) - 1 where
  expm1(x) would be exact: glibc's expm1 has twice the latency of exp on the step's critical path
  (k = 1: 55 instead of 47 ns).  The price is a relative error of ~1e-16/|x| in the gains when
  x = tau*rho*nu is small, i.e. for errors |sigma| >> L tau^(k+1) where the gains are tiny anyway
  (they round to 0 only beyond |sigma| ~ L (1e16 tau |nu|)^(k+1), 1e25 L for k = 1, tau = 1 ms);
  the numpy reference uses expm1, and the tests bound the difference by exactly that;
* q = tau*rho = c / max(|sigma|^(1/(k+1)), c/q_max) with c = tau L^(1/(k+1)): pow has a positive
  exponent (pow(0, p) = 0, no division by zero, no inf, no NaN at sigma = 0), and q_max is where
  every exp(q nu_j) underflows to 0, so at sigma = 0 the step is exactly the dead-beat step and it is
  continuous in sigma; no sign function is needed (ell(sigma) sigma -> 0 as sigma -> 0).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.linalg import expm

from . import canonical
from ..errors import ModelDefinitionError, SampleError

# Levant (2003), Int. J. Control 76(9/10): lambda_0..lambda_5 of the recursive form, "suitable for k <= 5".
LEVANT_RECURSIVE_GAINS = (1.1, 1.5, 2.0, 3.0, 5.0, 8.0)
MAX_ORDER = len(LEVANT_RECURSIVE_GAINS) - 1

# exp(x) == 0.0 in IEEE double for x < -745.14; q_max puts the slowest eigenvalue past that point.
_UNDERFLOW_EXPONENT = 750.0


def levant_gains(order: int) -> tuple:
    """Non-recursive gains (lt_0, ..., lt_k) from Levant's recursive sequence.

    Parameters
    ----------
    order : int
        Differentiation order k, 1 <= k <= ``MAX_ORDER``.

    Returns
    -------
    tuple of float
        ``lt[j]`` multiplies ``L^((k-j+1)/(k+1)) |sigma|^(j/(k+1)) sign(sigma)`` in the equation of
        z_{k-j}; e.g. k = 2 gives (1.1, 2.12, 2.0).
    """
    _check_order(order)
    lt = [0.0] * (order + 1)
    lt[order] = LEVANT_RECURSIVE_GAINS[order]
    for j in range(order - 1, -1, -1):
        lt[j] = LEVANT_RECURSIVE_GAINS[j] * lt[j + 1] ** (j / (j + 1))
    return tuple(lt)


def _check_order(order) -> None:
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)):
        raise ModelDefinitionError(f"differentiator order must be an integer, got {order!r}")
    if not 1 <= order <= MAX_ORDER:
        raise ModelDefinitionError(f"differentiator order must be in 1..{MAX_ORDER} (Levant's gain sequence), "
                                   f"got {order}")


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ModelDefinitionError(f"differentiator {name} must be a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ModelDefinitionError(f"differentiator {name} must be finite and > 0, got {value!r}")
    return v


@dataclass(frozen=True)
class HosmdSpec:
    """One differentiator: order, Lipschitz constant, sample time and gains.

    Parameters
    ----------
    order : int
        k, the highest derivative estimated (1..``MAX_ORDER``); the state has k+1 entries.
    lipschitz : float
        L > 0, a Lipschitz constant of f^(k) (a bound of |f^(k+1)|), in signal units / s^(k+1).
    sample_time : float
        tau > 0 in seconds.
    gains : tuple of float, optional
        Non-recursive gains (lt_0, ..., lt_k); default ``levant_gains(order)``.  Custom gains must
        be positive and make nu^(k+1) + lt_k nu^k + ... + lt_0 Hurwitz.
    name : str, optional
        Label used in messages and generated code.

    Raises
    ------
    ModelDefinitionError
        If any field is out of range (the differentiators are part of an observer configuration).
    """

    order: int
    lipschitz: float
    sample_time: float
    gains: tuple = ()
    name: str = "hosmd"
    _roots: tuple = field(default=(), init=False, repr=False, compare=False)

    def __post_init__(self):
        _check_order(self.order)
        object.__setattr__(self, "order", int(self.order))
        object.__setattr__(self, "lipschitz", _positive("Lipschitz constant", self.lipschitz))
        object.__setattr__(self, "sample_time", _positive("sample time", self.sample_time))
        try:
            gains = tuple(self.gains) if len(self.gains) else levant_gains(self.order)
        except TypeError:
            raise ModelDefinitionError(f"differentiator {self.name!r}: gains must be a sequence of numbers, "
                                       f"got {self.gains!r}") from None
        if len(gains) != self.order + 1:
            raise ModelDefinitionError(f"differentiator {self.name!r}: order {self.order} needs "
                                       f"{self.order + 1} gains, got {len(gains)}")
        gains = tuple(_positive("gain", g) for g in gains)
        object.__setattr__(self, "gains", gains)
        # p(nu) = nu^(k+1) + lt_k nu^k + ... + lt_0 (numpy wants the highest power first)
        roots = np.array(canonical.polyroots([1.0, *gains[::-1]]))   # emitted: machine-independent
        if not np.all(roots.real < 0):
            raise ModelDefinitionError(f"differentiator {self.name!r}: gains {gains} do not make the gain "
                                       f"polynomial Hurwitz (roots {np.round(roots, 4).tolist()})")
        object.__setattr__(self, "_roots", tuple(complex(r) for r in roots))

    @property
    def n_state(self) -> int:
        return self.order + 1

    def initial_state(self, f0: float = 0.0) -> np.ndarray:
        """z = (f0, 0, ..., 0): the usual start from the first sample."""
        z = np.zeros(self.n_state)
        z[0] = f0
        return z


@dataclass(frozen=True)
class _Constants:
    real_roots: tuple     # real nu_j
    pairs: tuple          # (alpha, beta) of nu = alpha +- i beta, beta > 0
    Phi: np.ndarray       # exp(A tau)
    V: np.ndarray         # columns (Phi - I)^j O^-1 e_k, j = 0..k
    c: float              # tau L^(1/(k+1))
    q_floor: float        # c / q_max


@functools.lru_cache(maxsize=None)
def _constants(spec: HosmdSpec) -> _Constants:
    k, tau = spec.order, spec.sample_time
    n = k + 1
    real = sorted(r.real for r in spec._roots if abs(r.imag) <= 1e-12 * max(1.0, abs(r)))
    pairs = sorted((r.real, r.imag) for r in spec._roots if r.imag > 1e-12 * max(1.0, abs(r)))
    if len(real) + 2 * len(pairs) != n:
        raise ModelDefinitionError(f"differentiator {spec.name!r}: could not split the gain-polynomial roots "
                                   f"{spec._roots} into real roots and conjugate pairs")
    # Everything in time-scaled coordinates zeta_i = tau^i z_i, where Phi and O are pure numbers.
    Phi_s = np.array([[1.0 / math.factorial(j - i) if j >= i else 0.0 for j in range(n)] for i in range(n)])
    O_s = np.array([[float(m) ** j / math.factorial(j) for j in range(n)] for m in range(n)])  # rows c^T Phi^m
    # emitted constants: exact arithmetic (codegen.representation.canonical), the same on every machine
    g_s = canonical.solve(O_s, np.eye(n)[:, -1])
    N_s = Phi_s - np.eye(n)
    cols, v = [], g_s
    for j in range(n):
        cols.append(v)
        v = canonical.matmul(N_s, v)
    V_s = np.column_stack(cols)
    scale = np.array([tau ** -i for i in range(n)])
    Phi = Phi_s * scale[:, None] / scale[None, :]
    V = V_s * scale[:, None]
    slowest = min([-a for a in real] + [-a for a, _ in pairs])
    q_max = _UNDERFLOW_EXPONENT / slowest
    c = tau * spec.lipschitz ** (1.0 / n)
    return _Constants(tuple(real), tuple(pairs), Phi, V, c, c / q_max)


def _polymul(a: list, b: list) -> list:
    """Product of two coefficient lists (lowest power first); works on floats and SX alike."""
    out = [0] * (len(a) + len(b) - 1)
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i + j] = out[i + j] + x * y
    return out


def _step_sx(spec: HosmdSpec, z: list, sigma) -> list:
    """The step on SX scalars (real arithmetic only, constants folded in), given sigma = z_0 - f;
    z[0] is z_0 itself (Taylor coordinates) or sigma (error coordinates: the first entry of the
    result is then z_0+ - f, see :func:`hosmd_step_sx`)."""
    k = spec.order
    K = _constants(spec)
    mag = ca.fabs(sigma)
    root = ca.sqrt(mag) if k == 1 else ca.sqrt(ca.sqrt(mag)) if k == 3 else mag ** (1.0 / (k + 1))
    q = K.c / ca.fmax(root, K.q_floor)
    # characteristic polynomial of Phi - ell c^T in w = z - 1: prod (w + delta_j), delta = 1 - exp(q nu)
    poly = [1.0]
    for a in K.real_roots:
        poly = _polymul(poly, [1.0 - ca.exp(q * a), 1.0])
    for a, b in K.pairs:
        # (w + delta)(w + conj delta) with delta = 1 - e^{qa} e^{iqb}; in terms of em = e^{qa} - 1 and
        # u = 4 e^{qa} sin^2(qb/2): |delta|^2 = em^2 + u, 2 Re delta = u - 2 em (all terms >= 0)
        em = ca.exp(q * a) - 1.0
        s = ca.sin(0.5 * q * b)
        u = 4.0 * (1.0 + em) * (s * s)
        poly = _polymul(poly, [em * em + u, u - 2.0 * em, 1.0])
    nxt = []
    for i in range(k + 1):
        gain = 0.0
        for j in range(k + 1):
            gain = gain + K.V[i, j] * poly[j]
        acc = z[i]
        for j in range(i + 1, k + 1):
            acc = acc + K.Phi[i, j] * z[j]
        nxt.append(acc - gain * sigma)
    return nxt


@functools.lru_cache(maxsize=None)
def _reference_constants(spec: HosmdSpec):
    """The numpy reference derives its matrices on its own: expm of the scaled chain, observability
    matrix from powers of it (the SX step uses the closed-form factorial entries)."""
    n = spec.n_state
    Phi_s = expm(np.eye(n, k=1))
    obs = np.vstack([np.linalg.matrix_power(Phi_s, m)[0] for m in range(n)])
    g_s = np.linalg.solve(obs, np.eye(n)[:, -1])
    powers = [np.linalg.matrix_power(Phi_s - np.eye(n), j) @ g_s for j in range(n)]
    scale = spec.sample_time ** -np.arange(n, dtype=float)
    return Phi_s * np.outer(scale, 1.0 / scale), np.column_stack(powers) * scale[:, None]


def hosmd_step_numpy(spec: HosmdSpec, z, f: float, held: float | None = None) -> np.ndarray:
    """Reference step in numpy: the next differentiator state.

    An independent implementation of the same step (complex eigenvalues, ``numpy.poly``, matrices
    from ``scipy.linalg.expm``) that the CasADi step and the generated C are checked against.

    Parameters
    ----------
    spec : HosmdSpec
    z : array_like, shape (k+1,)
        Current state, the estimates of (f, f', ..., f^(k)) at the current sample; in error
        coordinates (``held`` given) its first entry is the estimate of f less ``held``.
    f : float
        Current sample of the signal.
    held : float, optional
        Error coordinates (:func:`hosmd_step_sx`): the sample the first entry is measured from;
        the result's first entry is then measured from ``f``.

    Returns
    -------
    numpy.ndarray, shape (k+1,)

    Raises
    ------
    SampleError
        If ``z`` has the wrong shape.
    """
    z = np.array(z, dtype=np.float64)
    if z.shape != (spec.n_state,):
        raise SampleError(f"differentiator {spec.name!r}: state must have shape ({spec.n_state},), got {z.shape}")
    n = spec.n_state
    Phi, V = _reference_constants(spec)
    nu = np.array(spec._roots)
    if held is None:
        sigma = float(z[0] - f)
    else:
        sigma = float(z[0] + (held - f))
        z[0] = sigma                     # Phi's first column is e_0: the result's first entry is z_0+ - f
    c = spec.sample_time * spec.lipschitz ** (1.0 / n)
    q = c / max(abs(sigma) ** (1.0 / n), c * np.max(nu.real) / -_UNDERFLOW_EXPONENT)
    delta = -np.expm1(q * nu)                          # complex; 1 - (discrete eigenvalue)
    b = np.poly(-delta)[::-1]                          # prod (w + delta_j), lowest power first
    return Phi @ z - (V @ b[:n].real) * sigma


def hosmd_run(spec: HosmdSpec, samples, z0=None) -> np.ndarray:
    """Run the CasADi step (the expression graph that becomes the C) over ``samples``, fast.

    Row j of the result is the state z_j, i.e. the estimates at sample j before the update with f_j
    (``z0`` default: ``spec.initial_state(samples[0])``).
    """
    samples = np.asarray(samples, dtype=np.float64).ravel()
    z = spec.initial_state(samples[0] if samples.size else 0.0) if z0 is None else np.asarray(z0, float)
    if samples.size == 0:
        return np.empty((0, spec.n_state))
    after = np.array(_function_cached(spec).mapaccum(samples.size)(z, samples[None, :])).T
    return np.vstack([z[None, :], after[:-1]])


def hosmd_step_sx(spec: HosmdSpec, z, f, held=None) -> ca.SX:
    """Next differentiator state as a CasADi SX expression, for embedding in an observer step.

    Error coordinates (``held`` given): the first state entry is the estimate of f less the
    sample the differentiator consumed last (``held``), and the result's first entry is the new
    estimate less ``f``; the other entries are the derivative estimates as in Taylor coordinates.
    The step is the same; what changes is its rounding. In Taylor coordinates z_0 is stored at
    the signal's scale, so in float32 it carries half a unit in the last place of |f| (6e-8 for a
    signal of order 1), and sigma = z_0 - f, the tracking error the gains multiply by up to
    tau^-k, inherits that whole error. In error coordinates the stored entry is the increment
    over one sample (of order tau |f'|), sigma = z[0] + (held - f) is formed from it and from an
    exact difference of two input samples, and its rounding is that of the increment's scale.

    Parameters
    ----------
    spec : HosmdSpec
    z : casadi.SX, shape (k+1, 1)
        Current differentiator state (part of the observer's state vector).
    f : casadi.SX, scalar
        Current sample of the differentiated signal.
    held : casadi.SX, scalar, optional
        The sample the first entry is measured from (error coordinates); default Taylor coordinates.

    Returns
    -------
    casadi.SX, shape (k+1, 1)
    """
    if z.shape != (spec.n_state, 1):
        raise SampleError(f"differentiator {spec.name!r}: state must be SX of shape ({spec.n_state}, 1), "
                          f"got {z.shape}")
    zs = [z[i] for i in range(spec.n_state)]
    if held is None:
        sigma = zs[0] - f
    else:
        sigma = zs[0] + (held - f)
        zs[0] = sigma                    # Phi's first column is e_0: the result's first entry is z_0+ - f
    return ca.vertcat(*_step_sx(spec, zs, sigma))


@functools.lru_cache(maxsize=64)
def _function_cached(spec: HosmdSpec) -> ca.Function:
    return hosmd_function(spec)


def hosmd_function(spec: HosmdSpec, name: str = "hosmd_step") -> ca.Function:
    """``name(z, f) -> z_next`` as a CasADi Function (tests, benchmarks, code generation)."""
    z = ca.SX.sym("z", spec.n_state)
    f = ca.SX.sym("f")
    return ca.Function(name, [z, f], [hosmd_step_sx(spec, z, f)], ["z", "f"], ["z_next"])
