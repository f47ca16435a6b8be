"""Structural facts of a model with its sensors: what the measured outputs allow, over the whole box.

From the Jacobians of ``x' = f(x, u, d)``, ``y = h(x, u, d)`` (:class:`~.subject.Equations`)
A = df/dx, D = df/dd, C = dh/dx, Dd = dh/dd, evaluated at the corners of the box (the vertices of
the scheduling box and, for a nonlinear model, of its state box) and at points between them:

* observability and detectability of the states from the outputs (Hautus/PBH test at every
  eigenvalue; the unobservable subspace names the states it contains);
* the unknown-input conditions the families need: rank D (every unknown input acts), the matching
  condition rank(C D) = rank(D) (every unknown input reaches an output in one derivative),
  left invertibility (the unknown inputs can be told apart from the outputs at all), the invariant
  zeros of (A, D, C, Dd) and where they sit, strong detectability (left invertible, every zero in
  Re s < 0: the condition for any observer that decouples the unknown inputs);
* the relative degree of every output with respect to every unknown input, and the output
  derivatives (HOSMD orders) an algebraic observer would need;
* what is estimable if not everything: the largest set of unknown inputs that can be told apart,
  and the states reconstructible whatever the unknown inputs (orthogonal to the largest
  output-nulling subspace V*), so a user can drop a wish instead of guessing.

Each fact says what it rests on (:data:`BASIS`): *exact* (symbolic over the whole box, or a
model whose Jacobians do not depend on the box: one evaluation is all of it) or *sampled*
(corners and points between them: evidence, not a proof between samples; for a nonlinear model
the linearization, a local fact). Proofs over the whole box come from the families
(:meth:`codegen.families.Family.applicability`: sound interval bounds, certified designs).
"""
from __future__ import annotations

import dataclasses
import itertools
import time
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from .subject import Subject

BASIS = {
    "exact": "exact: symbolic, on the whole box",
    "constant": "exact: the Jacobians do not depend on the box, one evaluation is all of it",
    "sampled": "evidence: box corners and points between them, not a proof between samples",
    "linearized": "evidence: the linearization at box corners and points between them (a local fact of a "
                  "nonlinear model)",
    "vertices": "at the vertices of the family's polytope, where its LMIs are imposed (a certified design then "
                "covers the whole box)",
    "proof": "proof over the whole box (sound interval bounds or a certified design)",
}

ZERO_TOL = 1e-8      # an invariant zero with Re >= -ZERO_TOL |A| is on the axis (not decaying)
RTOL = 1e-9          # rank decisions, relative to the largest singular value of the (scaled) matrix
MAX_CORNERS = 64     # box corners beyond this are sampled at random (a 13-state box has 2^13)


@dataclass(frozen=True)
class Fact:
    """One structural fact, in the model's own names.

    Attributes
    ----------
    key : str
        Machine name: ``ui_rank``, ``observability``, ``matching``, ``left_invertibility``,
        ``invariant_zeros``, ``strong_detectability``, ``relative_degree``.
    holds : bool or None
        Whether the condition holds everywhere it was checked (None: a statement, no condition).
    statement : str
        One sentence naming the signals.
    basis : str
        A key of :data:`BASIS`.
    fix : str
        The change that would make it hold ("" when it holds).
    detail : dict
        The numbers behind it (JSON).
    """

    key: str
    holds: bool | None
    statement: str
    basis: str
    fix: str = ""
    detail: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"key": self.key, "holds": self.holds, "statement": self.statement, "basis": self.basis,
                "fix": self.fix, "detail": self.detail}


@dataclass(frozen=True)
class Samples:
    """Where the Jacobians were evaluated: the first ``corners`` rows are box corners."""

    symbols: tuple
    values: np.ndarray
    corners: int
    all_corners: bool

    def __len__(self) -> int:
        return self.values.shape[0]

    def at(self, k: int) -> str:
        if not self.symbols:
            return "everywhere (no box dependence)"
        return ", ".join(f"{s} = {v:.4g}" for s, v in zip(self.symbols, self.values[k]))

    def describe(self) -> str:
        if not self.symbols:
            return "one evaluation (the Jacobians do not depend on any bounded signal)"
        corner = (f"all {self.corners} corners" if self.all_corners else f"{self.corners} random corners")
        return (f"{corner} of the box of {', '.join(map(str, self.symbols))} and {len(self) - self.corners} "
                f"points between them")


@dataclass(frozen=True)
class PointFacts:
    """The structural numbers of one linearization (scaled coordinates)."""

    unobservable: np.ndarray        # basis of the unobservable subspace (n, k)
    unobservable_modes: tuple       # ((eigenvalue, direction), ...)
    rank_D: int
    rank_CD: int
    rank_Dd: int
    vstar: np.ndarray               # basis of the largest output-nulling subspace (n, k)
    left_invertible: bool
    inseparable: tuple              # indices of unknown inputs that cannot be told apart
    zeros: np.ndarray | None        # invariant zeros (None: not defined, the system is not left invertible)
    zero_directions: np.ndarray | None
    rd: np.ndarray                  # (ny, nd) relative degree, -1: never


