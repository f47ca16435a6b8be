"""Algebraic LPV unknown-input observers of arbitrary relative degree (Ichalal and Mammar 2015, Ichalal & Mammar 2015).

Continuous observer (59)/(85)/(86), with everything derived by :mod:`codegen.families.algebraic_uio.representation`::

    x_hat' = (A - L C - Q Mcal) x_hat + Q Y + L y,      d_hat = Gamma^dagger (Y - Mcal x_hat)

(Gamma^dagger = Gamma^-1 when square, else the left inverse of
:func:`codegen.families.algebraic_uio.representation.left_inverse`, Q = D Gamma^dagger.)

Y stacks the output derivatives y_i^(r_i); for r = 1 it is observer (23) (A - Q Mcal = P A). Known
inputs are removed with the auxiliary system (20)-(21): s' = A s + B u, the observer runs on
z = x - s with y_z = y - C s, and x_hat = z_hat + s.

Design (LMI (39)): a quadratic V = e'Xe with He(X(F - L C)) <= -2 alpha X on every vertex of an exact
polytope of the error dynamics. ``lmi = "product"`` is (39) literally (r = 1 only): P_rho and A_rho
get their own sector polytopes (premises found in each), L_rho = sum mu^A_j L_j, and
P_i A_j - L_j C is imposed for every pair (i, j), which covers P_rho A_rho - L_rho C exactly because
sum_i mu^P_i = 1. ``lmi = "direct"`` builds one polytope of F0 = A - Q Mcal in the parameters and
their derivatives (paper's (73)-(75), e.g. rho_1 = rho, rho_2 of (71) for Example 2) and pairs each
vertex with its own gain. The problem is homogeneous in (X, K): X >= I, and ||K_j|| is minimized.

Discrete step (what the C runs), at the configured sample time h:

* each output y_i (of y_z) and each scheduling signal has a Levant differentiator
  (:mod:`codegen.representation.differentiators`, state in the observer's state vector, update in the step);
  after the update with the sample at t_j, its state is a Taylor polynomial at t_{j+1}, exact for
  polynomials, which gives Y, y, rho, rho', ... anywhere in [t_{j-1}, t_j];
* the observer ODE is integrated over [t_{j-1}, t_j] by the 2-stage Gauss-Legendre method (order 4)
  with those polynomial inputs at the stage times (no O(h) lag: noise free, the errors sit at the
  differentiators' accuracy, ~1e-10 relative at 1 ms);
* Gauss methods are algebraically stable (M = BA + A'B - bb' = 0), so for V = e'Xe
  ``V(e+) = V(e) + 2h sum_i b_i <F_i Y_i, Y_i>_X <= V(e) - 2 h alpha sum_i b_i V(Y_i)`` for ANY stage
  matrices F_i in the certified polytope (B-stability): the step is non-expansive at every h and
  every scheduling sequence. With f = max_v ||F_v - L_v C||_X and a = max_i sum_j |a_ij|,
  ``||Y_i||_X >= (1 - g) ||e||_X``, g = h a f / (1 - h a f), hence sqrt(V) contracts by at most
  ``sqrt(1 - 2 h alpha (1 - g)^2)`` per step (:func:`discrete_certificate`);
* scheduling values at the stages (and at t_j) are clamped to the box of each parameter and derivative,
  so every F_i is inside the certified polytope; a clamp raises SCHEDULING_CLAMPED.
"""
from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np
import sympy as sp
from scipy.linalg import matrix_balance

from . import representation as rdeg
from ...representation.bounds import range_bound
from ...representation.differentiators import MAX_ORDER, HosmdSpec
from ...emit.stepgen import lambdify
from ...errors import (CertificateError, DesignLockError, DiscretizationError, InaccurateSolveError,
                      InfeasibleLMIError, ModelDefinitionError, SolverError)
from ...design.lmi import LMIProblem, LMISolution, bmat, check_blocks, trace, uncertified, worst_block
from ...model import LPVModel
from ...representation.polytope import (Premise, affine_decomposition, nonlinear_factors, sector_weights_product,
                                        vertex_matrices)
from ...settings import Rule, config_error, number_matrix, parse_settings, parse_table, parse_value, setting
from ...design.precision import margin_field, precision_field, required_margin
from ...representation import canonical
from ...representation.canonical import decimal_round

# 2-stage Gauss-Legendre (order 4)
_S3 = math.sqrt(3.0)
GL_C = (0.5 - _S3 / 6.0, 0.5 + _S3 / 6.0)
GL_A = ((0.25, 0.25 - _S3 / 6.0), (0.25 + _S3 / 6.0, 0.25))
GL_B = (0.5, 0.5)
#: a of :func:`discrete_certificate`: max_i sum_j |a_ij| of the tableau (0.5 + sqrt(3)/6)
GL_ROW_SUM = max(sum(abs(v) for v in row) for row in GL_A)


def decay_limit_of_step(h: float) -> float:
    """The decay rates the Gauss step can certify at sample time ``h`` are below this: He(X F) <= -2 alpha X
    gives ||F||_X >= alpha, and :func:`discrete_certificate` needs h a ||F||_X < 1."""
    return 1.0 / (GL_ROW_SUM * h)



