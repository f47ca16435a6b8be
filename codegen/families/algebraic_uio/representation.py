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
* eqs. (24), (60), (85)/(86): Q = D Gamma^-1 (square) or D Gamma^+ with Gamma^+ = (Gamma'Gamma)^-1
  Gamma' (more outputs than UIs), and P = I - Q M_{r-1} (the rows M^i_{r_i - 1} stacked; for r = 1
  this is eq. (24), P = I - Q C), so P D = D - Q Gamma = 0;
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
from ...errors import ModelDefinitionError, RankConditionError, RelativeDegreeError, SchedulingBoundsError
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
        Q = D Gamma^-1 / D Gamma^+ (eqs. (24), (60), (85), (86)); P = I - Q M_{r-1}, P D = 0.
    Gamma_inv : sympy.Matrix
        Gamma^-1 or Gamma^+ (the UI reconstruction of (59), (85), (86)).
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


def derive(lpv: LPVModel, rel_tol: float = 1e-3) -> Decoupling:
    """Relative degrees, M_{i rho}, Gamma, Q, P and F0 of an LPV model, proven uniform on the box.

    Raises
    ------
    RelativeDegreeError
        an output does not see the unknown inputs within n derivatives, or its relative degree is not
        uniform on the box;
    RankConditionError
        rank condition (64) fails (Gamma not of full column rank somewhere on the box);
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
    Gamma_inv = _simplify_matrix(Gamma.inv() if square else G2.inv() * Gamma.T)
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