@dataclass
class Linearization:
    """Numeric Jacobians of a subject at the samples, in scaled coordinates (states by the box
    half-widths, unknown inputs and outputs to unit largest entries: rank decisions do not depend
    on the units)."""

    subject: Subject
    samples: Samples
    A: np.ndarray       # (P, n, n)
    D: np.ndarray       # (P, n, nd)
    C: np.ndarray       # (P, ny, n)
    Dd: np.ndarray      # (P, ny, nd)
    affine: bool        # the model is affine in states and inputs (LPV): the Jacobians are the model
    unbounded: tuple    # signals the Jacobians depend on without a bound (evaluated at 0)
    symbolic: dict      # {"A", "D", "C", "Dd": sympy matrices} (unscaled)

    @property
    def n(self) -> int:
        return self.A.shape[1]

    @property
    def nd(self) -> int:
        return self.D.shape[2]

    @property
    def ny(self) -> int:
        return self.C.shape[1]

    @property
    def basis(self) -> str:
        if not self.samples.symbols:
            return "constant"
        return "sampled" if self.affine else "linearized"


def _rank(M: np.ndarray, rtol: float = RTOL) -> int:
    if M.size == 0:
        return 0
    s = np.linalg.svd(M, compute_uv=False)
    return int((s > rtol * max(s[0], 1e-300)).sum()) if s[0] > 1e-300 else 0


def _null(M: np.ndarray, tol: float) -> np.ndarray:
    """Orthonormal basis of the null space of M (absolute tolerance on the singular values)."""
    if M.shape[0] == 0:
        return np.eye(M.shape[1], dtype=M.dtype)
    _, s, vh = np.linalg.svd(M)
    r = int((s > tol).sum())
    return vh[r:].conj().T


def _orth(M: np.ndarray, tol: float) -> np.ndarray:
    if M.shape[1] == 0:
        return M
    u, s, _ = np.linalg.svd(M, full_matrices=False)
    return u[:, :int((s > tol).sum())]


def unobservable_subspace(A: np.ndarray, C: np.ndarray, tol: float) -> np.ndarray:
    """Basis of the largest A-invariant subspace in ker C (the unobservable states)."""
    V = _null(C, tol)
    while V.shape[1]:
        R = A @ V - V @ (V.T @ (A @ V))
        Y = _null(R, tol)
        if Y.shape[1] == V.shape[1]:
            break
        V = _orth(V @ Y, tol)
    return V


def output_nulling_subspace(A, D, C, Dd, tol: float) -> np.ndarray:
    """Basis of V*, the largest subspace the unknown inputs can keep the state in while the outputs
    stay zero: V_0 = R^n, V_{k+1} = {x : A x + D d in V_k, C x + Dd d = 0 for some d}."""
    n, nd, ny = A.shape[0], D.shape[1], C.shape[0]
    V = np.eye(n)
    while V.shape[1]:
        k = V.shape[1]
        M = np.block([[A, D, -V], [C, Dd, np.zeros((ny, k))]])
        N = _null(M, tol)
        X = _orth(N[:n], tol)
        if X.shape[1] == k:
            return X
        V = X
    return V


def point_facts(A, D, C, Dd, rtol: float = RTOL) -> PointFacts:
    """:class:`PointFacts` of one linearization."""
    n, nd, ny = A.shape[0], D.shape[1], C.shape[0]
    scale = max(1.0, np.abs(A).max(initial=0), np.abs(C).max(initial=0), np.abs(D).max(initial=0),
                np.abs(Dd).max(initial=0))
    tol = rtol * scale * max(n, 1)
    unobs = unobservable_subspace(A, C, tol)
    modes = []
    if unobs.shape[1]:
        for lam in np.linalg.eigvals(A):
            pbh = np.vstack([A - lam * np.eye(n), C.astype(complex)])
            _, s, vh = np.linalg.svd(pbh)
            if s[-1] <= tol:
                modes.append((complex(lam), np.abs(vh[-1])))
    rank_D = _rank(np.vstack([D, Dd]), rtol)
    rank_CD = _rank(C @ D, rtol)
    rank_Dd = _rank(Dd, rtol)
    vstar = output_nulling_subspace(A, D, C, Dd, tol) if nd else unobs
    # left invertibility: normal rank of the Rosenbrock matrix at two generic frequencies
    inseparable = set()
    left = True
    for s0 in (0.613 + 1.271j, -0.417 + 2.113j):
        s = s0 * scale
        # at |s| ~ scale the input-output part of R shrinks like |C D| / |s|: a stiff point (scale
        # 6e3) put a left-invertible system's smallest singular value (1e-4) under the tolerance.
        # Scaling the unknown inputs' columns and the outputs' rows by |s| (no change of rank)
        # keeps every block of R of the size of A - s I.
        R = np.block([[A - s * np.eye(n), scale * D], [scale * C, scale * scale * Dd]]).astype(complex)
        Nr = _null(R, tol * 10)
        if Nr.shape[1]:
            left = False
            dpart = np.abs(Nr[n:]).max(axis=1) if nd else np.zeros(0)
            inseparable |= {j for j in range(nd) if dpart[j] > 1e-6}
    zeros, dirs = None, None
    if left:
        k = vstar.shape[1]
        if k == 0:
            zeros, dirs = np.zeros(0, complex), np.zeros((n, 0))
        else:
            L = np.block([[vstar, -D], [np.zeros((ny, k)), -Dd]])
            if _rank(L, rtol) == k + nd:
                sol = np.linalg.lstsq(L, np.vstack([A @ vstar, C @ vstar]), rcond=None)[0]
                Z = sol[:k]
                zeros, w = np.linalg.eig(Z)
                dirs = np.abs(vstar @ w)
    rd = np.full((ny, nd), -1, dtype=int)
    for i in range(ny):
        for j in range(nd):
            if abs(Dd[i, j]) > rtol * scale:
                rd[i, j] = 0
                continue
            m = C[i].copy()
            for k in range(1, n + 1):
                v = m @ D[:, j]
                if abs(v) > rtol * max(np.linalg.norm(m) * np.linalg.norm(D[:, j]), 1e-300) * 1e3:
                    rd[i, j] = k
                    break
                m = m @ A
    return PointFacts(unobs, tuple(modes), rank_D, rank_CD, rank_Dd, vstar, left, tuple(sorted(inseparable)),
                      zeros, dirs, rd)