# ---- settings -----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class AlgebraicSettings:
    """Design settings of one observer (the ``[design]`` table of its configuration).

    Attributes
    ----------
    lmi : str
        "product" (LMI (39) with separate P and A polytopes, r = 1) or "direct" (polytope of A - Q Mcal).
    alpha : float
        Certified decay rate: He(X (F - L C)) <= -2 alpha X, i.e. V decays at least like exp(-2 alpha t).
    margin, tol : float
        Every LMI block <= -margin I; Clarabel tolerance.
    differentiators : dict
        {input name ("y_<output>" or a scheduling signal): HosmdSpec}.
    auxiliary : str
        Known inputs: "open_loop" (the paper's auxiliary system (20)) or "output_injection" (see :func:`aux_design`).
    auxiliary_alpha : float
        Decay rate of the output-injected auxiliary system.
    compare_gain : tuple or None
        A hand-picked constant gain (e.g. the paper's (52)) to certify beside the design, reported only.
    """

    lmi: str = setting("direct", choices=("product", "direct"))
    alpha: float = setting(1.0, gt=0, doc="certified decay rate")
    margin: float = setting(1e-6, ge=0)
    tol: float = setting(1e-9, gt=0)
    differentiators: dict = setting(default_factory=dict, doc="[design.differentiators.NAME] order, lipschitz")
    compare_gain: tuple | None = setting(None, parse=number_matrix)
    auxiliary: str = setting("open_loop", choices=("open_loop", "output_injection"))
    auxiliary_alpha: float = setting(0.5, gt=0, doc="decay rate of the output-injected auxiliary system")
    precision: str = precision_field()
    float32_margin: float = margin_field()

    def __post_init__(self):
        if self.lmi not in ("product", "direct"):
            raise ModelDefinitionError(f"[design] lmi must be 'product' or 'direct', got {self.lmi!r}")
        if not self.alpha > 0 or not self.margin >= 0 or not self.tol > 0:
            raise ModelDefinitionError("[design] needs alpha > 0, margin >= 0, tol > 0")


# [design.differentiators.NAME]: both keys required
DIFFERENTIATOR_RULES = {"order": Rule(int, ge=1, le=MAX_ORDER, required=True, doc="highest derivative estimated"),
                        "lipschitz": Rule(float, gt=0, required=True, doc="bound of |f^(order+1)|")}


def settings_from_config(config) -> AlgebraicSettings:
    """The ``[design]`` table as :class:`AlgebraicSettings` (every key and value checked, see codegen.settings)."""
    d = dict(config.design)
    specs = {}
    diffs = parse_value(d.get("differentiators", {}), Rule(dict), source=config.source, section="design",
                        key="differentiators")
    for name, tbl in diffs.items():
        tbl = parse_table(tbl, DIFFERENTIATOR_RULES, source=config.source, section=f"design.differentiators.{name}")
        specs[name] = HosmdSpec(tbl["order"], tbl["lipschitz"], config.sample_time, name=name)
    settings = parse_settings(AlgebraicSettings, d, source=config.source, section="design", differentiators=specs)
    limit = decay_limit_of_step(config.sample_time)
    if not settings.alpha < limit:
        raise config_error(config.source, "design", "alpha", d.get("alpha", settings.alpha),
                           f"must be < {limit:.4g} 1/s at sample_time = {config.sample_time:g} s: the 2-stage "
                           f"Gauss-Legendre step is certified only for h a ||F - L C||_X < 1 (a = {GL_ROW_SUM:.4g}, "
                           f"the largest row sum of |A| of its tableau), and a decay rate alpha needs ||F - L C||_X "
                           f">= alpha, so alpha < 1 / (a h); a faster decay needs a shorter sample_time")
    if required_margin(settings):
        # precision = "float32": the Gauss step contracts by sqrt(1 - 2 h alpha (1 - g)^2), g >= 0 from the
        # gains; alpha for g = 0 is the least that can do, the certificate then checks the margin
        m = required_margin(settings)
        need = (1.0 - (1.0 - m) ** 2) / (2.0 * config.sample_time)
        settings = dataclasses.replace(settings, alpha=max(settings.alpha, need))
    return settings


# ---- exact polytopes of symbolic matrices -------------------------------------------------------------

@dataclass(frozen=True)
class MatrixPolytope:
    """M(p) = sum_v mu_v(p) M_v exactly, mu = products of sector weights of the premises."""

    label: str
    premises: tuple          # Premise(name, expr in parameter/derivative symbols, lower, upper): sound range
    vertices: np.ndarray     # (N, rows, cols)

    @property
    def n_vertices(self) -> int:
        return self.vertices.shape[0]

    def to_json(self) -> dict:
        return {"premises": [{"expr": str(p.expr), "range": [p.lower, p.upper]} for p in self.premises],
                "vertices": self.vertices.tolist()}


def matrix_polytope(mat: sp.Matrix, boxes: dict, label: str) -> MatrixPolytope:
    """Sector polytope of a symbolic matrix: premises = its distinct nonconstant factors, ranges by
    sound interval bounds over ``boxes`` (so the polytope contains every value on the box)."""
    mat = sp.Matrix(mat).applyfunc(lambda e: sp.nsimplify(e, rational=True))
    syms = sorted(set().union(*(e.free_symbols for e in mat)), key=str)
    nonlin = nonlinear_factors([mat], syms) if syms else ()
    premises = []
    for k, g in enumerate(nonlin):
        box = rdeg._box_for(g, boxes, f"premise {g} of {label}")
        rb = range_bound(g, box, rel_tol=1e-6)
        if not rb.upper > rb.lower:
            raise ModelDefinitionError(f"premise {g} of {label} is constant on the box")
        premises.append(Premise(f"p{k}", g, rb.lower, rb.upper))
    decomp = affine_decomposition({label: mat}, syms, nonlin)
    p = len(premises)
    corners = [[(pr.upper if (idx >> (p - 1 - j)) & 1 else pr.lower) for j, pr in enumerate(premises)]
               for idx in range(2 ** p)]
    return MatrixPolytope(label, tuple(premises), vertex_matrices(decomp, corners)[label])


