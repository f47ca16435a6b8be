"""A small LMI layer compiled straight to Clarabel's PSD triangle cones.

Decision variables (scalars, matrices, symmetric matrices) are :class:`Affine`
matrices: a constant part and one coefficient matrix per scalar variable, held as
numpy arrays, so every block is built with ordinary matrix algebra (``@``, ``+``,
``.T``, :func:`bmat`) at numpy speed and its coefficients are exact by construction
(no probing, no symbolic differentiation). A product of two expressions that both
depend on the variables is not affine: it is recorded and refused, with the LMI's
label, when the problem is compiled. Compilation stacks the coefficients in
Clarabel's ``A x + s = b, s in K`` form (upper triangle, column-major,
off-diagonals scaled by sqrt(2)) and solves. Every solution is re-checked with
``numpy.linalg.eigvalsh`` on every block, independently of the solver, before it is
returned.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import clarabel
import numpy as np
from scipy import sparse

from ..errors import (CertificateError, DesignLockError, IllConditionedError, InaccurateSolveError,
                      InfeasibleLMIError, LMIShapeError, NonAffineLMIError)

SQRT2 = np.sqrt(2.0)


def _triu_pairs(n: int):
    """Index pairs (row, col) of the upper triangle, column by column (Clarabel's order)."""
    return [(i, j) for j in range(n) for i in range(j + 1)]


def svec(mat: np.ndarray) -> np.ndarray:
    """Clarabel's scaled vectorization of a symmetric matrix."""
    n = mat.shape[0]
    return np.array([mat[i, j] * (1.0 if i == j else SQRT2) for i, j in _triu_pairs(n)])


@functools.lru_cache(maxsize=None)
def _triu_index(n: int):
    """Row and column indices of :func:`_triu_pairs` and the sqrt(2) scaling, as arrays
    (cached: read-only)."""
    rows, cols = np.triu_indices(n)
    order = np.lexsort((rows, cols))  # by column, then row
    rows, cols = rows[order], cols[order]
    out = (rows, cols, np.where(rows == cols, 1.0, SQRT2))
    for a in out:
        a.flags.writeable = False
    return out


class Affine:
    """Matrix ``const + sum_k x_k coef[:, :, k]``, affine in the decision variables ``x``.

    Supports ``+``, ``-``, ``@`` and ``*`` with numpy arrays, numbers and other Affine
    matrices, ``.T``, slicing and :func:`bmat`. A product of two Affine matrices that both
    depend on ``x`` is not affine: the result is marked (``nonaffine`` names the variables
    involved) and refused when the LMI problem is compiled.
    """

    __array_ufunc__ = None   # numpy defers to our reflected operators (ndarray @ Affine)

    def __init__(self, const, coef=None, names: tuple = (), nonaffine: tuple = ()):
        if not (type(const) is np.ndarray and const.ndim == 2 and const.dtype == np.float64):
            const = np.atleast_2d(np.asarray(const, dtype=float))
        self.const = const
        self.coef = np.zeros(self.const.shape + (0,)) if coef is None else coef
        self.names = names            # names of the first coef.shape[2] scalar variables
        self.nonaffine = nonaffine    # variables of a product that is not affine

    @property
    def shape(self) -> tuple:
        return self.const.shape

    @property
    def T(self) -> "Affine":
        return Affine(self.const.T, self.coef.transpose(1, 0, 2), self.names, self.nonaffine)

    def __getitem__(self, idx) -> "Affine":
        idx = idx if isinstance(idx, tuple) else (idx,)
        const = np.atleast_2d(self.const[idx])
        return Affine(const, self.coef[idx].reshape(const.shape + (-1,)), self.names, self.nonaffine)

    def is_constant(self) -> bool:
        return not self.coef.any() and not self.nonaffine

    def value(self, x: np.ndarray) -> np.ndarray:
        """The matrix at decision variables ``x``."""
        return self.const + self.coef @ x[:self.coef.shape[2]]

    def __neg__(self) -> "Affine":
        return Affine(-self.const, -self.coef, self.names, self.nonaffine)

    def __add__(self, other) -> "Affine":
        other = _as_affine(other)
        if other.shape != self.shape:
            a, b = _common(self, other)
            return Affine(a.const + b.const, a.coef + b.coef, a.names, a.nonaffine + b.nonaffine)
        ka, kb = self.coef.shape[2], other.coef.shape[2]
        if ka == kb:
            coef = self.coef + other.coef
        else:
            coef = (self.coef if ka > kb else other.coef).copy()
            coef[:, :, :min(ka, kb)] += (other.coef if ka > kb else self.coef)
        names = self.names if ka >= kb else other.names
        return Affine(self.const + other.const, coef, names, self.nonaffine + other.nonaffine)

    __radd__ = __add__

    def __sub__(self, other) -> "Affine":
        return self + (-_as_affine(other))

    def __rsub__(self, other) -> "Affine":
        return _as_affine(other) + (-self)

    def __mul__(self, other) -> "Affine":
        if not isinstance(other, Affine) and np.ndim(other) == 0:
            k = float(other)
            return Affine(k * self.const, k * self.coef, self.names, self.nonaffine)
        other = _as_affine(other)
        for s_, m_ in ((self, other), (other, self)):
            if s_.shape == (1, 1) and m_.is_constant():     # scalar expression times constant matrix
                return Affine(s_.const.item() * m_.const, s_.coef.reshape(1, 1, -1) * m_.const[:, :, None],
                              s_.names, s_.nonaffine)
        if self.is_constant() or other.is_constant():
            raise LMIShapeError("elementwise products of matrices are not supported; use @")
        return _product_marker(self, other, np.broadcast_shapes(self.shape, other.shape))

    __rmul__ = __mul__

    def __matmul__(self, other) -> "Affine":
        if isinstance(other, Affine):
            if other.is_constant():
                return self @ other.const
            if self.is_constant():
                return self.const @ other
            return _product_marker(self, other, (self.shape[0], other.shape[1]))
        other = np.atleast_2d(np.asarray(other, dtype=float))
        return Affine(self.const @ other, np.einsum("ijk,jl->ilk", self.coef, other), self.names,
                      self.nonaffine)

    def __rmatmul__(self, other) -> "Affine":
        other = np.atleast_2d(np.asarray(other, dtype=float))
        return Affine(other @ self.const, np.einsum("ij,jlk->ilk", other, self.coef), self.names,
                      self.nonaffine)


def _as_affine(x) -> Affine:
    return x if isinstance(x, Affine) else Affine(x)


def _product_marker(a: Affine, b: Affine, shape) -> Affine:
    """Stand-in for the product of two variable-dependent matrices: refused at compilation."""
    used = [e.names[k] for e in (a, b) for k in np.flatnonzero(e.coef.any(axis=(0, 1)))]
    return Affine(np.zeros(shape), None, (), a.nonaffine + b.nonaffine + (tuple(dict.fromkeys(used)),))


def _pad(coef: np.ndarray, k: int) -> np.ndarray:
    if coef.shape[2] >= k:
        return coef
    return np.concatenate([coef, np.zeros(coef.shape[:2] + (k - coef.shape[2],))], axis=2)


def _common(a, b) -> tuple:
    """Both operands as Affine with the same number of variables."""
    a, b = _as_affine(a), _as_affine(b)
    if a.const.shape != b.const.shape:
        if a.shape == (1, 1) and a.is_constant():
            a = Affine(np.full(b.shape, a.const.item()))
        elif b.shape == (1, 1) and b.is_constant():
            b = Affine(np.full(a.shape, b.const.item()))
        else:
            raise LMIShapeError(f"cannot add matrices of shapes {a.shape} and {b.shape}")
    k = max(a.coef.shape[2], b.coef.shape[2])
    names = a.names if len(a.names) >= len(b.names) else b.names
    return (Affine(a.const, _pad(a.coef, k), names, a.nonaffine),
            Affine(b.const, _pad(b.coef, k), names, b.nonaffine))


def _null_directions_fixed(J: np.ndarray, q: np.ndarray, rel: float = 1e-13) -> np.ndarray:
    """Variables that can be fixed at 0 without changing the problem ``min q x, J x + c in K``.

    Unpivoted LDL' of the Gram matrix of the columns of [J; q] (formed sparse: no threaded BLAS
    call on a matrix this small), latest-declared variable first: a pivot below ``rel`` times
    its column's squared norm means that column lies in the span of the ones before it (to
    sqrt(rel) = 3e-7 relative; rounding in the coefficients leaves exact dependencies near
    1e-16), i.e. a direction v with [J; q] v = 0 that moves this variable. Every point of the
    problem moves along such directions to one where these variables are 0: they are fixed.
    """
    Js = sparse.csc_matrix(np.vstack([J, q[None, :]])[:, ::-1])
    G = (Js.T @ Js).toarray()
    norms = np.diag(G).copy()
    fixed = []
    for k in range(G.shape[0]):
        piv = G[k, k]
        if piv <= rel * norms[k]:
            fixed.append(G.shape[0] - 1 - k)
            continue
        col = G[k + 1:, k] / piv
        G[k + 1:, k + 1:] -= np.outer(col, G[k, k + 1:])
    return np.array(sorted(fixed), dtype=int)


def bmat(rows) -> Affine:
    """Block matrix from a nested list of Affine matrices, arrays and numbers (like ``np.block``)."""
    rows = [[_as_affine(b) for b in row] for row in rows]
    k = max(b.coef.shape[2] for row in rows for b in row)
    names = max((b.names for row in rows for b in row), key=len)
    nonaffine = tuple(t for row in rows for b in row for t in b.nonaffine)
    const = np.concatenate([np.concatenate([b.const for b in row], axis=1) for row in rows], axis=0)
    coef = np.concatenate([np.concatenate([_pad(b.coef, k) for b in row], axis=1) for row in rows], axis=0)
    return Affine(const, coef, names, nonaffine)


def trace(a: Affine) -> Affine:
    """Trace of a square Affine matrix (a 1x1 Affine)."""
    a = _as_affine(a)
    return Affine(np.trace(a.const), np.trace(a.coef).reshape(1, 1, -1), a.names, a.nonaffine)


@dataclass
class Constraint:
    """``expr >= margin * I`` (PSD) for a symmetric affine expression."""

    label: str
    expr: Affine
    margin: float
    hint: str


# An eigenvalue numpy.linalg.eigvalsh returns is within about n eps ||M||_2 of the exact eigenvalue of
# the matrix it was given (a backward-stable symmetric solver, then Weyl's inequality); a smallest
# eigenvalue below this many times that is not known to be positive, so the block is not certified.
# An exactly singular block (X = 0 against "X > 0") or one positive by rounding only fails.
EIG_ROUNDING_FACTOR = 4.0


@dataclass(frozen=True)
class BlockCheck:
    label: str
    size: int
    min_eig: float        # of expr - margin*I ... reported for expr itself
    scale: float          # largest |eigenvalue| of the block, for a relative figure

    @property
    def relative_margin(self) -> float:
        return self.min_eig / max(self.scale, 1e-300)

    @property
    def rounding_floor(self) -> float:
        """Smallest eigenvalue that is known to be positive: ``EIG_ROUNDING_FACTOR n eps ||M||_2``."""
        return EIG_ROUNDING_FACTOR * self.size * float(np.finfo(float).eps) * self.scale

    @property
    def certified(self) -> bool:
        """The block is positive definite beyond the eigensolver's rounding (a strict LMI holds)."""
        return bool(self.min_eig > self.rounding_floor)

    def failure(self) -> str:
        """Why the block is not certified, for an error message."""
        floor = f" (it must exceed the eigensolver's rounding {self.rounding_floor:.1e})" if self.min_eig >= 0 else ""
        return f"smallest eigenvalue {self.min_eig:.3e}{floor}, block scale {self.scale:.3e}"


def worst_block(checks, by: str = "relative_margin") -> BlockCheck:
    """The block with the least margin (``by``: ``"relative_margin"`` or ``"min_eig"``), named the same on every
    machine: mirror-image blocks (two vertices of one symmetric polytope) have equal eigenvalues but for their
    last bits, and those bits differ from one CPU to another; of the blocks within the eigensolver's rounding
    (or 1e-9 relative) of the least, the first in order is taken."""
    checks = list(checks)
    relative = by == "relative_margin"

    def value(c):
        return c.relative_margin if relative else c.min_eig

    def noise(c):
        return c.rounding_floor / max(c.scale, 1e-300) if relative else c.rounding_floor
    least = min(checks, key=value)
    return next(c for c in checks
                if value(c) <= value(least) + max(noise(c), noise(least), 1e-9 * abs(value(least))))


def uncertified(checks) -> BlockCheck | None:
    """The block with the least relative margin among those that fail, or None when all are certified."""
    failed = [c for c in checks if not c.certified]
    return min(failed, key=lambda c: c.relative_margin) if failed else None


@dataclass(frozen=True)
class LMISolution:
    """Values of the decision variables and the independent certificate."""

    values: dict
    objective: float
    status: str
    solve_time_s: float
    build_time_s: float
    iterations: int
    checks: tuple

    @property
    def worst(self) -> BlockCheck:
        return worst_block(self.checks)

    def __getitem__(self, name: str):
        return self.values[name]


# Second stage of every solve (:meth:`LMIProblem.solve`): the objective may exceed its optimum
# by this fraction; far above the solver's tolerance, so the least-norm point is well determined.
OPTIMALITY_SLACK = 1e-4
# Column scaling never shrinks a variable below this fraction of the largest one: a variable the
# first solve left at noise level must not become a column of 1e-12s.
SCALE_FLOOR = 1e-6
# The second stage keeps every block this far inside (see LMIProblem._central_margin), giving up
# this fraction of the largest common relative margin the optimal set allows.
CENTRAL_MARGIN = False
CENTRAL_GIVE = 0.5
# Weight of the non-symmetric variables (gains) in the least-norm stage, against 1 for the
# symmetric certificates (LMIProblem._norm_weights).
GAIN_WEIGHT = 3e-2


def objective_bound(t: float, slack: float = OPTIMALITY_SLACK) -> float:
    """``t (1 + slack)`` rounded up to three significant digits, in decimal arithmetic (the same
    on every machine): the second stage's bound on the objective."""
    import decimal
    v = t + slack * abs(t)
    if v == 0.0:
        return 1e-14
    d = decimal.Decimal(repr(float(v)))
    quantum = decimal.Decimal(1).scaleb(d.adjusted() - 2)
    return float((d / quantum).to_integral_value(rounding=decimal.ROUND_CEILING) * quantum)


def exact_json(values: dict) -> dict:
    """Decision variables as nested lists of floats (JSON writes the shortest repr that
    round-trips, so a replayed value is bit-identical to the solved one)."""
    return {k: (float(v) if np.ndim(v) == 0 else np.asarray(v, dtype=float).tolist()) for k, v in values.items()}


@dataclass(frozen=True)
class SolveRecord:
    """One solved LMI problem of a design: what the design lock commits."""

    problem: str
    variables: dict
    objective: float
    iterations: int
    data: dict = field(default_factory=dict)     # constants of the problem found at design time

    def to_json(self) -> dict:
        return {"problem": self.problem, "objective": self.objective, "iterations": self.iterations,
                **({"data": self.data} if self.data else {}), "variables": self.variables}

    @classmethod
    def from_json(cls, data: dict, source: str = "") -> "SolveRecord":
        try:
            rec = cls(str(data["problem"]), dict(data["variables"]), float(data["objective"]),
                      int(data["iterations"]), dict(data.get("data", {})))
        except (KeyError, TypeError, ValueError) as exc:
            raise DesignLockError(f"{source}: malformed LMI solution record ({exc})") from None
        for name, value in rec.variables.items():
            # a hand-edited or damaged record: re-checking it would end in LinAlgError, not in a verdict
            try:
                finite = np.all(np.isfinite(np.array(value, dtype=float)))
            except (TypeError, ValueError):
                finite = None
            if not finite:
                raise DesignLockError(f"{source}: LMI solution record {rec.problem!r}: variable {name!r} is "
                                      + ("not a matrix of numbers" if finite is None else "not finite")
                                      + "; allowed: finite numbers, a matrix as nested lists")
        return rec


@dataclass(frozen=True)
class ReducedProblem:
    """The problem handed to Clarabel (after :meth:`LMIProblem._reduce`, or as compiled)."""

    A: object                 # scipy CSC, A x + s = b
    b: np.ndarray
    q: np.ndarray
    cones: list
    blocks: tuple             # (constraint, rows of its cone)
    kept_variables: np.ndarray


@dataclass
class LMIProblem:
    """Container of decision variables, PSD constraints and a linear objective.

    Examples
    --------
    >>> prob = LMIProblem("lyapunov")
    >>> P = prob.symmetric("P", 2)
    >>> A = np.array([[-1.0, 2.0], [0.0, -3.0]])
    >>> prob.require_psd("P > 0", P, margin=1e-6)
    >>> prob.require_nsd("A'P + PA < 0", A.T @ P + P @ A, margin=1e-6)
    >>> prob.minimize(trace(P))
    >>> sol = prob.solve()
    """

    name: str
    # False for an analysis (a bisection, a report): solved afresh every time, never committed
    # to or replayed from a design lock, and without the least-norm stage unless asked.
    design: bool = True
    # constants found at design time that the problem is built from (committed with the solution and
    # handed back by a replay: codegen.design.solver.Solver.committed_data); exact JSON numbers
    data: dict = field(default_factory=dict)
    _names: list = field(default_factory=list)
    _variables: dict = field(default_factory=dict)
    _constraints: list = field(default_factory=list)
    _objective: Affine | None = None
    _evaluate: object = None
    _compiled: object = None
    _symmetric: set = field(default_factory=set)      # names of the symmetric matrix variables
    _scalars: set = field(default_factory=set)        # names declared by scalar(): handed back as numbers

    @property
    def block_count(self) -> int:
        """How many PSD/NSD blocks the problem requires."""
        return len(self._constraints)

    @property
    def has_objective(self) -> bool:
        """Whether the problem minimizes something (else it asks for a feasible point)."""
        return self._objective is not None

    # -- decision variables -------------------------------------------------
    def _fresh(self, name: str, shape: tuple, slots: np.ndarray, count: int) -> Affine:
        """Affine matrix whose entry (i, j) is variable ``first + slots[i, j]`` (-1: zero)."""
        first = len(self._names)
        self._names.extend(f"{name}_{k}" for k in range(count))
        coef = np.zeros(shape + (first + count,))
        i, j = np.nonzero(slots >= 0)
        coef[i, j, first + slots[i, j]] = 1.0
        expr = Affine(np.zeros(shape), coef, tuple(self._names))
        if name in self._variables:
            raise LMIShapeError(f"{self.name}: variable {name!r} declared twice")
        self._variables[name] = expr
        return expr

    def scalar(self, name: str) -> Affine:
        self._scalars.add(name)
        return self._fresh(name, (1, 1), np.zeros((1, 1), dtype=int), 1)

    def matrix(self, name: str, rows: int, cols: int) -> Affine:
        # column-major numbering, as a reshaped vector of scalars
        return self._fresh(name, (rows, cols), np.arange(rows * cols).reshape(cols, rows).T, rows * cols)

    def symmetric(self, name: str, n: int) -> Affine:
        self._symmetric.add(name)
        slots = np.zeros((n, n), dtype=int)
        rows, cols, _ = _triu_index(n)
        slots[rows, cols] = slots[cols, rows] = np.arange(rows.size)
        return self._fresh(name, (n, n), slots, rows.size)

    # -- constraints --------------------------------------------------------
    def require_psd(self, label: str, expr, margin: float = 0.0, hint: str = "") -> None:
        """Require ``expr >= margin * I``."""
        expr = _as_affine(expr)
        if expr.shape[0] != expr.shape[1]:
            raise LMIShapeError(f"{self.name}: LMI {label!r} is {expr.shape[0]}x{expr.shape[1]}, not square")
        self._constraints.append(Constraint(label, expr, margin, hint))

    def require_nsd(self, label: str, expr, margin: float = 0.0, hint: str = "") -> None:
        """Require ``expr <= -margin * I``."""
        self.require_psd(label, -_as_affine(expr), margin, hint)

    def minimize(self, objective) -> None:
        objective = _as_affine(objective)
        if objective.shape != (1, 1):
            raise LMIShapeError(f"{self.name}: the objective must be a scalar, got shape {objective.shape}")
        self._objective = objective

    # -- compilation and solve -----------------------------------------------
    def _compile(self):
        """Coefficients of every block, stacked in Clarabel's form.

        Every block's coefficients are exact by construction; a block marked non-affine or
        not symmetric (relative 1e-12) is refused. Returns (names, A, b, q, cones, blocks)
        with blocks = [(constraint, rows in the stacked triangles, rows in the stacked full
        column-major blocks)].
        """
        nvar = len(self._names)
        # Built sparse: a block involves a few of the variables (a polytope's vertex its own gains),
        # and dense rows of every variable grew as blocks x variables (2.5 GB for a 2048-vertex one).
        tri_rows, tri_cols, tri_vals, tri_b = [], [], [], []
        full_rows, full_cols, full_vals, full_c = [], [], [], []
        blocks, cones = [], []
        index = {}   # triangle index arrays by block size, within this compilation
        offset = full_offset = 0
        for con in self._constraints:
            expr = con.expr
            if expr.nonaffine:
                bad = [v for used in expr.nonaffine for v in used][:4]
                raise NonAffineLMIError(
                    f"{self.name}: LMI {con.label!r} is not affine in the decision variables "
                    f"(products involving {', '.join(bad)}); fix one factor or use a change of variables")
            n = expr.shape[0]
            used = np.flatnonzero(expr.coef.any(axis=(0, 1)))
            coef = expr.coef[:, :, used]          # the variables this block involves
            const = expr.const
            if (np.abs(const - const.T) > 1e-12 * (1 + np.abs(const))).any() or \
                    (np.abs(coef - coef.transpose(1, 0, 2)) > 1e-12 * (1 + np.abs(coef))).any():
                raise LMIShapeError(f"{self.name}: LMI {con.label!r} is not symmetric")
            if n not in index:
                index[n] = _triu_index(n)
            rows, cols, scale = index[n]
            tri = coef[rows, cols] * scale[:, None]
            tri[np.abs(tri) < 1e-300] = 0.0
            r, c = np.nonzero(tri)
            tri_rows.append(offset + r)
            tri_cols.append(used[c])
            tri_vals.append(-tri[r, c])
            tri_b.append(const[rows, cols] * scale - con.margin * np.where(rows == cols, 1.0, 0.0))
            # column-major full blocks, for the independent re-check
            full = coef.transpose(1, 0, 2).reshape(n * n, used.size)
            r, c = np.nonzero(full)
            full_rows.append(full_offset + r)
            full_cols.append(used[c])
            full_vals.append(full[r, c])
            full_c.append(const.T.ravel())
            blocks.append((con, slice(offset, offset + rows.size), slice(full_offset, full_offset + n * n)))
            cones.append(clarabel.PSDTriangleConeT(n))
            offset += rows.size
            full_offset += n * n

        def stacked(rows, cols, vals, shape, fmt):
            if not rows:
                return sparse.csc_matrix(shape) if fmt == "csc" else sparse.csr_matrix(shape)
            coo = sparse.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape)
            return coo.tocsc() if fmt == "csc" else coo.tocsr()

        A = stacked(tri_rows, tri_cols, tri_vals, (offset, nvar), "csc")
        b = np.concatenate(tri_b) if tri_b else np.zeros(0)
        full_const = np.concatenate(full_c) if full_c else np.zeros(0)
        full_coef = stacked(full_rows, full_cols, full_vals, (full_offset, nvar), "csr")
        # the original block expressions, for the independent re-check (each entry the sum of its
        # terms in the order of the variables)
        self._evaluate = lambda xv: full_const + full_coef @ np.asarray(xv, dtype=float)
        self._compiled = blocks
        if self._objective is None:
            q = np.zeros(nvar)
        else:
            if self._objective.nonaffine:
                raise NonAffineLMIError(f"{self.name}: objective is not linear in the decision variables")
            q = _pad(self._objective.coef, nvar)[0, 0].copy()
        return tuple(self._names), A, b, q, cones, blocks

    def _reduce(self, q: np.ndarray, blocks) -> "ReducedProblem":
        """Exact reductions of the compiled problem for the solver; the feasible set and the
        objective over it are unchanged, and the certificate still re-checks every original block.

        1. Constant part of a block (Schur complement). Rows and columns K of a block that no
           variable enters, with a positive definite constant part C = S_KK, give
           ``[[E(x), B], [B', C]] >= 0  <=>  E(x) - B C^-1 B' >= 0`` (S = const - margin I).
        2. Implied blocks. A block with the same coefficients as another one and a constant part
           larger by a positive semidefinite matrix holds whenever that one holds: it is left out.
           (Theorem 1: (20) reduced by 1. is P_i + X >= (m + 1/(mu - m)) I, which implies (19).)
        3. Directions v that change no block and not the objective ([A; q] v = 0): x and
           x + t v are the same point of the problem, so as many variables as there are such
           directions are fixed at 0, earliest-declared first (:func:`_null_directions_fixed`).
           Theorem 1: the blocks depend on P_i and X only through P_i + X, so X = 0 loses nothing.
        Each removes work per iteration and the freedom that slows an interior-point method.
        """
        nvar = q.size
        parts = []   # (constraint, coefficients (n, n, nvar), constant part minus margin (n, n))
        for con, _, _ in blocks:
            n = con.expr.shape[0]
            coef = _pad(con.expr.coef, nvar)
            S = con.expr.const - con.margin * np.eye(n)
            fixed = ~coef.any(axis=(1, 2))
            if fixed.any() and not fixed.all():
                K, V = np.flatnonzero(fixed), np.flatnonzero(~fixed)
                C = S[np.ix_(K, K)]
                eig = np.linalg.eigvalsh(0.5 * (C + C.T))
                if eig[0] > 1e-9 * max(1.0, eig[-1]):
                    B = S[np.ix_(V, K)]
                    S = S[np.ix_(V, V)] - B @ np.linalg.solve(C, B.T)
                    S, coef = 0.5 * (S + S.T), coef[np.ix_(V, V)]
            parts.append((con, coef, S))
        groups = {}   # blocks with identical coefficients
        for j, (_, coef, _) in enumerate(parts):
            groups.setdefault((coef.shape, coef.tobytes()), []).append(j)
        keep = []
        for j, (_, _, S_j) in enumerate(parts):
            implied = False
            for i in groups[(parts[j][1].shape, parts[j][1].tobytes())]:
                if i == j:
                    continue
                low = np.linalg.eigvalsh(S_j - parts[i][2])[0]
                if low > 0 or (low == 0 and i < j and i in keep):
                    implied = True
                    break
            if not implied:
                keep.append(j)
        rows, rhs, cones, solver_blocks, offset = [], [], [], [], 0
        for j in keep:
            con, coef, S = parts[j]
            n = S.shape[0]
            r, c, scale = _triu_index(n)
            rows.append(coef[r, c] * scale[:, None])
            rhs.append(S[r, c] * scale)
            cones.append(clarabel.PSDTriangleConeT(n))
            solver_blocks.append((con, slice(offset, offset + r.size)))
            offset += r.size
        J = np.concatenate(rows) if rows else np.zeros((0, nvar))
        kept = np.setdiff1d(np.arange(nvar), _null_directions_fixed(J, q))
        J = J[:, kept]
        J[np.abs(J) < 1e-300] = 0.0
        return ReducedProblem(-sparse.csc_matrix(J), np.concatenate(rhs) if rhs else np.zeros(0),
                              q[kept].copy(), cones, tuple(solver_blocks), kept)

    def solve(self, tol: float = 1e-9, max_iter: int = 200, max_abs_value: float = 1e9,
              verbose: bool = False, reduce: bool = False, unique: bool | None = None,
              optimality_slack: float = OPTIMALITY_SLACK, refine: bool = False) -> LMISolution:
        """Solve with Clarabel, then re-check every block with numpy eigenvalues.

        ``unique`` (default: a design problem's ``design`` flag): the optimum of an SDP is often a face, not a point (the interconnected
        design's gains differ in sign between two BLAS kernels at the same gamma). A second
        stage picks the point of least Euclidean norm of all decision variables among those
        within ``optimality_slack`` (relative) of the first stage's objective: a strictly convex
        objective over a convex set has exactly one minimizer, so a re-solve on another machine
        gives materially the same design. Problems without an objective get the least-norm
        feasible point directly.

        ``refine`` (with ``unique`` false): the optimum itself, accurately (the first stage of the unique point:
        solved again in scaled coordinates), not the least-norm point near it: for an analysis that reads
        the optimal value alone.

        ``reduce``: hand Clarabel the exactly equivalent problem of :meth:`_reduce` (fewer and
        smaller cones, fewer variables: fewer and cheaper iterations). Off by default: the
        emitted designs come from the problem as stated (see docs, Performance).

        Always a fresh solve: a design's pipeline hands its design problems to a solver object
        (:mod:`codegen.design.solver`), which records this solution for a design lock or replays
        a committed one (:meth:`replay`) instead.

        Raises
        ------
        InfeasibleLMIError
            names the blocks carrying most of the infeasibility certificate.
        InaccurateSolveError, IllConditionedError, CertificateError, DesignLockError
        """
        unique = self.design if unique is None else unique
        t0 = time.perf_counter()
        names, A, b, q, cones, blocks = self._compile()
        nvar = len(names)
        if reduce:
            red = self._reduce(q, blocks)
        else:
            red = ReducedProblem(A, b, q, cones, tuple((con, tri) for con, tri, _ in blocks), np.arange(nvar))
        kept = red.kept_variables
        t1 = time.perf_counter()
        zero_P = sparse.csc_matrix((kept.size, kept.size))
        # with the refining stages to follow, an AlmostSolved first point is a good enough start
        result, solve_time = self._clarabel(zero_P, red.q, red.A, red.b, red.cones, red.blocks, tol, max_iter, verbose,
                                            stage="first solve" if unique or refine else "")
        iterations = int(result.iterations)
        xs = np.asarray(result.x, dtype=float)
        if unique:
            xs, its, dt = self._unique_point(red, blocks, xs, tol, max_iter, verbose, optimality_slack)
            iterations, solve_time = iterations + its, solve_time + dt
        elif refine:
            _, xs, _, its, dt = self._refined_optimum(red, xs, tol, max_iter, verbose)
            iterations, solve_time = iterations + its, solve_time + dt
        xv = np.zeros(nvar)
        xv[kept] = xs   # variables left out by _reduce are 0
        if not np.all(np.isfinite(xv)) or np.abs(xv).max(initial=0) > max_abs_value:
            raise IllConditionedError(
                f"{self.name}: solution has entries up to {np.abs(xv).max():.3g} (limit "
                f"{max_abs_value:g}); the problem is nearly unbounded — add or tighten a bound "
                f"on the gains/Lyapunov matrices")
        return self._solution(xv, blocks, float(q @ xv), "Solved", solve_time, t1 - t0, iterations)

    def _unique_point(self, red: "ReducedProblem", blocks, x0: np.ndarray, tol, max_iter, verbose, slack) -> tuple:
        """The least-norm point of the optimal set (see :meth:`solve`); returns (x, iterations, seconds).

        1. The optimum is refined with column scaling: each variable measured in a power of two
           of its magnitude at ``x0``. The problem and its optimum are the same, its conditioning
           is not (Theorem 1: gamma^2 ~ 1e-4 beside Lyapunov entries ~ 1e2 leaves a tolerance-1e-8
           solve 1-60 % above the optimum at gain bounds of 100-3000 1/s). The better of the two
           objectives bounds the second stage.
        2. min ||x / scale|| (a second-order cone) with the objective at most
           :func:`objective_bound` (the optimum times (1 + slack), rounded up to three significant
           digits: two machines whose optima differ in the last digits bound the same set, and
           the point on that bound does not move with their noise). A least-norm point lies on
           the boundary of the feasible set, within the solver's tolerance: blocks that then fail
           the numpy re-check get their margin raised by twice the violation and the stage is
           solved again (at most three times). If the stage does not converge in either
           coordinates, the refined optimum is returned (certified, not unique).
        """
        t_best, x_best, scale, its, secs = self._refined_optimum(red, x0, tol, max_iter, verbose)
        has_objective = bool(np.any(red.q))
        bound = objective_bound(t_best, slack) if has_objective else None
        b = red.b.copy()
        evaluate = self._evaluate
        if CENTRAL_MARGIN:
            central = self._central_margin(red, b, bound, x_best, tol, max_iter, verbose)
            if central is not None:
                b, it, dt = central
                its, secs = its + it, secs + dt
        for attempt in range(4):
            point = None
            for coordinates in ("own", "scaled"):
                try:
                    point = self._least_norm(red, b, bound, scale, coordinates, tol, max_iter, verbose)
                    break
                except InaccurateSolveError:
                    continue
            if point is None:
                # no least-norm point to the solver's accuracy: the refined optimum stands (certified
                # like any solution, but not the unique point a re-solve elsewhere would reach)
                return x_best, its, secs
            x, it, dt = point
            its, secs = its + it, secs + dt
            xv = np.zeros(len(self._names))
            xv[red.kept_variables] = x
            full = np.asarray(evaluate(xv), dtype=float).ravel()
            solver_rows = {id(con): rows for con, rows in red.blocks}
            failing = []
            for con, _, full_rows in blocks:
                k = con.expr.shape[0]
                mat = full[full_rows].reshape(k, k, order="F")
                lo = float(np.linalg.eigvalsh(0.5 * (mat + mat.T))[0])
                if lo < 0.0 and id(con) in solver_rows:
                    failing.append((solver_rows[id(con)], k, lo))
            if not failing or attempt == 3:
                return x, its, secs
            for rows, k, lo in failing:
                r, cidx, _ = _triu_index(k)
                diag = np.flatnonzero(r == cidx)
                if rows.stop - rows.start == r.size:       # a block the reduction left whole
                    b[np.arange(rows.start, rows.stop)[diag]] -= 2.0 * abs(lo)
        return x, its, secs

    def _refined_optimum(self, red: "ReducedProblem", x0: np.ndarray, tol, max_iter, verbose) -> tuple:
        """Stage 1 of :meth:`_unique_point`: (objective, point, the variables' power-of-two scale, iterations,
        seconds) of the better of ``x0`` and the optimum solved again with each variable measured in a power of
        two of its magnitude at ``x0``."""
        its, secs = 0, 0.0
        n = x0.size
        scale = np.ones(n)
        floor = SCALE_FLOOR * np.abs(x0).max(initial=0.0)
        for slots in self._variable_slots(red.kept_variables).values():
            m = max(np.abs(x0[slots]).max(initial=0.0), floor)
            if m > 0:
                scale[slots] = 2.0 ** np.round(np.log2(m))
        t_best, x_best = float(red.q @ x0), x0
        if bool(np.any(red.q)) and np.any(scale != 1.0):
            try:
                result, dt = self._clarabel(sparse.csc_matrix((n, n)), red.q * scale, red.A @ sparse.diags(scale),
                                            red.b, red.cones, red.blocks, tol, max_iter, verbose, stage="scaled optimum")
                its, secs = its + int(result.iterations), secs + dt
                x_scaled = scale * np.asarray(result.x, dtype=float)
                if float(red.q @ x_scaled) < t_best:
                    t_best, x_best = float(red.q @ x_scaled), x_scaled
            except (InaccurateSolveError, InfeasibleLMIError):
                pass        # the unscaled optimum stands
        return t_best, x_best, scale, its, secs

    def _norm_weights(self, red, scale) -> np.ndarray:
        """Weights of the least-norm stage: each variable in its own magnitude; the symmetric
        matrices (Lyapunov-type certificates) with weight 1, every other variable (gains,
        multipliers, the objective's scalars) with :data:`GAIN_WEIGHT`. The point is then the
        smallest certificate among the near-optimal designs, unique because every variable is in
        the norm; with all weights equal it would be the smallest gains instead, which at the same
        gamma made the switched PI observer's bank estimate 3-4x slower (docs/guarantees.md)."""
        w = 1.0 / scale
        for key, slots in self._variable_slots(red.kept_variables).items():
            if key not in self._symmetric:
                w[slots] *= GAIN_WEIGHT
        return w

    def _central_margin(self, red, b, bound, x1, tol, max_iter, verbose):
        """The largest common margin s, relative to each block's size at ``x1``, that every block
        keeps inside the optimal set (blocks >= (margin + s size) I, objective <= bound); returns
        the right-hand side with the margins raised to (1 - CENTRAL_GIVE) s* (decimal-rounded down),
        or None. The least-norm point of what is left is then interior, as the solver's own
        optimum was, instead of on the boundary where least norm alone would put it (smallest
        gains: a sluggish observer at the same gamma)."""
        from .rates import round_down
        n = red.q.size
        xv = np.zeros(len(self._names))
        xv[red.kept_variables] = x1
        sizes, diag_rows = [], []
        full = np.asarray(self._evaluate(xv), dtype=float).ravel()
        by_id = {id(con): full_rows for con, _, full_rows in self._compiled}
        for con, rows in red.blocks:
            k = con.expr.shape[0]
            r, c, _ = _triu_index(k)
            if rows.stop - rows.start != r.size or id(con) not in by_id:
                sizes.append(0.0)
                diag_rows.append(np.zeros(0, dtype=int))
                continue
            mat = full[by_id[id(con)]].reshape(k, k, order="F")
            size = float(np.abs(np.linalg.eigvalsh(0.5 * (mat + mat.T))).max(initial=0.0))
            sizes.append(2.0 ** np.round(np.log2(size)) if size > 0 else 0.0)
            diag_rows.append(np.arange(rows.start, rows.stop)[np.flatnonzero(r == c)])
        col = np.zeros(red.A.shape[0])
        for size, d in zip(sizes, diag_rows):
            col[d] = size
        rows, rhs, cones, shift = sparse.hstack([red.A, sparse.csc_matrix(col[:, None])]), b, list(red.cones), 0
        if bound is not None:
            rows = sparse.vstack([sparse.csc_matrix(np.concatenate([red.q, [0.0]])[None, :]), rows])
            rhs, cones, shift = np.concatenate([[bound], b]), [clarabel.NonnegativeConeT(1), *cones], 1
        cap = sparse.csc_matrix(([1.0], ([0], [n])), shape=(1, n + 1))       # s <= 1
        rows = sparse.vstack([rows, cap], format="csc")
        rhs = np.concatenate([rhs, [1.0]])
        q = np.zeros(n + 1)
        q[n] = -1.0
        try:
            result, dt = self._clarabel(sparse.csc_matrix((n + 1, n + 1)), q, rows, rhs,
                                        [*cones, clarabel.NonnegativeConeT(1)], red.blocks, tol, max_iter, verbose,
                                        shift=shift, stage="central margin")
        except (InaccurateSolveError, InfeasibleLMIError):
            return None
        s_star = float(np.asarray(result.x)[n])
        if not s_star > 0:
            return None
        s_keep = round_down(s_star * (1.0 - CENTRAL_GIVE), 3)
        return b - s_keep * col, int(result.iterations), dt

    def _least_norm(self, red, b, bound, scale, coordinates, tol, max_iter, verbose) -> tuple:
        """min tau s.t. ||x / scale|| <= tau, the blocks, and (with an objective) q x <= bound.

        Each variable is weighed in its own magnitude (``scale``, powers of two): with one norm for
        all, a large objective variable (a gain bound t ~ 1e7) would be all the norm sees.
        ``coordinates`` "scaled" solves for x / scale (the same point, other conditioning)."""
        n = red.q.size
        col = np.ones(n) if coordinates == "own" else scale
        A = red.A @ sparse.diags(col) if coordinates == "scaled" else red.A
        rows, rhs, cones, shift = A, b, list(red.cones), 0
        if bound is not None:
            rows = sparse.vstack([sparse.csc_matrix((red.q * col)[None, :]), A], format="csc")
            rhs = np.concatenate([[bound], b])
            cones, shift = [clarabel.NonnegativeConeT(1), *red.cones], 1
        soc = sparse.vstack([sparse.csc_matrix(([-1.0], ([0], [n])), shape=(1, n + 1)),
                             sparse.hstack([-sparse.diags(col * self._norm_weights(red, scale)),
                                            sparse.csc_matrix((n, 1))])])
        rows = sparse.vstack([sparse.hstack([rows, sparse.csc_matrix((rows.shape[0], 1))]), soc], format="csc")
        q2 = np.zeros(n + 1)
        q2[n] = 1.0
        result, dt = self._clarabel(sparse.csc_matrix((n + 1, n + 1)), q2, rows, np.concatenate([rhs, np.zeros(n + 1)]),
                                    [*cones, clarabel.SecondOrderConeT(n + 1)], red.blocks, tol, max_iter, verbose,
                                    shift=shift, stage="least-norm point")
        return col * np.asarray(result.x, dtype=float)[:n], int(result.iterations), dt

    def _variable_slots(self, kept: np.ndarray) -> dict:
        """{variable name: positions in ``kept`` of its scalar variables}."""
        where = {int(k): pos for pos, k in enumerate(kept)}
        out = {}
        for key, expr in self._variables.items():
            slots = sorted({where[int(k)] for k in np.nonzero(expr.coef)[2] if int(k) in where})
            if slots:
                out[key] = np.array(slots, dtype=int)
        return out

    def _clarabel(self, P, q, A, b, cones, blocks, tol, max_iter, verbose, shift: int = 0, stage: str = ""):
        """One Clarabel solve; ``blocks`` name the cones from row ``shift`` on (for the
        infeasibility message). Returns (result, solve seconds).

        The refining stages (``stage`` given) start from a point the first solve proved feasible
        and accept Clarabel's AlmostSolved (its reduced tolerances): what counts is the numpy
        re-check of every block, which the returned solution still has to pass."""
        settings = clarabel.DefaultSettings()
        settings.verbose = verbose
        settings.tol_gap_abs = tol
        settings.tol_gap_rel = tol
        settings.tol_feas = tol
        settings.tol_infeas_abs = tol
        settings.tol_infeas_rel = tol
        settings.max_iter = max_iter
        solver = clarabel.DefaultSolver(P, q, A, b, cones, settings)
        t0 = time.perf_counter()
        result = solver.solve()
        dt = time.perf_counter() - t0
        status = str(result.status)
        if "Infeasible" in status:
            z = np.asarray(result.z)[shift:]
            raise InfeasibleLMIError(self._infeasibility_message(status, z, blocks), status=status.split(".")[-1])
        if status.split(".")[-1] != "Solved" and not (stage and status.split(".")[-1] == "AlmostSolved"):
            raise InaccurateSolveError(
                f"{self.name}{' (' + stage + ')' if stage else ''}: Clarabel stopped with status {status} after {result.iterations} "
                f"iterations; loosen the tolerance (now {tol:g}), rescale the data, or relax the "
                f"design constraints")
        return result, dt

    def _solution(self, xv, blocks, objective, status, solve_time, build_time, iterations) -> LMISolution:
        values = {k: v.value(xv) for k, v in self._variables.items()}
        # a scalar is a number; a matrix or symmetric variable stays a matrix even at 1x1 (a one-state model)
        values = {k: (v.item() if k in self._scalars else v) for k, v in values.items()}
        checks = self.certify_values(xv, blocks, self._evaluate)
        return LMISolution(values, objective, status, solve_time, build_time, iterations, checks)

    def replay(self, record: "SolveRecord") -> LMISolution:
        """The committed solution ``record`` of this problem, re-checked block by block (no solver).

        Raises
        ------
        DesignLockError
            the record was solved for other constants (:attr:`data`), other variables or shapes.
        CertificateError
            a block fails the numpy re-check."""
        t0 = time.perf_counter()
        names, _, _, q, _, blocks = self._compile()
        if record.data != self.data:
            raise DesignLockError(
                f"{self.name}: committed for {record.data}, the problem is built for {self.data}; re-solve with "
                f"`uiogen design NAME --update`")
        if set(record.variables) != set(self._variables):
            raise DesignLockError(
                f"{self.name}: the committed solution has variables {sorted(record.variables)}, the problem "
                f"{sorted(self._variables)}; re-solve with `uiogen design NAME --update`")
        xv = np.zeros(len(names))
        for key, expr in self._variables.items():
            value = np.atleast_2d(np.asarray(record.variables[key], dtype=float))
            if value.shape != expr.shape:
                raise DesignLockError(f"{self.name}: committed {key} has shape {value.shape}, the problem "
                                      f"{expr.shape}; re-solve with `uiogen design NAME --update`")
            i, j, k = np.nonzero(expr.coef)
            xv[k] = value[i, j]
        return self._solution(xv, blocks, record.objective, "Committed", 0.0, time.perf_counter() - t0,
                              record.iterations)

    @staticmethod
    def certify_values(xv: np.ndarray, blocks, evaluate) -> tuple:
        """Evaluate every block at ``xv`` and check its eigenvalues with numpy."""
        full = np.asarray(evaluate(xv), dtype=float).ravel()
        checks = []
        for con, _, rows in blocks:
            n = con.expr.shape[0]
            mat = full[rows].reshape(n, n, order="F")
            eig = np.linalg.eigvalsh(0.5 * (mat + mat.T))
            check = BlockCheck(con.label, n, float(eig[0]), float(np.abs(eig).max()))
            checks.append(check)
            if not check.certified:
                raise CertificateError(
                    f"LMI {con.label!r} fails the numpy re-check: {check.failure()}; the solver's answer "
                    f"cannot be trusted — tighten the solver tolerance or add a margin")
        return tuple(checks)

    def _infeasibility_message(self, status: str, z: np.ndarray, blocks) -> str:
        """``blocks``: (constraint, rows of z) of every cone the solver saw."""
        weights = [(float(np.abs(z[rows]).sum()), con) for con, rows in blocks]
        total = sum(w for w, _ in weights) or 1.0
        weights.sort(key=lambda t: -t[0])
        top = [f"{con.label!r} ({100 * w / total:.0f}% of the certificate)"
               + (f" — {con.hint}" if con.hint else "") for w, con in weights[:3] if w > 0]
        return (f"{self.name}: LMIs are infeasible (Clarabel: {status}). Blocks carrying the "
                f"infeasibility certificate: {'; '.join(top) or 'unknown'}")


def unsvec(vec: np.ndarray, n: int) -> np.ndarray:
    """Inverse of :func:`svec`."""
    mat = np.zeros((n, n))
    for val, (i, j) in zip(vec, _triu_pairs(n)):
        v = val if i == j else val / SQRT2
        mat[i, j] = v
        mat[j, i] = v
    return mat


def check_blocks(named_blocks: dict) -> tuple:
    """Certificate of numeric matrices: ``{label: symmetric matrix that must be PSD}``.

    Used to check externally supplied designs without any solver.
    """
    out = []
    for label, mat in named_blocks.items():
        mat = np.asarray(mat, dtype=float)
        sym = 0.5 * (mat + mat.T)
        eig = np.linalg.eigvalsh(sym)
        out.append(BlockCheck(label, mat.shape[0], float(eig[0]), float(np.abs(eig).max())))
    return tuple(out)