# ---- evaluation ---------------------------------------------------------------------------------------

def _samples(box: dict, used: tuple, n_between: int, seed: int = 0) -> Samples:
    syms = tuple(s for s in used if s in box)
    if not syms:
        return Samples((), np.zeros((1, 0)), 1, True)
    rng = np.random.default_rng(seed)
    lo = np.array([box[s][0] for s in syms], float)
    hi = np.array([box[s][1] for s in syms], float)
    k = len(syms)
    if 2 ** k <= MAX_CORNERS:
        corners = np.array(list(itertools.product(*zip(lo, hi))), float)
        every = True
    else:
        bits = rng.integers(0, 2, size=(MAX_CORNERS, k))
        corners = np.where(bits == 1, hi, lo)
        every = False
    if k == 1:
        between = np.linspace(lo[0], hi[0], n_between + 2)[1:-1, None]
    else:
        between = rng.uniform(lo, hi, size=(n_between, k))
    return Samples(syms, np.vstack([corners, between]), corners.shape[0], every)


def _is_affine(exprs, variables: set) -> bool:
    """Whether every expression is affine in ``variables`` (polynomial of total degree <= 1)."""
    for e in exprs:
        if not e.free_symbols & variables:
            continue
        used = sorted(e.free_symbols & variables, key=str)
        if not e.is_polynomial(*used) or sp.Poly(e, *used).total_degree() > 1:
            return False
    return True


def _casadi_jacobian(F: sp.Matrix, xd: tuple):
    """(symbols the Jacobian depends on, callable (values of those symbols) -> dF/d(x, d)) by CasADi's
    automatic differentiation of the model's own expressions (a nonlinear model: sympy's symbolic
    Jacobian of a tyre law with Min/Max/|.| can take minutes to print)."""
    import casadi as ca
    from ..emit.stepgen import lambdify
    syms = list(dict.fromkeys([*xd, *sorted(F.free_symbols, key=str)]))
    Z = ca.SX.sym("z", len(syms))
    values = lambdify(syms, list(F))(*[Z[i] for i in range(len(syms))])
    Fv = ca.vertcat(*[v if isinstance(v, ca.SX) else ca.SX(float(v)) for v in values])
    J = ca.jacobian(Fv, ca.vertcat(*[Z[syms.index(s)] for s in xd])) if xd else ca.SX(F.shape[0], 0)
    used = [s for i, s in enumerate(syms) if ca.depends_on(J, Z[i])]
    fun = ca.Function("jacobian", [Z], [J])
    at = [syms.index(s) for s in used]

    def evaluate(*vals):
        z = np.zeros(len(syms))
        z[at] = vals
        return np.array(fun(z), dtype=float)
    return used, evaluate


def linearize(subject: Subject, n_between: int = 200, samples: Samples | None = None) -> Linearization:
    """The Jacobians of ``subject`` at the box corners and ``n_between`` points between them (or at
    given ``samples``: a signal they do not cover is taken at the middle of its box, else 0).

    An LPV model (affine in states and inputs) gives its matrices symbolically (sympy); a nonlinear
    one is differentiated numerically at each sample (CasADi automatic differentiation).
    """
    from scipy.linalg import matrix_balance
    eq = subject.equations
    states, unknown, known = eq.states, eq.unknown, eq.known
    f, h = eq.f, eq.h
    box = dict(eq.box)
    n, nd, ny = len(states), len(unknown), h.shape[0]
    xd = (*states, *unknown)
    F = sp.Matrix.vstack(f, h)
    inputs = set(states) | set(known) | set(unknown)
    affine = _is_affine(list(F), inputs)
    symbolic = {}
    if affine:
        J = F.jacobian(sp.Matrix(xd)) if xd else sp.zeros(F.shape[0], 0)
        free = set().union(*(e.free_symbols for e in J)) if len(J) else set()
        symbolic = {"A": J[:n, :n], "D": J[:n, n:], "C": J[n:, :n], "Dd": J[n:, n:]}
    else:
        free, numeric = _casadi_jacobian(F, xd)
    ordered = sorted(free, key=str)
    unbounded = tuple(s for s in ordered if s not in box)
    used = tuple(s for s in ordered if s in box)
    fixed = ()
    if samples is None:
        samples = _samples(box, used, n_between)
    else:
        fixed = tuple(s for s in used if s not in samples.symbols)
        unbounded = tuple(s for s in unbounded if s not in samples.symbols)
    args = list(samples.symbols) + list(fixed) + list(unbounded)
    at_fixed = [0.5 * (box[s][0] + box[s][1]) for s in fixed]
    if affine:
        fn = sp.lambdify(args, J, "numpy")
    else:
        where = [args.index(s) for s in free]            # the evaluator takes its own symbols' order
        fn = lambda *vals: numeric(*[vals[k] for k in where])
    vals = []
    with np.errstate(all="ignore"):
        for row in samples.values:
            vals.append(np.array(fn(*row, *at_fixed, *([0.0] * len(unbounded))), dtype=float).reshape(n + ny, n + nd))
    M = np.array(vals)
    if not np.all(np.isfinite(M)):
        bad = int(np.flatnonzero(~np.isfinite(M).all(axis=(1, 2)))[0])
        from ..errors import SchedulingBoundsError
        raise SchedulingBoundsError(f"model {subject.name!r}: its Jacobians are not finite at {samples.at(bad)} "
                                    f"(a singularity in the box of {subject.parameter_path})")
    # scaling (a similarity: no fact depends on it, only the rank decisions' conditioning): states by
    # the box half-widths, then diagonal balancing (powers of 2) of the mean |A|; unknown inputs and
    # outputs to unit largest entries
    sx = np.array([max(abs(box[s][1] - box[s][0]) / 2, 1e-12) if s in box else 1.0 for s in states])
    Araw, Draw, Craw, Ddraw = M[:, :n, :n], M[:, :n, n:], M[:, n:, :n], M[:, n:, n:]
    As = Araw * sx[None, None, :] / sx[None, :, None]
    if n:
        _, (t, _) = matrix_balance(np.abs(As).mean(axis=0) + np.eye(n), permute=False, separate=True)
        sx = sx * t
        As = Araw * sx[None, None, :] / sx[None, :, None]
    Ds = Draw / sx[None, :, None]
    Cs = Craw * sx[None, None, :]
    dcol = np.maximum(np.abs(np.concatenate([Ds, Ddraw], axis=1)).max(axis=(0, 1)), 1e-300) if nd else np.ones(0)
    Ds, Dds = Ds / dcol, Ddraw / dcol
    yrow = np.maximum(np.abs(np.concatenate([Cs, Dds], axis=2)).max(axis=(0, 2)), 1e-300) if ny else np.ones(0)
    Cs, Dds = Cs / yrow[None, :, None], Dds / yrow[None, :, None]
    return Linearization(subject, samples, As, Ds, Cs, Dds, affine, unbounded, symbolic)