def _lambdify(symbols, expr, xp):
    expr = sp.sympify(expr)
    expr = expr.evalf(20) if not isinstance(expr, sp.MatrixBase) else expr.applyfunc(lambda e: e.evalf(20))
    return lambdify(symbols, expr, xp)


# ---- the classical polytopic UIO (11) --------------------------------------------------------------------

def classical_uio(lpv: LPVModel, boxes: dict, rel_tol: float = 1e-9) -> dict:
    """Try the classical polytopic UIO (11) with F = 0: a common H with (I + H C) D_i = 0 at every
    vertex of the polytope (41) of (A, D) (eqs. (17), (47)-(48)).

    Returns a report: per-vertex rank(C D_i) vs rank(D_i), per-vertex solutions H_i (least squares),
    whether a common H exists and, if not, why.
    """
    n, nd = lpv.nx, lpv.nd
    poly = matrix_polytope(sp.Matrix.hstack(lpv.A, lpv.D), boxes, "[A D]")
    C = np.array(lpv.C.evalf(), dtype=float)
    D_v = [v[:, n:n + nd] for v in poly.vertices]
    report = {"vertices": [], "premises": [str(p.expr) for p in poly.premises]}
    ranks_ok = True
    rhs, lhs = [], []
    for k, Dv in enumerate(D_v):
        CD = C @ Dv
        r_cd, r_d = np.linalg.matrix_rank(CD), np.linalg.matrix_rank(Dv)
        ranks_ok &= r_cd == r_d
        # H C D_v = -D_v, least squares for H (n x ny): (C D_v)' H' = -D_v'
        Hv, *_ = np.linalg.lstsq(CD.T, -Dv.T, rcond=None)
        res = float(np.abs(Hv.T @ CD + Dv).max())
        report["vertices"].append({"D": Dv.ravel().tolist(), "rank_CD": int(r_cd), "rank_D": int(r_d),
                                   "H": Hv.T.tolist(), "residual": res})
        lhs.append(CD)
        rhs.append(-Dv)
    Hc, *_ = np.linalg.lstsq(np.hstack(lhs).T, np.hstack(rhs).T, rcond=None)
    residual = float(max(np.abs(Hc.T @ l - r).max() for l, r in zip(lhs, rhs)))
    scale = max(float(np.abs(np.hstack(rhs)).max()), 1e-300)
    exists = ranks_ok and residual <= rel_tol * scale
    if not ranks_ok:
        reason = ("the matching condition rank(C D_i) = rank(D_i) fails at a vertex "
                  f"({', '.join(str(v['rank_CD']) + ' vs ' + str(v['rank_D']) for v in report['vertices'])}), so (I + H C) D_i = 0 "
                  "has no solution even at a single vertex")
    elif not exists:
        per = "; ".join(f"vertex {k + 1}: H = {np.round(np.asarray(v['H']).ravel(), 6).tolist()}"
                        for k, v in enumerate(report["vertices"]))
        reason = (f"each vertex has its own solution of H C D_i = -D_i ({per}), but no common H satisfies "
                  f"all of them (least-squares residual {residual:.3g}): the polytope fixes the structure of H, "
                  f"while D(rho)/(C D(rho)) changes direction with rho")
    else:
        reason = "a common H exists"
    report.update({"exists": bool(exists), "common_H_least_squares": Hc.T.tolist(), "residual": residual,
                   "reason": reason})
    return report


# ---- LMI (39) ------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class AlgebraicDesign:
    """Gains, Lyapunov matrix and their certificate."""

    settings: AlgebraicSettings
    form: str                       # "product" | "direct"
    gain_polytope: MatrixPolytope   # memberships the gain L(p) = sum mu_j L_j uses
    factor_polytope: MatrixPolytope | None   # P_rho's polytope (product form)
    X: np.ndarray
    L: tuple                        # L_j (n x ny)
    closed_loop: tuple              # (label, F_cl numeric n x n) covering F(p) - L(p) C
    scaling: np.ndarray             # diagonal state scaling used by the solver (powers of 2)
    solution: LMISolution | None
    fixed_modes: dict | None = None   # gain-independent modes of F0 (see fixed_modes)
    output_scaling: np.ndarray | None = None   # outputs' scaling of the fallback problem (None: the model's units)

    def gains_json(self) -> dict:
        out = {"form": self.form, "alpha": self.settings.alpha, "X": self.X.tolist(),
               "L": [l.tolist() for l in self.L], "state_scaling": self.scaling.tolist(),
               "gain_premises": [{"expr": str(p.expr), "range": [p.lower, p.upper]}
                                 for p in self.gain_polytope.premises]}
        if self.output_scaling is not None:
            out["output_scaling"] = self.output_scaling.tolist()
        return out


def _vertex_blocks(form, F0_poly, P_poly, A_poly, C):
    """[(label, constant matrix F, gain index)] whose hull covers F0(p) - L(p) C."""
    if form == "product":
        return [(f"(39) i={i + 1} j={j + 1}", P @ A, j) for i, P in enumerate(P_poly.vertices)
                for j, A in enumerate(A_poly.vertices)]
    return [(f"(39) vertex {v + 1}", F, v) for v, F in enumerate(F0_poly.vertices)]


