"""A small LMI layer compiled straight to Clarabel's PSD triangle cones.

Decision variables are CasADi SX symbols (scalars, matrices, symmetric
matrices); constraints are affine symmetric matrix expressions built with
ordinary matrix algebra. Compilation extracts the exact coefficients with
``casadi.jacobian`` (an expression that still depends on the variables after
differentiation is not affine and is refused), stacks them in Clarabel's
``A x + s = b, s in K`` form (upper triangle, column-major, off-diagonals scaled
by sqrt(2)) and solves. Every solution is re-checked with ``numpy.linalg.eigvalsh``
on every block, independently of the solver, before it is returned.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import clarabel
import numpy as np
from scipy import sparse

from .errors import (
    CertificateError,
    IllConditionedError,
    InaccurateSolveError,
    InfeasibleLMIError,
    LMIShapeError,
    NonAffineLMIError,
    SolverError,
)

SQRT2 = np.sqrt(2.0)


def _triu_pairs(n: int):
    """Index pairs (row, col) of the upper triangle, column by column (Clarabel's order)."""
    return [(i, j) for j in range(n) for i in range(j + 1)]


def svec(mat: np.ndarray) -> np.ndarray:
    """Clarabel's scaled vectorization of a symmetric matrix."""
    n = mat.shape[0]
    return np.array([mat[i, j] * (1.0 if i == j else SQRT2) for i, j in _triu_pairs(n)])


@dataclass
class Constraint:
    """``expr >= margin * I`` (PSD) for a symmetric affine expression."""

    label: str
    expr: ca.SX
    margin: float
    hint: str


@dataclass(frozen=True)
class BlockCheck:
    label: str
    size: int
    min_eig: float        # of expr - margin*I ... reported for expr itself
    scale: float          # largest |eigenvalue| of the block, for a relative figure

    @property
    def relative_margin(self) -> float:
        return self.min_eig / max(self.scale, 1e-300)


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
        return min(self.checks, key=lambda c: c.relative_margin)

    def __getitem__(self, name: str):
        return self.values[name]


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
    >>> prob.minimize(ca.trace(P))
    >>> sol = prob.solve()
    """

    name: str
    _symbols: list = field(default_factory=list)
    _variables: dict = field(default_factory=dict)
    _constraints: list = field(default_factory=list)
    _objective: ca.SX | None = None
    _evaluate: ca.Function | None = None

    # -- decision variables -------------------------------------------------
    def _fresh(self, name: str, count: int) -> list:
        syms = [ca.SX.sym(f"{name}_{k}") for k in range(count)]
        self._symbols.extend(syms)
        return syms

    def _register(self, name: str, expr: ca.SX) -> ca.SX:
        if name in self._variables:
            raise LMIShapeError(f"{self.name}: variable {name!r} declared twice")
        self._variables[name] = expr
        return expr

    def scalar(self, name: str) -> ca.SX:
        return self._register(name, self._fresh(name, 1)[0])

    def matrix(self, name: str, rows: int, cols: int) -> ca.SX:
        syms = self._fresh(name, rows * cols)
        return self._register(name, ca.reshape(ca.vertcat(*syms), rows, cols))

    def symmetric(self, name: str, n: int) -> ca.SX:
        syms = iter(self._fresh(name, n * (n + 1) // 2))
        mat = ca.SX(n, n)
        for i, j in _triu_pairs(n):
            s = next(syms)
            mat[i, j] = s
            mat[j, i] = s
        return self._register(name, mat)

    # -- constraints --------------------------------------------------------
    def require_psd(self, label: str, expr, margin: float = 0.0, hint: str = "") -> None:
        """Require ``expr >= margin * I``."""
        expr = ca.SX(expr) if not isinstance(expr, ca.SX) else expr
        if expr.shape[0] != expr.shape[1]:
            raise LMIShapeError(f"{self.name}: LMI {label!r} is {expr.shape[0]}x{expr.shape[1]}, not square")
        self._constraints.append(Constraint(label, expr, margin, hint))

    def require_nsd(self, label: str, expr, margin: float = 0.0, hint: str = "") -> None:
        """Require ``expr <= -margin * I``."""
        self.require_psd(label, -expr, margin, hint)

    def minimize(self, objective) -> None:
        self._objective = ca.SX(objective)

    # -- compilation and solve -----------------------------------------------
    def _compile(self):
        """Coefficients of every block, stacked in Clarabel's form.

        Affinity is checked structurally (``casadi.which_depends`` of order 2: no entry may
        depend nonlinearly on a variable); the coefficients are then read by evaluating the
        vectorized blocks at 0 and at 2**40 e_k (a power of two, so dividing back is exact
        and the constant part cannot swamp the coefficient). Returns (x, A, b, q, cones,
        blocks) with blocks = [(constraint, rows in the stacked triangles, rows in the stacked
        full column-major blocks)].
        """
        x = ca.vertcat(*self._symbols)
        nvar = x.shape[0]
        vecs, blocks, cones, margins, tri_rows, full_offset, offset = [], [], [], [], [], 0, 0
        sym_a, sym_b = [], []
        for con in self._constraints:
            n = con.expr.shape[0]
            vecs.append(ca.vec(con.expr))
            pairs = _triu_pairs(n)
            for i, j in pairs:  # column-major vec: entry (i, j) sits at j*n + i
                tri_rows.append((full_offset + j * n + i, 1.0 if i == j else SQRT2))
                if i != j:
                    sym_a.append(full_offset + j * n + i)
                    sym_b.append(full_offset + i * n + j)
            blocks.append((con, slice(offset, offset + len(pairs)), slice(full_offset, full_offset + n * n)))
            margins.append(svec(con.margin * np.eye(n)))
            cones.append(clarabel.PSDTriangleConeT(n))
            offset += len(pairs)
            full_offset += n * n
        V = ca.vertcat(*vecs) if vecs else ca.SX(0, 1)
        nonlinear = ca.which_depends(V, x, 2, True) if nvar else []
        if any(nonlinear):
            for con in self._constraints:
                dep = ca.which_depends(ca.vec(con.expr), x, 2, False)
                if any(dep):
                    bad = [str(self._symbols[k]) for k, d in enumerate(dep) if d][:4]
                    raise NonAffineLMIError(
                        f"{self.name}: LMI {con.label!r} is not affine in the decision variables "
                        f"(products involving {', '.join(bad)}); fix one factor or use a change of variables")
        f = ca.Function("blocks", [x], [V])
        probe = 2.0 ** 40
        vals = np.asarray(f.map(nvar + 1)(np.hstack([np.zeros((nvar, 1)), probe * np.eye(nvar)])).full())
        c_full = vals[:, 0]
        J_full = (vals[:, 1:] - c_full[:, None]) / probe
        if sym_a:
            mismatch = (np.abs(c_full[sym_a] - c_full[sym_b]) > 1e-12 * (1 + np.abs(c_full[sym_a]))) | \
                (np.abs(J_full[sym_a] - J_full[sym_b]).max(axis=1) > 1e-12 * (1 + np.abs(J_full[sym_a]).max(axis=1)))
            if mismatch.any():
                bad_row = sym_a[int(np.argmax(mismatch))]
                start = 0
                for con in self._constraints:
                    n = con.expr.shape[0]
                    if start <= bad_row < start + n * n:
                        raise LMIShapeError(f"{self.name}: LMI {con.label!r} is not symmetric")
                    start += n * n
        rows = np.array([r for r, _ in tri_rows], dtype=int)
        scale = np.array([w for _, w in tri_rows])
        J = J_full[rows] * scale[:, None]
        J[np.abs(J) < 1e-300] = 0.0
        A = -sparse.csc_matrix(J)
        b = c_full[rows] * scale - (np.concatenate(margins) if margins else 0.0)
        self._evaluate = f  # the original block expressions, for the independent re-check
        if self._objective is None:
            q = np.zeros(nvar)
        else:
            if any(ca.which_depends(self._objective, x, 2, True)):
                raise NonAffineLMIError(f"{self.name}: objective is not linear in the decision variables")
            fo = ca.Function("obj", [x], [self._objective])
            ov = np.asarray(fo.map(nvar + 1)(np.hstack([np.zeros((nvar, 1)), probe * np.eye(nvar)])).full()).ravel()
            q = (ov[1:] - ov[0]) / probe
        return x, A, b, q, cones, blocks

    def solve(self, tol: float = 1e-9, max_iter: int = 200, max_abs_value: float = 1e9,
              verbose: bool = False) -> LMISolution:
        """Solve with Clarabel, then re-check every block with numpy eigenvalues.

        Raises
        ------
        InfeasibleLMIError
            names the blocks carrying most of the infeasibility certificate.
        InaccurateSolveError, IllConditionedError, CertificateError
        """
        t0 = time.perf_counter()
        x, A, b, q, cones, blocks = self._compile()
        nvar = x.shape[0]
        settings = clarabel.DefaultSettings()
        settings.verbose = verbose
        settings.tol_gap_abs = tol
        settings.tol_gap_rel = tol
        settings.tol_feas = tol
        settings.tol_infeas_abs = tol
        settings.tol_infeas_rel = tol
        settings.max_iter = max_iter
        P = sparse.csc_matrix((nvar, nvar))
        solver = clarabel.DefaultSolver(P, q, A, b, cones, settings)
        t1 = time.perf_counter()
        result = solver.solve()
        t2 = time.perf_counter()
        status = str(result.status)
        if "Infeasible" in status:
            raise InfeasibleLMIError(self._infeasibility_message(status, np.asarray(result.z), blocks))
        if status.split(".")[-1] != "Solved":
            raise InaccurateSolveError(
                f"{self.name}: Clarabel stopped with status {status} after {result.iterations} "
                f"iterations; loosen the tolerance (now {tol:g}), rescale the data, or relax the "
                f"design constraints")
        xv = np.asarray(result.x, dtype=float)
        if not np.all(np.isfinite(xv)) or np.abs(xv).max(initial=0) > max_abs_value:
            raise IllConditionedError(
                f"{self.name}: solution has entries up to {np.abs(xv).max():.3g} (limit "
                f"{max_abs_value:g}); the problem is nearly unbounded — add or tighten a bound "
                f"on the gains/Lyapunov matrices")
        names = list(self._variables)
        evaluated = ca.Function("v", [x], [ca.SX(self._variables[k]) for k in names])(xv)
        evaluated = evaluated if isinstance(evaluated, (list, tuple)) else [evaluated]
        values = {k: np.array(v.full(), dtype=float) for k, v in zip(names, evaluated)}
        values = {k: (v.item() if v.size == 1 else v) for k, v in values.items()}
        checks = self.certify_values(xv, blocks, self._evaluate)
        return LMISolution(values, float(result.obj_val), status, t2 - t1, t1 - t0,
                           int(result.iterations), checks)

    @staticmethod
    def certify_values(xv: np.ndarray, blocks, evaluate: ca.Function) -> tuple:
        """Evaluate every block at ``xv`` and check its eigenvalues with numpy."""
        full = np.asarray(evaluate(xv).full()).ravel()
        checks = []
        for con, _, rows in blocks:
            n = con.expr.shape[0]
            mat = full[rows].reshape(n, n, order="F")
            eig = np.linalg.eigvalsh(0.5 * (mat + mat.T))
            check = BlockCheck(con.label, n, float(eig[0]), float(np.abs(eig).max()))
            checks.append(check)
            if eig[0] < 0.0:
                raise CertificateError(
                    f"LMI {con.label!r} fails the numpy re-check: smallest eigenvalue "
                    f"{eig[0]:.3e} < 0 (block scale {check.scale:.3e}); the solver's answer "
                    f"cannot be trusted — tighten the solver tolerance or add a margin")
        return tuple(checks)

    def _infeasibility_message(self, status: str, z: np.ndarray, blocks) -> str:
        weights = [(float(np.abs(z[rows]).sum()), con) for con, rows, _ in blocks]
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