# ---- the facts -----------------------------------------------------------------------------------------

def _names(names, idx) -> str:
    return ", ".join(names[k] for k in idx)


def _along(vec: np.ndarray, names, share: float = 0.1) -> list:
    v = np.abs(vec)
    return [names[k] for k in np.flatnonzero(v >= share * v.max())] if v.max() > 0 else []


@dataclass
class Structure:
    """Every structural fact of a subject (:func:`analyze`)."""

    subject: Subject
    lin: Linearization
    points: list
    facts: list
    relative_degrees: dict        # {output: {unknown input: r or None}}
    hosmd_orders: dict            # {"y_<output>": order}
    estimable: dict
    candidates: dict              # {fact key: [sensor text, ...]}: the measurements that make it hold
    seconds: float = 0.0
    sensors: list = field(default_factory=list)   # every Sensor checked (when a fact failed)

    def fact(self, key: str) -> Fact | None:
        return next((f for f in self.facts if f.key == key), None)

    def fix(self, key: str, default: str = "") -> str:
        """The fix the structure found for fact ``key`` (sensor candidates), else ``default``."""
        f = self.fact(key)
        return f.fix if f is not None and f.fix else default

    def decay_limit(self) -> dict | None:
        """The fastest decay any observer's error can have: an unobservable mode is untouched by every
        output injection, so the error along it decays at its own rate and no faster. {"rate": -(the
        largest real part of the unobservable modes over the samples) [1/s], "states": the states
        along them, "at": where}; None when every state is observable, or when a mode does not decay
        (then no observer converges, and the observability fact fails)."""
        f = self.fact("observability")
        if f is None or "slowest_real_part" not in f.detail or not f.detail["slowest_real_part"] < 0:
            return None
        return {"rate": -float(f.detail["slowest_real_part"]), "states": list(f.detail["unobservable_states"]),
                "at": f.detail.get("slowest_at", "")}

    def slowest_zero(self) -> tuple:
        """(largest real part of the invariant zeros over the samples, the zero, where) or None."""
        best = None
        for k, p in enumerate(self.points):
            if p.zeros is not None and p.zeros.size:
                z = p.zeros[int(np.argmax(p.zeros.real))]
                if best is None or z.real > best[0]:
                    best = (float(z.real), complex(z), self.lin.samples.at(k))
        return best

    @property
    def basis(self) -> str:
        return self.lin.basis

    def to_json(self) -> dict:
        return {"samples": {"symbols": [str(s) for s in self.lin.samples.symbols],
                            "count": len(self.lin.samples), "corners": self.lin.samples.corners,
                            "all_corners": self.lin.samples.all_corners,
                            "described": self.lin.samples.describe(),
                            "unbounded_at_zero": [str(s) for s in self.lin.unbounded]},
                "affine": self.lin.affine,
                "facts": [f.to_json() for f in self.facts],
                "relative_degrees": self.relative_degrees, "hosmd_orders": self.hosmd_orders,
                "estimable": self.estimable,
                "candidates": self.candidates,
                "sensors": [dataclasses.asdict(x) for x in self.sensors],
                "seconds": self.seconds}


def _symbolic_relative_degrees(lin: Linearization) -> dict | None:
    """{(i, j): generic relative degree} from the symbolic matrices of an LPV model (frozen
    scheduling): the first k with C_i A^(k-1) D_j not identically zero; None for a nonlinear model
    or when sympy takes too long a road (n > 8)."""
    if not lin.affine or lin.n > 8:
        return None
    A, D, C, Dd = (lin.symbolic[k] for k in ("A", "D", "C", "Dd"))
    out = {}
    for i in range(C.shape[0]):
        m = C.row(i)
        rows = [m]
        for _ in range(lin.n - 1):
            rows.append(sp.expand(rows[-1] * A))
        for j in range(D.shape[1]):
            if sp.simplify(Dd[i, j]) != 0:
                out[(i, j)] = 0
                continue
            out[(i, j)] = None
            for k, row in enumerate(rows, start=1):
                if sp.simplify(sp.together((row * D.col(j))[0])) != 0:
                    out[(i, j)] = k
                    break
    return out