def _balance(mats, C=None) -> np.ndarray:
    """Diagonal power-of-2 state scaling S (exact similarity in floating point) for the solver.

    With an output matrix: unit columns of the observability matrix [C; C F; ...; C F^(n-1)] at the
    polytope's mean (states scaled so that the chain from the outputs to each state has gain ~1,
    e.g. F_yr in kN-like units for Example 3); without: matrix balancing of sum |F_v|.
    """
    n = mats[0].shape[0]
    if C is not None:
        Fm = sum(mats) / len(mats)
        O = np.vstack([C @ np.linalg.matrix_power(Fm, k) for k in range(n)])
        norms = np.linalg.norm(O, axis=0)
        if np.all(norms > 0):
            return 2.0 ** np.round(-np.log2(norms))
    M = sum(np.abs(m) for m in mats) + np.eye(n)
    _, S = matrix_balance(M, permute=False, separate=True)
    return np.asarray(S[0], float)


def problem_name(dec: rdeg.Decoupling) -> str:
    return f"{dec.lpv.definition.name}: Ichalal and Mammar 2015 LMI (39)"


def _output_scaling(C: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Per output the power of 2 nearest the norm of its row of C S: the outputs in units of the
    scaled states, whatever units the model writes them in (1 for a row of zeros)."""
    norms = np.linalg.norm(C * S[None, :], axis=1)
    return np.where(norms > 0, 2.0 ** np.round(np.log2(np.where(norms > 0, norms, 1.0))), 1.0)


def _committed_scaling(data: dict, n: int, ny: int, name: str) -> tuple:
    """(S, W): the solver's state and output scalings a committed solution was solved in
    (``state_scaling``, ``output_scaling`` of the problem's data, present only for the fallback
    problem of :func:`design`); (None, None): the default problem."""
    if "state_scaling" not in data and "output_scaling" not in data:
        return None, None
    out = []
    for key, size in (("state_scaling", n), ("output_scaling", ny)):
        v = np.asarray(data.get(key, []), dtype=float).ravel()
        if v.size != size or not np.all(np.isfinite(v)) or np.any(v <= 0) or np.any(np.frexp(v)[0] != 0.5):
            raise DesignLockError(f"{name}: committed {key} {data.get(key)!r} is not {size} power(s) of two; "
                                  f"re-solve with `uiogen design NAME --update`")
        out.append(v)
    return tuple(out)


def build_problem(dec: rdeg.Decoupling, settings: AlgebraicSettings, scaling=None, output_scaling=None) -> tuple:
    """LMI (39) in balanced coordinates: (problem, parts for :func:`design`).

    ``scaling``: the diagonal state scaling S (powers of 2) to pose it in, None: the observability
    scaling of :func:`_balance`; ``output_scaling``: W (powers of 2), the gains are solved for the
    outputs y / W, None: the model's units. Others than these defaults (:func:`design`'s fallback)
    are the problem's data, so a design lock replays the problem it was solved in."""
    lpv = dec.lpv
    n, ny = lpv.nx, lpv.ny
    C = np.array(lpv.C.evalf(), dtype=float)
    form = settings.lmi
    if form == "product":
        if dec.r != 1:
            raise ModelDefinitionError(f"lmi = 'product' is LMI (39) for relative degree 1 (F = P A); this model "
                                       f"has relative degree {dec.r}: use lmi = 'direct'")
        P_poly = matrix_polytope(dec.P, dec.boxes, "P")
        A_poly = matrix_polytope(lpv.A, dec.boxes, "A")
        gain_poly, factor_poly, F0_poly = A_poly, P_poly, None
    else:
        F0_poly = matrix_polytope(dec.F0, dec.boxes, "A - Q Mcal")
        gain_poly, factor_poly, P_poly, A_poly = F0_poly, None, None, None
    fixed = fixed_modes(dec)
    if fixed["count"] and fixed["decay_limit"] <= settings.alpha:
        lo, hi = fixed["real_range"]
        head = (f"{lpv.definition.name}: decay rate alpha = {settings.alpha:g} is out of reach for any gain: "
                f"A - Q Mcal has {fixed['count']} mode(s) unobservable from C (invariant zeros of (A, D, C)) "
                f"with real parts in [{lo:.4g}, {hi:.4g}] on the box")
        if fixed["decay_limit"] > 1e-6:        # a mode that decays, however slowly: alpha below its rate
            half = float(f"{0.5 * fixed['decay_limit']:.2g}")
            raise InfeasibleLMIError(f"{head}; choose [design] alpha < {fixed['decay_limit']:.4g} (e.g. {half:g})")
        # alpha > 0 is required, and no gain moves these modes: no alpha works (issue 42)
        along = fixed_mode_states(dec)
        raise InfeasibleLMIError(
            f"{head}: {'it does' if fixed['count'] == 1 else 'they do'} not decay (real part up to {hi:.4g} 1/s), so "
            f"no [design] alpha (> 0) works and no unknown-input observer of these outputs converges; measure "
            f"{' or '.join(along) if along else 'a state along the mode'} too (an output that reads "
            f"{'it' if len(along) <= 1 else 'one of them'}: the mode is then seen; `uiogen analyze` names the "
            f"sensors that remove it)")
    blocks = _vertex_blocks(form, F0_poly, P_poly, A_poly, C)
    default = _balance([F for _, F, _ in blocks], C)
    S = default if scaling is None else np.asarray(scaling, dtype=float)
    W = np.ones(ny) if output_scaling is None else np.asarray(output_scaling, dtype=float)
    Si = 1.0 / S
    Cs = C * S[None, :] / W[:, None]
    # the default problem's data stay as they were (the built-in design locks hold no such key)
    plain = np.array_equal(S, default) and np.all(W == 1.0)
    prob = LMIProblem(problem_name(dec), data={} if plain else {"state_scaling": S.tolist(),
                                                                "output_scaling": W.tolist()})
    X = prob.symmetric("X", n)
    K = [prob.matrix(f"K{j + 1}", n, ny) for j in range(gain_poly.n_vertices)]
    t = prob.scalar("t")
    prob.require_psd("X >= I", X, margin=1.0)   # the re-check sees X itself (slack 1)
    alpha = settings.alpha
    for label, F, j in blocks:
        Fs = Si[:, None] * F * S[None, :]
        XF = X @ Fs - K[j] @ Cs
        prob.require_nsd(label, XF + XF.T + 2 * alpha * X, margin=settings.margin,
                         hint="the decay rate alpha may be too high, or the pair (F0, C) not detectable on the box")
    for j in range(len(K)):
        # only the objective (gain size) uses this block, and it is active at the optimum: the solver gets
        # block >= 0, the numpy re-check block + I >= 0 (the same trick as X >= I)
        norm_blk = bmat([[t * np.eye(ny), K[j].T], [K[j], np.eye(n)]])
        prob.require_psd(f"||K{j + 1}||^2 <= t (objective)", norm_blk + np.eye(n + ny), margin=1.0)
    prob.minimize(t)
    return prob, (form, gain_poly, factor_poly, blocks, S, Si, W, K, fixed)


