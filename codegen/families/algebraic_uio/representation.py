"""Relative degree, decoupling matrices and the rank condition of Ichalal and Mammar 2015.

For an LPV model x' = A(rho) x + B(rho) u + D(rho) d, y = C x (from :func:`codegen.model.instantiate`)
this module differentiates every output along the trajectories, with the scheduling signals
time-varying, and derives, symbolically and with no hand-written matrix:

* eqs. (53)-(58): M_0 = C_i, M_{j+1} = M_j A + dM_j/dt, where dM_j/dt = sum_k sum_m
  dM_j/d rho_k^(m) rho_k^(m+1) brings in the parameter derivatives (rho-dot in M_2, rho-ddot in
  M_3, ...); y_i^(j) = M_j x + (terms in u) as long as M_{j-1} D = 0;
* Definition 2 / Assumption 1: the relative degree r_i of output i w.r.t. the unknown inputs is the
  first j with M_{j-1} D not identically zero, and it must be *uniform*: that row may not vanish
  anywhere on the box Theta x Theta_1 x ... (the parameter box and its derivative bounds).  This is
  proven with sound interval bounds (:mod:`codegen.representation.bounds`), not sampled; a row that vanishes
  somewhere (or cannot be proven not to) is a :class:`RelativeDegreeError`;
* eqs. (84)-(86) (one or several outputs/UIs): the stacked output derivatives
  Y = M(rho) x + Gamma(rho) d, with M the rows M^i_{r_i} and Gamma the rows M^i_{r_i - 1} D;
  rank condition (64) (full column rank of Gamma on the whole box, proven by bounding det Gamma or
  det Gamma'Gamma away from 0; a :class:`~codegen.errors.RankConditionError` names the failure);
* eqs. (24), (60), (85)/(86): Q = D Gamma^dagger and P = I - Q M_{r-1} (the rows M^i_{r_i - 1}
  stacked; for r = 1 this is eq. (24), P = I - Q C), so P D = D - Q Gamma = 0 for *any* left inverse
  (Gamma^dagger Gamma = I). A square Gamma has one, Gamma^-1. With more outputs than UIs there are
  many; the paper's (86) takes Gamma^+ = (Gamma'Gamma)^-1 Gamma', a least-squares inverse in the
  units the outputs happen to be written in. We take the one the state error reaches least
  (:func:`left_inverse`): d_hat = Gamma^dagger (Y - Mcal x_hat) = d + Gamma^dagger Mcal e, and the
  decoupling adds Q Mcal = D Gamma^dagger Mcal to the error matrix, so Gamma^dagger minimizes
  Gamma^dagger R Gamma^dagger' (Loewner order), R = Mcal S^2 Mcal', S the widths of the declared
  [state_bounds] (the Gauss-Markov estimator of d from Y - Mcal x_hat with the state error as its
  noise). It does not depend on the units of the outputs (or of the states, through their boxes);
* the error dynamics matrix of (59)/(65): F0(rho, rho', ...) = A - Q M (for r = 1, F0 = P A as in (23)).

Parameter derivatives are symbols ``<name>_d1, <name>_d2, ...``; their bounds come from the
parameter file: ``rate_min``/``rate_max`` for the first derivative and, for higher ones, the
optional key ``derivative_bounds = [[min2, max2], [min3, max3], ...]`` in the signal's
``[scheduling.NAME]`` table (read here, not by :mod:`codegen.model`).
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import cached_property

import sympy as sp

from ...representation.bounds import BoundsError, range_bound
from ...errors import (ConfigurationError, ModelDefinitionError, RankConditionError, RelativeDegreeError,
                      SchedulingBoundsError)
from ...model import LPVModel


def derivative_symbol(sym: sp.Symbol, order: int) -> sp.Symbol:
    """rho^(order) as a symbol: ``rho`` itself for order 0, else ``rho_d<order>``."""
    return sym if order == 0 else sp.Symbol(f"{sym}_d{order}", real=True)


def derivative_order(sym: sp.Symbol, base: tuple) -> tuple:
    """(index of the base signal, derivative order) of a symbol made by :func:`derivative_symbol`."""
    for k, b in enumerate(base):
        if sym == b:
            return k, 0
        name = str(sym)
        if name.startswith(f"{b}_d") and name[len(str(b)) + 2:].isdigit():
            return k, int(name[len(str(b)) + 2:])
    raise ModelDefinitionError(f"{sym} is not a scheduling signal or one of its derivatives")


def time_derivative(expr, base: tuple, max_order: int = 8):
    """d/dt of a sympy expression/matrix in the scheduling signals and their derivatives."""
    expr = sp.sympify(expr)
    out = expr * 0
    for sym in expr.free_symbols:
        k, m = derivative_order(sym, base)
        if m + 1 > max_order:
            raise ModelDefinitionError(f"derivative of order {m + 1} of {base[k]} exceeds {max_order}")
        out = out + sp.diff(expr, sym) * derivative_symbol(base[k], m + 1)
    return out


def derivative_boxes(lpv: LPVModel) -> dict:
    """{symbol: (lo, hi)} for every scheduling signal and every derivative order the file bounds."""
    with open(lpv.parameters.source, "rb") as fh:
        raw = tomllib.load(fh).get("scheduling", {})
    out = {}
    for sym, box in zip(lpv.scheduling_symbols, lpv.boxes):
        out[sym] = (box.lower, box.upper)
        out[derivative_symbol(sym, 1)] = (box.rate_lower, box.rate_upper)
        higher = raw.get(str(sym), {}).get("derivative_bounds", [])
        if not isinstance(higher, list):
            raise SchedulingBoundsError(f"{lpv.parameters.source}: [scheduling.{sym}] derivative_bounds must be "
                                        f"a list of [min, max] pairs (orders 2, 3, ...)")
        for m, pair in enumerate(higher, start=2):
            if (not isinstance(pair, list) or len(pair) != 2
                    or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair)
                    or not pair[0] <= pair[1]):
                raise SchedulingBoundsError(f"{lpv.parameters.source}: [scheduling.{sym}] derivative_bounds entry "
                                            f"{m - 2} (order {m}) must be [min, max] with min <= max, got {pair!r}")
            out[derivative_symbol(sym, m)] = (float(pair[0]), float(pair[1]))
    return out


def _is_zero(expr) -> bool:
    return sp.simplify(sp.cancel(sp.together(expr))) == 0


def _num(e) -> str:
    """An expression with its exact rational coefficients shown as 12-digit decimals."""
    return str(sp.N(sp.expand(e), 12))


def _simplify_matrix(m: sp.Matrix) -> sp.Matrix:
    return m.applyfunc(lambda e: sp.cancel(sp.together(e)))


def _box_for(expr, boxes: dict, what: str) -> dict:
    missing = sorted(map(str, set(sp.sympify(expr).free_symbols) - set(boxes)))
    if missing:
        raise SchedulingBoundsError(
            f"{what} depends on {', '.join(missing)}, which has no bound: add the derivative bounds to the "
            f"parameter file ([scheduling.NAME] rate_min/rate_max, derivative_bounds = [[min2, max2], ...])")
    return {s: boxes[s] for s in sp.sympify(expr).free_symbols}


def nonvanishing(expr, boxes: dict, what: str, rel_tol: float = 1e-3) -> dict:
    """Prove that ``expr`` keeps one sign on the box (sound interval bound); returns its bounds.

    Raises
    ------
    RelativeDegreeError
        if the expression takes the value 0 somewhere (both signs are attained) or the bound
        cannot exclude 0.
    """
    expr = sp.sympify(expr)
    box = _box_for(expr, boxes, what)
    try:
        rb = range_bound(expr, box, rel_tol=rel_tol)
    except BoundsError as exc:
        raise RelativeDegreeError(f"{what} = {expr}: cannot bound it on the box ({exc})") from None
    if rb.lower > 0 or rb.upper < 0:
        return {"expr": str(expr), "lower": rb.lower, "upper": rb.upper}
    if rb.attained_min <= 0 <= rb.attained_max:
        raise RelativeDegreeError(
            f"{what} = {expr} vanishes on the box (it takes values from {rb.attained_min:.4g} to "
            f"{rb.attained_max:.4g}): the relative degree is not uniform (Assumption 1)")
    raise RelativeDegreeError(f"{what} = {expr}: its sound bound [{rb.lower:.4g}, {rb.upper:.4g}] does not "
                              f"exclude 0, so a uniform relative degree cannot be proven")


@dataclass(frozen=True)
class Decoupling:
    """Everything eqs. (53)-(60) and (84)-(86) derive from one LPV model.

    Attributes
    ----------
    relative_degrees : tuple of int
        r_i per output (Definition 2), uniform on the box.
    M : tuple of tuple of sympy.Matrix
        ``M[i][j]`` is the row M^i_j (j = 0..r_i) of output i: y_i^(j) = M^i_j x + (u terms).
    Gamma, Mcal : sympy.Matrix
        eq. (84): Y = Mcal x + Gamma d (+ u terms); Gamma has rank n_d on the whole box (64).
    Q, P : sympy.Matrix
        Q = D Gamma^dagger (eqs. (24), (60), (85), (86)); P = I - Q M_{r-1}, P D = 0.
    Gamma_inv : sympy.Matrix
        The left inverse Gamma^dagger: Gamma^-1 when square, else :func:`left_inverse` (the UI
        reconstruction of (59), (85), (86)).
    F0 : sympy.Matrix
        A - Q Mcal, the error dynamics before the output injection (eqs. (31), (65), (69)).
    base : tuple of sympy.Symbol
        The scheduling signals; their derivatives are ``derivative_symbol(base[k], m)``.
    derivative_orders : dict
        {base symbol: highest derivative order the observer needs (in F0, Q, Mcal, Gamma)}.
    boxes : dict
        Bounds of every scheduling symbol and derivative used.
    certificates : dict
        The sound bounds proving uniformity and the rank condition.
    """

    lpv: LPVModel
    relative_degrees: tuple
    M: tuple
    Gamma: sp.Matrix
    Mcal: sp.Matrix
    Q: sp.Matrix
    P: sp.Matrix
    Gamma_inv: sp.Matrix
    F0: sp.Matrix
    base: tuple
    derivative_orders: dict
    boxes: dict
    certificates: dict

    @property
    def r(self) -> int:
        return max(self.relative_degrees)

    @cached_property
    def symbols(self) -> tuple:
        """The scheduling signals and every derivative the observer needs, in a fixed order."""
        return tuple(derivative_symbol(b, m) for b in self.base for m in range(self.derivative_orders[b] + 1))

    def to_json(self) -> dict:
        rows = lambda m: [[_num(e) for e in m.row(i)] for i in range(m.shape[0])]
        return {
            "relative_degrees": list(self.relative_degrees),
            "M": [[rows(mj) for mj in mi] for mi in self.M],
            "Gamma": rows(self.Gamma), "Mcal": rows(self.Mcal), "Q": rows(self.Q), "P": rows(self.P),
            "Gamma_inverse": rows(self.Gamma_inv), "F0": rows(self.F0),
            "derivative_orders": {str(k): v for k, v in self.derivative_orders.items()},
            "boxes": {str(k): list(v) for k, v in self.boxes.items() if k in self.symbols},
            "certificates": self.certificates,
        }


def check_structure(lpv: LPVModel) -> None:
    """The model class of Ichalal and Mammar 2015, eq. (1): unknown inputs, a constant C, y = C x.

    Raises
    ------
    ModelDefinitionError, NotAffineError
        naming what the model has that the class does not take.
    """
    C = lpv.C
    if lpv.nd == 0:
        raise ModelDefinitionError(f"model {lpv.definition.name!r} has no unknown inputs")
    lpv.require_no_ui_feedthrough("algebraic UIO", "Ichalal and Mammar 2015, eq. (1): the unknown inputs are "
                                  "recovered from output derivatives of their relative degree")
    if any(e.free_symbols for e in C):
        raise ModelDefinitionError(f"model {lpv.definition.name!r}: this family needs a constant output matrix C "
                                   f"(Ichalal and Mammar 2015, eq. (1)); C depends on {sorted(map(str, set().union(*(e.free_symbols for e in C))))}. "
                                   f"The L-infinity UIO (family linf_uio) takes a scheduling-dependent C")
    if getattr(lpv, "Bw", None) is not None and lpv.Bw.shape[1] > 0:
        raise ModelDefinitionError(f"model {lpv.definition.name!r}: derived inputs are not supported by the algebraic "
                                   f"UIO. The L-infinity UIO (family linf_uio) takes them")
    if lpv.Du is not None and any(e != 0 for e in lpv.Du):
        raise ModelDefinitionError(f"model {lpv.definition.name!r}: outputs with a known-input feedthrough are not "
                                   f"supported by the algebraic UIO (y = C x). The L-infinity UIO (family linf_uio) "
                                   f"takes y = C x + Du u")


def state_scale(lpv: LPVModel, Mcal: sp.Matrix) -> sp.Matrix:
    """diag(S): the width of the declared ``[state_bounds]`` box of every state ``Mcal`` reads (exact
    rationals), 0 for the states it does not read (they do not enter R of :func:`left_inverse`).

    Raises
    ------
    ConfigurationError
        a state that ``Mcal`` reads has no ``[state_bounds]`` entry: without its scale the left
        inverse would depend on the units the state is written in.
    """
    d = lpv.definition
    read = [j for j in range(lpv.nx) if any(not _is_zero(e) for e in Mcal.col(j))]
    missing = [str(d.states[j]) for j in read if str(d.states[j]) not in lpv.parameters.state_bounds]
    if missing:
        raise ConfigurationError(
            f"{lpv.parameters.source}: [state_bounds] missing {', '.join(missing)}: model {d.name!r} has more outputs "
            f"({lpv.ny}) than unknown inputs ({lpv.nd}), so Gamma has many left inverses, and the algebraic UIO takes "
            f"the one the state error reaches least, measured in the state box (docs/families/algebraic_uio.md); "
            f"add {', '.join(f'{m} = [min, max]' for m in missing)} to [state_bounds]",
            source=lpv.parameters.source, section="state_bounds", key=missing[0], allowed="required")
    widths = [0] * lpv.nx
    for j in read:
        lo, hi = lpv.parameters.state_bounds[str(d.states[j])]
        widths[j] = sp.nsimplify(hi, rational=True) - sp.nsimplify(lo, rational=True)
    return sp.Matrix(widths)


def left_inverse(lpv: LPVModel, Gamma: sp.Matrix, Mcal: sp.Matrix, boxes: dict, rel_tol: float = 1e-3) -> tuple:
    """(Gamma^dagger, certificate) for a Gamma with more rows (outputs) than columns (unknown inputs).

    Every left inverse G (G Gamma = I) decouples: P D = D - D G Gamma = 0, and the error dynamics
    e' = (A - D G Mcal - L C) e of (59) hold for any of them, so LMI (39) certifies whichever is
    taken. They differ in how the state error enters: d_hat = G (Y - Mcal x_hat) = d + G Mcal e, and
    the decoupling adds D G Mcal to the error matrix. We take a G that minimizes G R G' in the Loewner
    order among the left inverses, R = Mcal S^2 Mcal' with S = diag of the state-box widths
    (:func:`state_scale`): the reconstruction least sensitive to a state error the size of the box,
    i.e. the Gauss-Markov (best linear unbiased) estimator of d from Y - Mcal x_hat = Gamma d + Mcal e.
    It minimizes ||K G Mcal S||_F for every K at once, so also the decoupling's term
    S^-1 D G Mcal S of the (box-scaled) error matrix. With T = R + Gamma Gamma' (Rao's unified least
    squares),

        G = (Gamma' T~^-1 Gamma)^-1 Gamma' T~^-1,      T~ = T + W N N' W,

    where the columns of N span the output combinations v with v' [Mcal S, Gamma] = 0 and W = diag(T).
    Without such combinations (N empty, T positive definite) this is (Gamma' R^-1 Gamma)^-1 Gamma' R^-1
    when R is invertible, and stays the unique minimizer when an output derivative reads no state
    (R singular). A combination v of N is identically 0 on the model's trajectories (measuring a
    position and its speed: y_1'' - y_2' = 0); the minimizers differ only in what they do with it,
    i.e. with the differentiators' errors in it, never in G Mcal, F0 or d_hat on exact signals: the
    term W N N' W picks the one with G W N = 0 (T~ N = W N N' W N, so T~^-1 W N = N (N' W N)^-1 and
    Gamma' N = 0), which is still a minimizer.

    Output units: a change y -> M y with M diagonal maps Gamma, Mcal, T, W, N to M Gamma, M Mcal,
    M T M, M W M, M^-1 N, hence G to G M^-1: G Mcal, Q Mcal, P and d_hat are the same whatever units
    the outputs are written in (the paper's Gamma^+ of (86) is not: in raw units it takes d from the
    output whose Gamma row is largest in those units). The state units enter only through the box, a
    common factor on S changes nothing, and the weight of Gamma Gamma' does not change G (Rao), so the
    unknown inputs' units do not either, except through W in the choice on N (differentiator errors
    in exactly redundant combinations only).

    Raises
    ------
    ConfigurationError
        a state Mcal reads has no [state_bounds] box (:func:`state_scale`);
    RankConditionError
        det T~ vanishes (or cannot be bounded away from 0) somewhere on the box: the rank of
        [Mcal S, Gamma] drops there, so no one left inverse is least sensitive on the whole box.
    """
    S = state_scale(lpv, Mcal)
    MS = Mcal * sp.diag(*S)
    T = _simplify_matrix(MS * MS.T + Gamma * Gamma.T)
    redundant = [_simplify_matrix(v) for v in sp.Matrix.hstack(MS, Gamma).T.nullspace()]
    Tt = T
    if redundant:
        N = sp.Matrix.hstack(*redundant)
        W = sp.diag(*T.diagonal())
        Tt = _simplify_matrix(T + W * N * N.T * W)
    det = sp.cancel(sp.together(Tt.det(method="berkowitz")))
    what = "det(Mcal S^2 Mcal' + Gamma Gamma'" + (" + W N N' W)" if redundant else ")")
    why = ("the rank of [Mcal S, Gamma] (the outputs' derivatives y_i^(r_i) in the state box and the unknown inputs) "
           "changes on the box, so no one left inverse of Gamma is the least sensitive to the state error there")
    if _is_zero(det):
        raise RankConditionError(f"{what} = 0 for every parameter value: {why}")
    try:
        cert = nonvanishing(det, boxes, what, rel_tol)
    except RelativeDegreeError as exc:
        raise RankConditionError(f"{exc}: {why}") from None
    # Tt^-1 = adj(Tt) / det Tt; the scalar det Tt cancels in G
    Ta = _simplify_matrix(Tt.adjugate(method="berkowitz"))
    G = _simplify_matrix((Gamma.T * Ta * Gamma).inv() * Gamma.T * Ta)
    names = lpv.definition.states
    out = {"rule": "G = (Gamma' T^-1 Gamma)^-1 Gamma' T^-1, T = Mcal S^2 Mcal' + Gamma Gamma' (+ W N N' W): the left "
                   "inverse least sensitive to the state error in the state box",
           "state_scale": {str(names[j]): _num(S[j]) for j in range(len(S)) if S[j] != 0},
           "quantity": what, "expr": _num(det), "bound": [cert["lower"], cert["upper"]]}
    if redundant:
        out["redundant_output_combinations"] = [[_num(e) for e in v] for v in redundant]
    return G, out


def derive(lpv: LPVModel, rel_tol: float = 1e-3) -> Decoupling:
    """Relative degrees, M_{i rho}, Gamma, Q, P and F0 of an LPV model, proven uniform on the box.

    Raises
    ------
    RelativeDegreeError
        an output does not see the unknown inputs within n derivatives, or its relative degree is not
        uniform on the box;
    RankConditionError
        rank condition (64) fails (Gamma not of full column rank somewhere on the box), or redundant
        outputs leave the left inverse of a non-square Gamma not unique (:func:`left_inverse`);
    ConfigurationError
        a non-square Gamma and a state its output derivatives read without a [state_bounds] box;
    ModelDefinitionError, SchedulingBoundsError
        C depends on the scheduling signals, no unknown inputs, a needed derivative is not bounded.
    """
    n, nd, ny = lpv.nx, lpv.nd, lpv.ny
    base = tuple(lpv.scheduling_symbols)
    # exact rational arithmetic: structural cancellations (e.g. in A - Q M) come out as exact zeros
    exact = lambda m: m.applyfunc(lambda e: sp.nsimplify(e, rational=True))
    A, D, C = exact(lpv.A), exact(lpv.D), exact(lpv.C)
    check_structure(lpv)
    boxes = derivative_boxes(lpv)
    certificates = {"uniform_relative_degree": [], "rank_condition_64": None}
    degrees, M_all = [], []
    for i in range(ny):
        rows = [C.row(i)]
        r = None
        for j in range(n):
            MD = _simplify_matrix(rows[j] * D)
            if any(not _is_zero(e) for e in MD):
                r = j + 1
                what = f"M^{i + 1}_{j} D" + (f" (entry of output {lpv.definition.output_names[i]})" if ny > 1 else "")
                target = MD[0] if nd == 1 else sum(e ** 2 for e in MD)
                cert = nonvanishing(target, boxes, what if nd == 1 else f"|{what}|^2", rel_tol)
                certificates["uniform_relative_degree"].append(
                    {"output": lpv.definition.output_names[i], "relative_degree": r, "M_D": [_num(e) for e in MD],
                     "bound": [cert["lower"], cert["upper"]]})
                break
            rows.append(_simplify_matrix(rows[j] * A + time_derivative(rows[j], base)))
        if r is None:
            raise RelativeDegreeError(
                f"output {lpv.definition.output_names[i]!r}: M_j D = 0 identically for j = 0..{n - 1}; the unknown "
                f"inputs never reach it, so it has no relative degree (Definition 2)")
        rows.append(_simplify_matrix(rows[r - 1] * A + time_derivative(rows[r - 1], base)))
        degrees.append(r)
        M_all.append(tuple(rows))
    Gamma = _simplify_matrix(sp.Matrix.vstack(*[M_all[i][degrees[i] - 1] * D for i in range(ny)]))
    Mcal = sp.Matrix.vstack(*[M_all[i][degrees[i]] for i in range(ny)])
    Mprev = sp.Matrix.vstack(*[M_all[i][degrees[i] - 1] for i in range(ny)])
    if ny < nd:
        raise RankConditionError(f"rank condition (64) fails: {ny} outputs cannot reconstruct {nd} unknown inputs "
                                 f"(Gamma is {ny}x{nd})")
    square = ny == nd
    G2 = Gamma if square else _simplify_matrix(Gamma.T * Gamma)
    det = sp.cancel(sp.together(G2.det(method="berkowitz")))
    label = "det Gamma" if square else "det(Gamma' Gamma)"
    if _is_zero(det):
        raise RankConditionError(
            f"rank condition (64) fails: Gamma = {Gamma.tolist()} (eq. (84)) is singular for every parameter value "
            f"({label} = 0 identically), so Q = D Gamma^-1 does not exist; Ichalal and Mammar 2015 Remark 2: replace Y by outputs, "
            f"derivatives and parameter-varying combinations of them for which Gamma has full column rank")
    try:
        cert = nonvanishing(det, boxes, label, rel_tol)
    except RelativeDegreeError as exc:
        raise RankConditionError(f"rank condition (64) fails on the box: {exc}") from None
    certificates["rank_condition_64"] = {"quantity": label, "expr": _num(det), "bound": [cert["lower"], cert["upper"]]}
    if square:
        Gamma_inv = _simplify_matrix(Gamma.inv())      # the only left inverse
    else:
        Gamma_inv, certificates["left_inverse"] = left_inverse(lpv, Gamma, Mcal, boxes, rel_tol)
    Q = _simplify_matrix(D * Gamma_inv)
    P = _simplify_matrix(sp.eye(n) - Q * Mprev)
    F0 = _simplify_matrix(A - Q * Mcal)
    residual = _simplify_matrix(P * D)
    if any(not _is_zero(e) for e in residual):
        raise RankConditionError(f"decoupling (63) fails: P D = {residual.tolist()} != 0")
    used = set().union(*(sp.sympify(m).free_symbols for m in (F0, Q, Mcal, Gamma, Gamma_inv)))
    orders = {b: 0 for b in base}
    for sym in used:
        k, m = derivative_order(sym, base)
        orders[base[k]] = max(orders[base[k]], m)
    missing = [str(derivative_symbol(b, m)) for b in base for m in range(orders[b] + 1)
               if derivative_symbol(b, m) not in boxes]
    if missing:
        raise SchedulingBoundsError(
            f"the observer needs {', '.join(missing)}, which the parameter file does not bound "
            f"([scheduling.NAME] derivative_bounds = [[min2, max2], ...])")
    return Decoupling(lpv, tuple(degrees), tuple(M_all), Gamma, Mcal, Q, P, Gamma_inv, F0, base, orders, boxes,
                      certificates)