def _with_sensors(lin: Linearization, rows: np.ndarray) -> tuple:
    """(C, Dd) at every sample with the extra measurement rows ``rows`` (in scaled states) appended."""
    P = lin.A.shape[0]
    C = np.concatenate([lin.C, np.broadcast_to(rows, (P, *rows.shape))], axis=1)
    Dd = np.concatenate([lin.Dd, np.zeros((P, rows.shape[0], lin.nd))], axis=1)
    return C, Dd


def _declared_rows(subject: Subject, samples: Samples) -> dict:
    """{name: (C row, Dd row) at every sample, scaled} of the declared outputs left out by
    ``--outputs`` (candidate sensors)."""
    extra = [o for o in subject.base_model.outputs if o[0] in subject.unmeasured_declared_outputs()]
    if not extra:
        return {}
    trial = subject.with_outputs(tuple(extra))
    lin = linearize(trial, samples=samples)
    ny0 = len(subject.outputs)
    return {name: (lin.C[:, ny0 + k], lin.Dd[:, ny0 + k]) for k, (name, _) in enumerate(extra)}


@dataclass(frozen=True)
class Sensor:
    """What one more measurement would change, checked at every sample."""

    text: str                   # "measure v_y", "measure a_y (an output the model declares, ...)"
    name: str                   # the state or declared output it measures
    observable: bool
    matching: bool
    left_invertible: bool
    strongly_detectable: bool
    slowest_zero: float         # largest real part of the invariant zeros (-inf: none)

    def key(self) -> tuple:
        return (not self.strongly_detectable, self.slowest_zero)


def _sensor_effect(text, name, lin: Linearization, C: np.ndarray, Dd: np.ndarray, pts: list) -> Sensor:
    P = C.shape[0]
    obs = match = left = True
    worst = -np.inf
    for q in range(P):
        pf = point_facts(lin.A[q], lin.D[q], C[q], Dd[q])
        obs &= pf.unobservable.shape[1] == 0
        match &= pf.rank_CD == pts[q].rank_D
        left &= pf.left_invertible
        if pf.zeros is not None and pf.zeros.size:
            worst = max(worst, float(pf.zeros.real.max()))
    strong = left and worst < -ZERO_TOL
    return Sensor(text, name, bool(obs), bool(match), bool(left), bool(strong), worst)


def candidate_sensors(subject: Subject, lin: Linearization, pts: list) -> list:
    """:class:`Sensor` of every measurement the model could add: each declared output that
    ``--outputs`` left out, then each state not yet measured (a state that a declared output
    measures is named by that output). Best first: strongly detectable, fastest zero dynamics."""
    measured = {str(sp.sympify(e)) for _, e in subject.model.outputs}
    found = []
    declared = {n: str(sp.sympify(e)) for n, e in subject.base_model.outputs}
    for name, (crow, drow) in _declared_rows(subject, lin.samples).items():
        C = np.concatenate([lin.C, crow[:, None, :]], axis=1)
        Dd = np.concatenate([lin.Dd, drow[:, None, :]], axis=1)
        found.append(_sensor_effect(f"measure {name} (an output the model declares, left out by --outputs)", name,
                                    lin, C, Dd, pts))
    named = set(declared[n] for n in subject.unmeasured_declared_outputs())
    for k, s in enumerate(subject.states):
        if s in measured or s in named:
            continue
        row = np.zeros((1, lin.n))
        row[0, k] = 1.0
        C, Dd = _with_sensors(lin, row)
        found.append(_sensor_effect(f"measure {s}", s, lin, C, Dd, pts))
    return sorted(found, key=Sensor.key)


def analyze(subject: Subject, n_between: int = 200) -> Structure:
    """Every structural fact of ``subject`` (see the module docstring), one named step per fact."""
    t0 = time.perf_counter()
    lin = linearize(subject, n_between)
    pts = [point_facts(lin.A[k], lin.D[k], lin.C[k], lin.Dd[k]) for k in range(len(lin.samples))]
    c = _Analysis(subject, lin, pts)
    _ui_rank(c)
    _observability(c)
    rel, hosmd = _relative_degrees(c)
    _matching(c, rel)
    _left_invertibility(c)
    _zeros_and_strong_detectability(c)
    estimable = _estimable(subject, lin, pts)
    seconds = time.perf_counter() - t0
    return Structure(subject, lin, pts, c.facts, rel, hosmd, estimable, c.candidates, seconds, c.found)


class _Analysis:
    """What every step of :func:`analyze` reads (the linearization, the facts at each point, the names) and
    what they add to (``facts``, ``candidates``); the candidate sensors computed once, and only when a fact
    fails (:meth:`sensors`)."""

    def __init__(self, subject: Subject, lin: Linearization, pts: list):
        self.subject, self.lin, self.pts = subject, lin, pts
        self.S, self.P, self.basis = lin.samples, len(lin.samples), lin.basis
        self.st, self.ui, self.out = subject.states, subject.unknown_inputs, subject.outputs
        self.n, self.nd, self.ny = lin.n, lin.nd, lin.ny
        self.facts, self.candidates, self._found = [], {}, None
        self.note = (f"; {', '.join(map(str, lin.unbounded))} {'has' if len(lin.unbounded) == 1 else 'have'} no "
                     f"bound in {subject.parameter_path.name}: taken at 0") if lin.unbounded else ""

    def sensors(self) -> list:
        if self._found is None:
            self._found = candidate_sensors(self.subject, self.lin, self.pts)
        return self._found

    @property
    def found(self) -> list:
        return self._found or []