def _inconclusive(exc: Exception) -> bool:
    """Did the solver fail numerically, short of an outcome at its full tolerances? True for a solve
    stopped short of them (InaccurateSolveError: InsufficientProgress, AlmostSolved, ...), an
    infeasibility found only at reduced tolerances (AlmostPrimalInfeasible), or an answer the
    independent numpy re-check refutes (CertificateError): the fallback scaling of :func:`design`
    is for these. False for an outcome reached at the full tolerances, which stands: an
    infeasibility verdict (PrimalInfeasible) or one proven before any solve, and a solution whose
    entries are too large to use (IllConditionedError, whose message asks for a bound). (Measured:
    retrying the latter too certifies the algebraic UIO's trial on the built-in roll model, which
    `uiogen analyze switched_pi_bank_angle` would then rank above its own switched PI observer.)"""
    if isinstance(exc, InfeasibleLMIError):
        return exc.status is not None and exc.status.startswith("Almost")
    return isinstance(exc, (InaccurateSolveError, CertificateError))


def design(dec: rdeg.Decoupling, settings: AlgebraicSettings, solver) -> AlgebraicDesign:
    """LMI (39) in balanced coordinates, answered by ``solver`` (:mod:`codegen.design.solver`); rounded
    gains re-certified with numpy.

    The solver's coordinates are a conditioning device only (the certificate is checked in them,
    an exact power-of-2 congruence of the model's). The observability scaling of :func:`_balance`
    comes first, with the outputs in the model's units; when the solver fails numerically there
    (:func:`_inconclusive`: stopped short of its tolerances, infeasible only at reduced ones, an
    answer the numpy re-check refutes; an outcome at its full tolerances stands), it is posed once more
    in the matrix balancing S of the vertex matrices (:func:`_balance` without C), with each output
    divided by the power of 2 nearest its row norm of C S (:func:`_output_scaling`). Why: the
    observability matrix adds C F^k of every order k at one weight, so for a stiff error matrix (an
    electric pole at -500/s beside a mechanical chain) its F^(n-1) terms set the scale alone and
    shrink the slow states by ~1e5 (the L = 0.2 mH assist motor: Clarabel reports
    AlmostPrimalInfeasible there, and certifies the same problem in the matrix-balanced
    coordinates, cond X = 22); and both the observability scaling and the outputs' own units move
    with the units the outputs are written in (the motor's current in mA: at 2 mH both fail
    without the output scaling), the fallback's scalings do not (F0 does not, by the choice of
    left inverse, and the output scaling follows C). A problem that solves in the observability
    scaling keeps it, so every design that solved before is unchanged. The fallback scalings are
    committed with the solution (the problem's ``state_scaling``, ``output_scaling``) and
    replayed; when the fallback fails too, the first error is raised, naming both."""
    lpv = dec.lpv
    n, ny = lpv.nx, lpv.ny
    C = np.array(lpv.C.evalf(), dtype=float)
    committed = solver.committed_data(problem_name(dec))
    scaling, outputs = (None, None) if committed is None else _committed_scaling(committed, n, ny, problem_name(dec))
    prob, (form, gain_poly, factor_poly, blocks, S, Si, W, K, fixed) = build_problem(dec, settings, scaling, outputs)
    try:
        sol = solver.solve(prob, tol=settings.tol)
    except (SolverError, CertificateError) as first:
        balanced = _balance([F for _, F, _ in blocks])
        Wb = _output_scaling(C, balanced)
        if (committed is not None or (np.array_equal(balanced, S) and np.array_equal(Wb, W))
                or not _inconclusive(first)):
            # a replay answers the problem it was committed for; no other scaling to try; a verdict the
            # solver reached at its full tolerances stands
            raise
        prob, (form, gain_poly, factor_poly, blocks, S, Si, W, K, fixed) = build_problem(dec, settings, balanced, Wb)
        try:
            sol = solver.solve(prob, tol=settings.tol)
        except (SolverError, CertificateError) as second:
            raise type(first)(f"{first} (posed again in the matrix-balanced state scaling {balanced.tolist()}, "
                              f"outputs scaled by {Wb.tolist()}: {type(second).__name__}: {second})") from None
    Xs = decimal_round(0.5 * (sol["X"] + sol["X"].T))
    # emitted: solved exactly (codegen.representation.canonical), the same on every machine
    Ls = [canonical.solve(Xs, np.atleast_2d(sol[f"K{j + 1}"]).reshape(n, ny)) for j in range(len(K))]
    # back to the model's coordinates: x = S x_s, y = W y_s, L = S L_s W^-1, X = S^-1 X_s S^-1 (powers of 2: exact)
    L = tuple(decimal_round(S[:, None] * l / W[None, :]) for l in Ls)
    Xo = Si[:, None] * Xs * Si[None, :]
    closed = tuple((label, F - L[j] @ C) for label, F, j in blocks)
    return AlgebraicDesign(settings, form, gain_poly, factor_poly, Xo, L, closed, S, sol, fixed,
                           None if np.all(W == 1.0) else W)