def _ui_rank(c: _Analysis) -> None:
    """Every unknown input acts on the system (rank [D; Dd]): appended to ``c.facts`` (``c.candidates`` where sensors are proposed)."""
    lin, pts, S, basis, note, ui = c.lin, c.pts, c.S, c.basis, c.note, c.ui
    nd, facts = c.nd, c.facts
    if nd:
        bad = [k for k, p in enumerate(pts) if p.rank_D < nd]
        if not bad:
            facts.append(Fact("ui_rank", True, f"the unknown inputs {', '.join(ui)} act independently "
                              f"(rank [D; Dd] = {nd}) at every sample{note}", basis))
        else:
            k = bad[0]
            Dfull = np.vstack([lin.D[k], lin.Dd[k]])
            zero = [ui[j] for j in range(nd) if np.abs(Dfull[:, j]).max() <= RTOL]
            what = (f"{', '.join(zero)} enter{'s' if len(zero) == 1 else ''} neither the dynamics nor the outputs"
                    if zero else f"the columns of D of {', '.join(ui)} are dependent")
            facts.append(Fact("ui_rank", False, f"rank [D; Dd] = {pts[k].rank_D} < {nd} at {S.at(k)}: {what}",
                              basis, "remove the unknown inputs that do not act, or merge the dependent ones into one",
                              {"points_failing": len(bad)}))


def _observability(c: _Analysis) -> None:
    """Observability, else detectability, of the states from the outputs (unknown inputs absent): appended to ``c.facts`` (``c.candidates`` where sensors are proposed)."""
    pts, S, P, basis, note, st = c.pts, c.S, c.P, c.basis, c.note, c.st
    out, n, facts, candidates, sensors = c.out, c.n, c.facts, c.candidates, c.sensors
    unobs_pts = [k for k, p in enumerate(pts) if p.unobservable.shape[1]]
    if not unobs_pts:
        facts.append(Fact("observability", True, f"every state ({', '.join(st)}) is observable from "
                          f"{', '.join(out)} (PBH rank test) at every sample{note}", basis))
    else:
        states_along, worst, worst_k = set(), -np.inf, unobs_pts[0]
        for k in unobs_pts:
            V = pts[k].unobservable
            states_along |= {st[i] for i in range(n) if np.abs(V[i]).max() > 1e-6}
            for lam, _ in pts[k].unobservable_modes:
                if lam.real > worst:
                    worst, worst_k = lam.real, k
        detectable = worst < 0
        along = sorted(states_along, key=st.index)
        found_ = [c for c in sensors() if c.observable]
        cands = [c.text for c in found_]
        candidates["observability"] = [{"sensor": c.name, "text": c.text} for c in found_]
        fix = (f"{' or '.join(cands[:3])} (each makes every state observable at every sample)" if cands
               else f"measure an output that sees {', '.join(along)}, or drop {'it' if len(along) == 1 else 'them'} "
                    f"from the states")
        statement = (f"{', '.join(along)} {'is' if len(along) == 1 else 'are'} not observable from "
                     f"{', '.join(out)} at {len(unobs_pts)} of {P} points; the slowest unobservable mode has "
                     f"Re = {worst:.4g} 1/s at {S.at(worst_k)}: "
                     + ("detectable (it decays by itself)" if detectable else "NOT detectable (no observer converges "
                                                                             "along it)"))
        facts.append(Fact("observability", detectable, statement, basis, "" if detectable else fix,
                          {"unobservable_states": along, "points": len(unobs_pts), "slowest_real_part": worst,
                           "slowest_at": S.at(worst_k), "detectable": detectable}))
        if detectable:
            facts[-1] = Fact("observability", True, statement, basis, "",
                             {"unobservable_states": along, "points": len(unobs_pts), "slowest_real_part": worst,
                              "slowest_at": S.at(worst_k), "detectable": True, "to_observe_all": fix})


def _relative_degrees(c: _Analysis) -> tuple:
    """Relative degrees of every output to every unknown input, and the HOSMD orders: (rel, hosmd): appended to ``c.facts`` (``c.candidates`` where sensors are proposed)."""
    lin, pts, basis, ui, out, nd = c.lin, c.pts, c.basis, c.ui, c.out, c.nd
    ny, facts = c.ny, c.facts
    sym_rd = _symbolic_relative_degrees(lin)
    rel, hosmd = {}, {}
    nonuniform, order_sets = [], {}
    for i, o in enumerate(out):
        rel[o] = {}
        for j, u in enumerate(ui):
            vals = {int(p.rd[i, j]) for p in pts}
            seen = sorted(v for v in vals if v >= 0)
            rel[o][u] = min(seen) if seen else None
            if len(vals) > 1:
                nonuniform.append((o, u, sorted(vals)))
        # the output's own order: the lowest derivative in which any unknown input appears
        order_sets[o] = sorted({min((int(v) for v in p.rd[i] if v >= 0), default=-1) for p in pts})
        finite = [r for r in rel[o].values() if r is not None]
        if finite:
            hosmd[f"y_{o}"] = min(finite)
    if nd and ny:
        table = "; ".join(f"y_{o}: " + ", ".join(f"{u} {'never' if r is None else r}" for u, r in rel[o].items())
                          for o in out)
        exact = sym_rd is not None and all(sym_rd[(i, j)] == rel[o][u] for i, o in enumerate(out)
                                           for j, u in enumerate(ui))
        rbasis = basis if not exact or basis == "constant" else "exact"
        shaky = {o: v for o, v in order_sets.items() if len(v) > 1}
        never = [u for u in ui if all(rel[o][u] is None for o in out)]
        statement = (f"relative degree (the derivative of the output in which the unknown input first appears) "
                     f"{table}" + (" (generic degrees exact, symbolic; the same at every sample)"
                                   if exact and not nonuniform and basis != "constant" else ""))
        if shaky:
            statement += ("; NOT uniform: " + "; ".join(f"y_{o} sees the first unknown input in derivative "
                                                        f"{' or '.join('never' if v < 0 else str(v) for v in vals)} "
                                                        f"depending on the point" for o, vals in shaky.items()))
        elif nonuniform:
            statement += (f"; the output orders are uniform (higher degrees of other pairs vary between points: "
                          f"{len(nonuniform)} pair(s), see the JSON)")
        fix = f"measure a signal {', '.join(never)} reach{'es' if len(never) == 1 else ''}" if never else ""
        if shaky and not fix:
            fix = "restrict the box where the output's relative degree changes, or measure a signal the unknown " \
                  "inputs reach uniformly"
        facts.append(Fact("relative_degree", not shaky and not never, statement, rbasis, fix,
                          {"relative_degrees": rel, "hosmd_orders": hosmd, "uniform_outputs": not shaky,
                           "varying_pairs": [{"output": o, "unknown_input": u, "degrees": v}
                                             for o, u, v in nonuniform], "never_reached": never}))
    return rel, hosmd


def _matching(c: _Analysis, rel: dict) -> None:
    """The matching condition rank(C D) = rank(D): appended to ``c.facts`` (``c.candidates`` where sensors are proposed)."""
    subject, lin, pts, S, P, basis = c.subject, c.lin, c.pts, c.S, c.P, c.basis
    st, ui, out, n, nd, facts = c.st, c.ui, c.out, c.n, c.nd, c.facts
    candidates, sensors = c.candidates, c.sensors
    if nd:
        bad = [k for k, p in enumerate(pts) if p.rank_CD != p.rank_D]
        late = [u for u in ui if all(rel.get(o, {}).get(u) is None or rel[o][u] >= 2 for o in out)]
        if not bad:
            facts.append(Fact("matching", True, f"matching condition rank(C D) = rank(D) = {pts[0].rank_D}: every "
                              f"unknown input reaches a measured output in its first derivative, at every sample", basis))
        else:
            k = bad[0]
            if late:
                why = "; ".join(f"{u} reaches " + (", ".join(f"y_{o} only in derivative {rel[o][u]}" for o in out
                                                              if rel[o][u] is not None) or "no measured output")
                                for u in late)
            else:
                why = (f"{', '.join(ui)} reach the outputs in their first derivative only through the same "
                       f"combination")
            drives = {u: [st[i] for i in range(n) if np.abs(lin.D[:, i, ui.index(u)]).max() > RTOL] for u in late}
            found_ = [c for c in sensors() if c.matching]
            cands = [c.text for c in found_]
            candidates["matching"] = [{"sensor": c.name, "text": c.text} for c in found_]
            direct = "; ".join(f"{u} enters " + ", ".join(f"d{x}/dt = {subject.equation_text(x)}" for x in s)
                               for u, s in drives.items() if s)
            fix = ((f"{' or '.join(cands[:3])} (rank(C D) = rank(D) then holds at every sample)" if cands
                    else "measure more outputs")
                   + (f"; or an output in which {'/'.join(drives)} appear{'s' if len(drives) == 1 else ''} directly "
                      f"(relative degree 0, e.g. an accelerometer measuring such a derivative: {direct})"
                      if direct else ""))
            facts.append(Fact("matching", False, f"matching condition fails: rank(C D) = {pts[k].rank_CD} != rank(D) "
                              f"= {pts[k].rank_D} at {S.at(k)} ({len(bad)} of {P} points): {why}", basis, fix,
                              {"points_failing": len(bad), "late_unknown_inputs": late, "drives": drives}))


def _left_invertibility(c: _Analysis) -> None:
    """Left invertibility: can the unknown inputs be told apart at all?: appended to ``c.facts`` (``c.candidates`` where sensors are proposed)."""
    pts, S, P, basis, ui, out = c.pts, c.S, c.P, c.basis, c.ui, c.out
    n, nd, ny, facts, candidates, sensors = c.n, c.nd, c.ny, c.facts, c.candidates, c.sensors
    if nd:
        bad = [k for k, p in enumerate(pts) if not p.left_invertible]
        if not bad:
            facts.append(Fact("left_invertibility", True, f"left invertible: {', '.join(ui)} can be told apart from "
                              f"the outputs and their derivatives (normal rank of the system matrix n + n_d = "
                              f"{n + nd}) at every sample", basis))
        else:
            insep = sorted({j for k in bad for j in pts[k].inseparable})
            names = _names(ui, insep)
            found_ = [c for c in sensors() if c.left_invertible]
            cands = [c.text for c in found_]
            candidates["left_invertibility"] = [{"sensor": c.name, "text": c.text} for c in found_]
            fix = (" or ".join(cands[:3]) if cands else
                   f"measure at least {nd} outputs the unknown inputs reach independently")
            fix += f", or treat {' or '.join(names.split(', '))} as known (uiogen analyze --unknown-inputs ...)"
            facts.append(Fact("left_invertibility", False, f"NOT left invertible at {len(bad)} of {P} points (e.g. "
                              f"{S.at(bad[0])}): {names} cannot be told apart from {', '.join(out)} "
                              f"({ny} output{'s' if ny != 1 else ''} for {nd} unknown input{'s' if nd != 1 else ''})",
                              basis, fix, {"inseparable": [ui[j] for j in insep], "points_failing": len(bad)}))