def certify(d: AlgebraicDesign) -> dict:
    """Numpy re-check of He(X F_cl) + 2 alpha X < 0 on every block with the emitted (rounded) gains,
    evaluated in the balanced coordinates (congruence with the power-of-2 scaling is exact)."""
    S = d.scaling
    Xs = S[:, None] * d.X * S[None, :]
    named = {"X > 0": Xs}
    for label, F in d.closed_loop:
        Fs = (1.0 / S)[:, None] * F * S[None, :]
        named[label] = -(Xs @ Fs + Fs.T @ Xs + 2 * d.settings.alpha * Xs)
    checks = check_blocks(named)
    worst = worst_block(checks, "min_eig")
    failed = uncertified(checks)
    if failed is not None:
        raise CertificateError(f"LMI (39) block {failed.label!r} fails the numpy re-check on the emitted gains: "
                               f"{failed.failure()}")
    return {"blocks": len(checks), "worst_block": worst.label, "worst_min_eig": worst.min_eig,
            "worst_relative_margin": worst.relative_margin, "alpha": d.settings.alpha}


def dense_check(dec: rdeg.Decoupling, d: AlgebraicDesign, samples: int = 4000, seed: int = 0) -> dict:
    """Independent of the polytope: He(X (F0(p) - L(p) C)) + 2 alpha X at random points of the box, with
    F0 evaluated from its symbolic expression (catches a wrong polytope, not only a wrong solve)."""
    rng = np.random.default_rng(seed)
    syms = dec.symbols
    F0 = _lambdify(syms, dec.F0, np)
    prem = [_lambdify(syms, p.expr, np) for p in d.gain_polytope.premises]
    C = np.array(dec.lpv.C.evalf(), dtype=float)
    S = d.scaling
    Xs = S[:, None] * d.X * S[None, :]
    points = [[rng.uniform(*dec.boxes[s]) if k % 4 else dec.boxes[s][rng.integers(2)] for s in syms]
              for k in range(samples)]
    theta = np.array([[f(*vals) for f in prem] for vals in points], dtype=float).reshape(samples, len(prem))
    # (samples, vertices); a polytope without premises (one vertex) gives the weight 1 for every sample
    mu = np.broadcast_to(sector_weights_product(theta, d.gain_polytope.premises), (samples, len(d.L)))
    # the interpolated gain at every sample at once, vertex by vertex in the order of a plain sum
    # (the same roundings): a polytope of 2^p vertices makes a per-sample Python sum the cost of the check
    gains = np.zeros((samples,) + np.shape(d.L[0]))
    for i, l in enumerate(d.L):
        gains += mu[:, i, None, None] * l
    worst = -np.inf
    for vals, L in zip(points, gains):
        Fs = (1.0 / S)[:, None] * (np.asarray(F0(*vals), float) - L @ C) * S[None, :]
        blk = Xs @ Fs + Fs.T @ Xs + 2 * d.settings.alpha * Xs
        worst = max(worst, float(np.linalg.eigvalsh(0.5 * (blk + blk.T)).max()))
    if worst >= 0:
        raise CertificateError(f"dense check of the error dynamics fails: max eigenvalue {worst:.3e} >= 0")
    return {"samples": samples, "max_eig": worst}


def fixed_modes(dec: rdeg.Decoupling, samples: int = 2000, seed: int = 0, rel_tol: float = 1e-9) -> dict:
    """Modes of the error dynamics that no gain can move: eigenvalues of F0(p) = A - Q Mcal unobservable
    from C (PBH test), at the corners and random points of the box.

    They are the invariant zeros of (A, D, C) that the decoupling leaves in e' = (F0 - L C) e, so they bound
    the decay of *any* unknown-input observer of this model, whatever its gain: with a fixed mode at
    Re = -s the error decays no faster than exp(-s t). A frozen-parameter fact, so a sampled mode with
    Re >= -alpha is a sound refutation of the decay rate alpha (LMI (39) is then infeasible), while
    ``decay_limit`` itself is the sampled bound, not a certificate.

    Returns
    -------
    dict
        ``count`` (fixed modes per point, the largest seen), ``real_range`` [min, max] of their real
        parts, ``decay_limit`` = -max real part (None when there is none), ``samples``.
    """
    F0, C, n, points = _mode_points(dec, samples, seed)
    count, reals = 0, []
    for vals in points:
        F = np.asarray(F0(*vals), dtype=float)
        scale = max(1.0, float(np.abs(F).max()), float(np.abs(C).max()))
        found = 0
        for lam in np.linalg.eigvals(F):
            pbh = np.vstack([F - lam * np.eye(n), C.astype(complex)])
            if np.linalg.svd(pbh, compute_uv=False)[-1] <= rel_tol * scale:
                reals.append(float(lam.real))
                found += 1
        count = max(count, found)
    if not reals:
        return {"count": 0, "real_range": None, "decay_limit": None, "samples": len(points)}
    return {"count": count, "real_range": [min(reals), max(reals)], "decay_limit": -max(reals),
            "samples": len(points)}


def _mode_points(dec: rdeg.Decoupling, samples: int, seed: int) -> tuple:
    """(F0 as a numpy function, C, n, the points): where :func:`fixed_modes` and :func:`fixed_mode_states`
    look for fixed modes, every corner of the box and ``samples`` seeded points inside it."""
    rng = np.random.default_rng(seed)
    syms = dec.symbols
    C = np.array(dec.lpv.C.evalf(), dtype=float)
    corners = [[dec.boxes[s][(k >> i) & 1] for i, s in enumerate(syms)] for k in range(2 ** len(syms))]
    points = corners + [[rng.uniform(*dec.boxes[s]) for s in syms] for _ in range(samples)]
    return _lambdify(syms, dec.F0, np), C, C.shape[1], points


def fixed_mode_states(dec: rdeg.Decoupling, samples: int = 200, seed: int = 0, rel_tol: float = 1e-9) -> list:
    """The states along the least stable fixed mode of :func:`fixed_modes` (its eigenvector's entries
    above a tenth of the largest, in the model's units), at the corner or sample where it is least
    stable: what an added output must read to make that mode observable."""
    F0, C, n, points = _mode_points(dec, samples, seed)
    best, vector = -np.inf, None
    for vals in points:
        F = np.asarray(F0(*vals), dtype=float)
        scale = max(1.0, float(np.abs(F).max()), float(np.abs(C).max()))
        w, V = np.linalg.eig(F)
        for lam, v in zip(w, V.T):
            pbh = np.vstack([F - lam * np.eye(n), C.astype(complex)])
            if np.linalg.svd(pbh, compute_uv=False)[-1] <= rel_tol * scale and lam.real > best:
                best, vector = float(lam.real), np.abs(v)
    if vector is None:
        return []
    states = dec.lpv.definition.states
    return [str(states[i]) for i in range(n) if vector[i] >= 0.1 * vector.max()]


def check_fixed_gain(d: AlgebraicDesign, L: np.ndarray, C: np.ndarray, tol: float = 1e-9) -> dict:
    """Is a given constant gain certified by some common quadratic V on the same polytope?
    Bisection on the decay rate alpha (reported; e.g. the paper's hand gain (52))."""
    n = d.X.shape[0]
    # open-loop vertex matrices: F_cl + L_j C of the design, then the fixed gain
    opens = []
    for (label, F_cl), j in zip(d.closed_loop, _gain_indices(d)):
        opens.append((label, F_cl + d.L[j] @ C - L @ C))
    S = d.scaling

    def feasible(alpha):
        prob = LMIProblem("fixed gain", design=False)   # a report, not part of the design
        X = prob.symmetric("X", n)
        prob.require_psd("X >= I", X, margin=1.0)   # the re-check sees X itself (slack 1)
        for label, F in opens:
            Fs = (1.0 / S)[:, None] * F * S[None, :]
            prob.require_nsd(label, X @ Fs + Fs.T @ X + 2 * alpha * X, margin=1e-7)
        try:
            prob.solve(tol=tol)
            return True
        except (SolverError, CertificateError):
            return False
    if not feasible(0.0):
        return {"certified": False, "alpha": None}
    lo, hi = 0.0, 1.0
    while feasible(hi) and hi < 1e3:
        lo, hi = hi, 2 * hi
    for _ in range(20):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if feasible(mid) else (lo, mid)
    return {"certified": True, "alpha": lo}


def _gain_indices(d: AlgebraicDesign) -> list:
    if d.form == "product":
        nA = d.gain_polytope.n_vertices
        return [j for _ in range(d.factor_polytope.n_vertices) for j in range(nA)]
    return list(range(d.gain_polytope.n_vertices))


# ---- discrete-time certificate -------------------------------------------------------------------------

def _x_norm_factor(X: np.ndarray):
    R = np.linalg.cholesky(X).T          # X = R'R
    return R, np.linalg.inv(R)


def discrete_certificate(d: AlgebraicDesign, h: float, samples: int = 2000, seed: int = 0) -> dict:
    """Gauss-Legendre step on the error dynamics: the B-stability bound and sampled amplification norms.

    Raises
    ------
    DiscretizationError
        if h a f >= 1 (the stage equations are then not provably contractive in the X-norm).
    """
    R, Ri = _x_norm_factor(d.X)
    mats = [F for _, F in d.closed_loop]
    f = max(float(np.linalg.norm(R @ F @ Ri, 2)) for F in mats)
    a = GL_ROW_SUM
    haf = h * a * f
    if haf >= 1:
        raise DiscretizationError(f"cannot certify the Gauss-Legendre step at h = {h:g} s: h a ||F||_X = {haf:.3f} >= 1 "
                                  f"(gains too high for this sample time); lower the sample time or alpha")
    g = haf / (1 - haf)
    c2 = 1 - 2 * h * d.settings.alpha * (1 - g) ** 2
    rng = np.random.default_rng(seed)
    n = d.X.shape[0]
    worst = 0.0
    stack = np.array(mats)
    for k in range(samples):
        # a convex combination summed vertex after vertex (add.reduce along the first axis adds
        # in that order: the same value as a Python sum, at numpy's speed for 2^p vertices)
        pick = [mats[rng.integers(len(mats))] for _ in range(2)] if k % 2 else \
            [np.add.reduce(rng.dirichlet(np.ones(len(mats)))[:, None, None] * stack, axis=0) for _ in range(2)]
        G = amplification(pick, h)
        worst = max(worst, float(np.linalg.norm(R @ G @ Ri, 2)))
    # unpivoted LU of the stage system I - h (A x F) is safe when it is strictly diagonally dominant
    absmax = np.max(np.abs(np.array(mats)), axis=0)
    dominance = 1.0 - h * a * float(absmax.sum(axis=1).max())
    return {"method": "Gauss-Legendre, 2 stages, order 4 (algebraically stable)", "h": h,
            "alpha": d.settings.alpha, "f_X_norm": f, "h_a_f": haf,
            "contraction_bound_per_step": math.sqrt(max(c2, 0.0)),
            "sampled_amplification_X_norm_max": worst, "samples": samples,
            "stage_system_diagonal_dominance": dominance}