def _zeros_and_strong_detectability(c: _Analysis) -> None:
    """Invariant zeros, where they sit, and strong detectability: appended to ``c.facts`` (``c.candidates`` where sensors are proposed)."""
    pts, S, P, basis, st, ui = c.pts, c.S, c.P, c.basis, c.st, c.ui
    nd, facts, candidates, sensors = c.nd, c.facts, c.candidates, c.sensors
    if nd:
        zs = [(k, z) for k, p in enumerate(pts) if p.zeros is not None for z in p.zeros]
        counts = sorted({p.zeros.size for p in pts if p.zeros is not None})
        if zs:
            re = np.array([z.real for _, z in zs])
            kmax = int(np.argmax(re))
            k_at, z_at = zs[kmax]
            p = pts[k_at]
            along = _along(p.zero_directions[:, list(p.zeros).index(z_at)], st) if p.zero_directions is not None else []
            # scaled states: the zeros themselves are invariant under the scaling (a similarity)
            statement = (f"{'/'.join(map(str, counts))} invariant zero(s) of (A, D, C, Dd) per point, real parts in "
                         f"[{_c(re.min())}, {_c(re.max())}] 1/s; the least stable, s = {_c(z_at)}, at {S.at(k_at)}, "
                         f"moves {', '.join(along)}: no observer that decouples {', '.join(ui)} makes the error along it "
                         f"decay faster than exp({_c(re.max())} t)")
            facts.append(Fact("invariant_zeros", None, statement, basis, "",
                              {"count": counts, "real_range": [float(re.min()), float(re.max())],
                               "least_stable": [z_at.real, z_at.imag], "at": S.at(k_at), "along": along}))
        elif any(p.zeros is not None for p in pts):
            facts.append(Fact("invariant_zeros", None, f"no invariant zeros at any sample: the unknown inputs leave no "
                              f"hidden dynamics (every state is reconstructible whatever they do)", basis))
        bad_lr = [k for k, p in enumerate(pts) if not p.left_invertible]
        bad_z = [k for k, p in enumerate(pts) if p.zeros is not None and p.zeros.size and p.zeros.real.max() >= -ZERO_TOL]
        if not bad_lr and not bad_z:
            facts.append(Fact("strong_detectability", True, f"strongly detectable: left invertible and every invariant "
                              f"zero in Re s < 0 at every sample: an observer that decouples {', '.join(ui)} exists for "
                              f"frozen scheduling", basis))
        else:
            if bad_z:
                k = bad_z[0]
                z = pts[k].zeros[np.argmax(pts[k].zeros.real)]
                found_ = [c for c in sensors() if c.strongly_detectable]
                cands = [c.text for c in found_]
                candidates["strong_detectability"] = [{"sensor": c.name, "text": c.text} for c in found_]
                fix = (" or ".join(cands[:3]) if cands else
                       "measure a signal along the zero's direction") + " (removes the unstable zero)"
                statement = (f"NOT strongly detectable: invariant zero s = {_c(z)} (Re >= 0) at {S.at(k)} "
                             f"({len(bad_z)} of {P} points): no observer that decouples {', '.join(ui)} converges")
            else:
                left = next((f for f in facts if f.key == "left_invertibility"), None)
                fix = left.fix if left is not None else ""
                statement = "NOT strongly detectable: the system is not left invertible (above)"
            facts.append(Fact("strong_detectability", False, statement, basis, fix,
                              {"points_unstable_zero": len(bad_z), "points_not_left_invertible": len(bad_lr)}))


def _c(z: complex) -> str:
    z = complex(0.0 if abs(z.real) < ZERO_TOL else z.real, 0.0 if abs(z.imag) < ZERO_TOL else z.imag)
    return f"{z.real:.4g}" if abs(z.imag) < 1e-9 * max(1.0, abs(z.real)) else f"{z.real:.4g} {'+-'[z.imag < 0]} " \
                                                                              f"{abs(z.imag):.4g}j"


def _estimable(subject: Subject, lin: Linearization, pts: list) -> dict:
    """The largest set of unknown inputs that can be told apart (the others treated as known), and
    the states reconstructible whatever those unknown inputs do (orthogonal to V* at every sample)."""
    st, ui = subject.states, subject.unknown_inputs
    n, nd, P = lin.n, lin.nd, len(pts)
    best = tuple(range(nd))
    if nd and not all(p.left_invertible for p in pts):
        best = ()
        for size in range(nd - 1, 0, -1):
            for subset in itertools.combinations(range(nd), size):
                cols = list(subset)
                if all(point_facts(lin.A[q], lin.D[q][:, cols], lin.C[q], lin.Dd[q][:, cols]).left_invertible
                       for q in range(P)):
                    best = subset
                    break
            if best:
                break
    cols = list(best)
    facts = pts if len(best) == nd else [point_facts(lin.A[q], lin.D[q][:, cols], lin.C[q], lin.Dd[q][:, cols])
                                          for q in range(P)]
    exact = [s for i, s in enumerate(st) if all(np.abs(p.vstar[i]).max(initial=0) <= 1e-6 for p in facts)]
    stable = all(p.zeros is not None and (p.zeros.size == 0 or p.zeros.real.max() < -ZERO_TOL) for p in facts)
    asym = list(st) if stable else exact
    unobs = sorted({st[i] for p in pts for i in range(n) if p.unobservable.shape[1]
                    and np.abs(p.unobservable[i]).max() > 1e-6}, key=st.index)
    return {"unknown_inputs": [ui[j] for j in best],
            "unknown_inputs_not": [u for j, u in enumerate(ui) if j not in best],
            "states_exactly": exact,
            "states_asymptotically": asym,
            "states_not": [s for s in st if s not in asym],
            "states_unobservable_without_unknown_inputs": unobs}