def amplification(F_stages, h: float) -> np.ndarray:
    """e+ = G e of the 2-stage Gauss method for e' = F(t) e with F_1, F_2 at the stages."""
    n = F_stages[0].shape[0]
    I = np.eye(n)
    big = np.block([[I - h * GL_A[0][0] * F_stages[0], -h * GL_A[0][1] * F_stages[0]],
                    [-h * GL_A[1][0] * F_stages[1], I - h * GL_A[1][1] * F_stages[1]]])
    K = np.linalg.solve(big, np.vstack([F_stages[0], F_stages[1]]))
    return I + h * (GL_B[0] * K[:n] + GL_B[1] * K[n:])


def aux_design(lpv: LPVModel, boxes: dict, mode: str, alpha: float, solver, tol: float = 1e-9) -> dict | None:
    """The auxiliary system of the known inputs, integrated by the same Gauss method as the observer.

    ``mode = "open_loop"`` is the paper's (20), s' = A s + B u: it is non-expansive (B-stable) if A(rho) has a
    common quadratic V_s with He(X_s A_v) < 0 on its polytope; that LMI is solved and a failure is a
    :class:`~codegen.errors.DiscretizationError` (the integration could not be shown bounded).

    ``mode = "output_injection"``: s' = (A - K_s C) s + B u + K_s y with a constant K_s designed here
    (He(X_s (A_v - K_s C)) <= -2 alpha X_s). Then z = x - s obeys z' = (A - K_s C) z + D d, y_z = C z
    exactly (no known input), and the observer is derived for A - K_s C; x_hat = z_hat + s as in (21).

    Returns None without known inputs, else {"K_s" (n x ny or None), certificate figures}.
    """
    if lpv.nu == 0:
        return None
    if mode not in ("open_loop", "output_injection"):
        raise ModelDefinitionError(f"[design] auxiliary must be 'open_loop' or 'output_injection', got {mode!r}")
    poly = matrix_polytope(lpv.A, boxes, "A")
    C = np.array(lpv.C.evalf(), dtype=float)
    S = _balance(list(poly.vertices), C)
    Si = 1.0 / S
    n, ny = lpv.nx, lpv.ny
    inject = mode == "output_injection"
    prob = LMIProblem(f"{lpv.definition.name}: auxiliary system ({'output injection' if inject else '(20)'})")
    X = prob.symmetric("Xs", n)
    W = prob.matrix("Ws", n, ny) if inject else None
    prob.require_psd("Xs >= I", X, margin=1.0)
    rate = alpha if inject else 0.0
    scaled = [Si[:, None] * A * S[None, :] for A in poly.vertices]
    Cs = C * S[None, :]
    for v, As in enumerate(scaled):
        XA = X @ As - W @ Cs if inject else X @ As
        prob.require_nsd(f"aux vertex {v + 1}", XA + XA.T + 2 * rate * X, margin=1e-4,
                         hint="A(rho) has no common quadratic Lyapunov function over the box: the open-loop "
                              "auxiliary system (20) cannot be shown bounded; use auxiliary = \"output_injection\"")
    if inject:
        t = prob.scalar("t")
        prob.require_psd("||Ws||^2 <= t (objective)",
                         bmat([[t * np.eye(ny), W.T], [W, np.eye(n)]]) + np.eye(n + ny), margin=1.0)
        prob.minimize(t)
    else:
        prob.minimize(trace(X))
    try:
        sol = solver.solve(prob, tol=tol)
    except InfeasibleLMIError as exc:
        if inject:
            raise
        raise DiscretizationError(str(exc)) from None
    Xs = decimal_round(0.5 * (sol["Xs"] + sol["Xs"].T))
    Ks = decimal_round(S[:, None] * canonical.solve(Xs, np.atleast_2d(sol["Ws"]).reshape(n, ny))) \
        if inject else None
    closed = [A - (Ks @ C if inject else 0) for A in poly.vertices]
    blocks = {}
    for v, Acl in enumerate(closed):
        As = Si[:, None] * Acl * S[None, :]
        blocks[f"aux vertex {v + 1}"] = -(Xs @ As + As.T @ Xs + 2 * rate * Xs)
    checks = check_blocks(blocks)
    worst = worst_block(checks, "min_eig")
    failed = uncertified(checks)
    if failed is not None:
        raise CertificateError(f"auxiliary-system certificate fails the numpy re-check ({failed.label}: {failed.failure()})")
    a = max(sum(abs(v) for v in row) for row in GL_A)
    return {"mode": mode, "K_s": None if Ks is None else Ks.tolist(), "decay": rate, "vertices": poly.n_vertices,
            "premises": [str(p.expr) for p in poly.premises], "worst_min_eig": worst.min_eig,
            "state_scaling": S.tolist(), "X_s": (Si[:, None] * Xs * Si[None, :]).tolist(),
            "abs_max_row_sum": float(np.max(np.abs(np.array(closed)), axis=0).sum(axis=1).max()), "gl_a": a}
