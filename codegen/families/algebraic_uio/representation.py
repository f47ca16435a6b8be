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
  Gamma^dagger R Gamma^dagger' (Loewner order) at the centre of the box, R = Mcal S^2 Mcal', S the
  widths of the declared [state_bounds] (a state's unit where none is declared; the Gauss-Markov
  estimator of d from Y - Mcal x_hat with the state error as its noise). It does not depend on
  the units of the outputs, to the 12 digits of its weight (nor on those of the states that have a
  box);
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

import numpy as np
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
        if box.rate_bounded:            # else the signal may jump: a derivative that needs its rate has no bound
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
    lpv.require_no_derived_inputs("algebraic UIO", "Ichalal and Mammar 2015, eq. (1): x' = A x + B u + D d")
    if lpv.Du is not None and any(e != 0 for e in lpv.Du):
        raise ModelDefinitionError(f"model {lpv.definition.name!r}: outputs with a known-input feedthrough are not "
                                   f"supported by the algebraic UIO (y = C x). The L-infinity UIO (family linf_uio) "
                                   f"takes y = C x + Du u")


def state_scale(lpv: LPVModel, Mcal: sp.Matrix) -> tuple:
    """(S, unboxed): per state the width of its declared ``[state_bounds]`` box (exact rationals), or
    1, its unit in the model, for a state without one, whose names ``unboxed`` lists (states ``Mcal``
    does not read only). The box is how large a state error can be in the user's own terms; without
    it the model's unit is all there is to measure it in. The outputs' units never enter (the choice
    of :func:`left_inverse` is unit-free in them either way); the states' enter only where no box
    is declared, which the design's certificate reports."""
    d = lpv.definition
    read = [j for j in range(lpv.nx) if any(not _is_zero(e) for e in Mcal.col(j))]
    widths, unboxed = [sp.Integer(1)] * lpv.nx, []
    for j in read:
        box = lpv.parameters.state_bounds.get(str(d.states[j]))
        if box is None:
            unboxed.append(str(d.states[j]))
        else:
            widths[j] = sp.nsimplify(box[1], rational=True) - sp.nsimplify(box[0], rational=True)
    return sp.Matrix(widths), tuple(unboxed)


REDUNDANT_TOL = 1e-6
"""A combination of the output derivatives whose share of [Mcal S, Gamma] (rows scaled to unit norm)
is below this singular value is taken as redundant (:func:`left_inverse`): the model's floats and
the auxiliary gain K_s leave exact redundancies (a position and its speed) at ~1e-13."""


def left_inverse(lpv: LPVModel, Gamma: sp.Matrix, Mcal: sp.Matrix, boxes: dict) -> tuple:
    """(Gamma^dagger, record) for a Gamma with more rows (outputs) than columns (unknown inputs).

    Every left inverse G (G Gamma = I) decouples: P D = D - D G Gamma = 0, and the error dynamics
    e' = (A - D G Mcal - L C) e of (59) hold for any of them, so LMI (39) certifies whichever is
    taken. They differ in how the state error enters: d_hat = G (Y - Mcal x_hat) = d + G Mcal e, and
    the decoupling adds D G Mcal to the error matrix. We take the weighted left inverse

        G = (Gamma' O Gamma)^-1 Gamma' O,      O = V^-1,   V = Mc S^2 Mc' + Gc Gc' (+ redundant part),

    Mc, Gc = Mcal, Gamma at the centre of the box (scheduling signals and their derivatives), S the
    widths of the state box (:func:`state_scale`). At the centre G minimizes G Mc S^2 Mc' G' in the
    Loewner order among the left inverses: the reconstruction least sensitive to a state error the
    size of the box (the Gauss-Markov estimator of d from Y - Mcal x_hat = Gamma d + Mcal e); it
    minimizes ||K G Mcal S||_F for every K at once, so also the decoupling's term S^-1 D G Mcal S of
    the box-scaled error matrix. Gc Gc' does not change that minimizer (Rao's unified least squares)
    and keeps V invertible when an output derivative reads no state. The weight is frozen at the
    centre so that G depends on what Gamma depends on, as the paper's Gamma^+ does: the pointwise
    minimizer would bring Mcal's parameter derivatives into G, hence new premises into the polytope
    of F0. An LTI model (the assist motor) has the minimizer exactly everywhere.

    With B = [Mc S, Gc] = R_B B_n (R_B the row norms, rows of B_n of unit norm), V = R_B (B_n B_n' +
    U U') R_B, where U spans the combinations u with u' B_n ~ 0 (singular values below
    :data:`REDUNDANT_TOL`). Such a combination is identically 0 on the model's trajectories (a
    position and its speed both measured: y_1'' - y_2' = 0); the minimizers differ only in what they
    do with it, i.e. with the differentiators' errors in it, never in d_hat on exact signals; U U'
    picks the one with G R_B U = 0 (and keeps V well-conditioned). O is computed in floating point
    and rounded to 12 significant digits: any positive definite weight gives an exact left inverse
    (checked in exact arithmetic, with O positive definite), and the exact weight would carry the
    model's floats as rationals of hundreds of digits into G and F0 = A - D G Mcal.

    Output units: a change y -> M y with M diagonal maps Gamma, Mcal, R_B to M Gamma, M Mcal, M R_B
    and leaves B_n, U alone, so O goes to M^-1 O M^-1 and G to G M^-1 (to rounding): G Mcal, Q Mcal,
    P and d_hat are the same whatever units the outputs are written in (the paper's Gamma^+ of (86)
    is not: in raw units it takes d from the output whose Gamma row is largest in those units). The
    states' units enter only where no box is declared, a common factor on S changes nothing, and the
    weight of Gc Gc' does not change G at the centre (Rao), so the unknown inputs' units do not either
    (but for the redundant part).

    Raises
    ------
    SchedulingBoundsError
        a scheduling symbol of Mcal or Gamma has no bound (no centre);
    RankConditionError
        the rounded weight is not positive definite (V too ill-conditioned for 12 digits).
    """
    S, unboxed = state_scale(lpv, Mcal)
    box = _box_for(sp.Matrix.hstack(Mcal, Gamma), boxes, "the weight of the left inverse of Gamma (Mcal, Gamma)")
    centre = {s: 0.5 * (lo + hi) for s, (lo, hi) in box.items()}
    B = np.array(sp.Matrix.hstack(Mcal * sp.diag(*S), Gamma).subs(centre).evalf(30), dtype=float)
    rows = np.linalg.norm(B, axis=1)            # > 0: Gamma's rows are nonzero on the box (relative degree)
    Bn = B / rows[:, None]
    P_, sv, _ = np.linalg.svd(Bn)
    sv = np.concatenate([sv, np.zeros(Bn.shape[0] - sv.size)])
    U = P_[:, sv < REDUNDANT_TOL * sv[0]]
    Z = Bn @ Bn.T + U @ U.T
    O = np.linalg.inv(Z) / rows[:, None] / rows[None, :]
    O = 0.5 * (O + O.T)
    Om = sp.Matrix(O.shape[0], O.shape[1], lambda i, j: sp.Rational(f"{O[i, j]:.11e}"))
    if not all(Om[:k, :k].det() > 0 for k in range(1, Om.shape[0] + 1)):
        raise RankConditionError(f"the weight of the left inverse of Gamma, {O.tolist()}, is not positive definite once "
                                 f"rounded to 12 digits: the rows of [Mcal S, Gamma] at the centre of the box (singular "
                                 f"values {sv.tolist()} once scaled to unit norm) are too close to dependent")
    G = _simplify_matrix((Gamma.T * Om * Gamma).inv() * Gamma.T * Om)
    names = lpv.definition.states
    out = {"rule": "G = (Gamma' O Gamma)^-1 Gamma' O, O = (Mcal S^2 Mcal' + Gamma Gamma' (+ redundant part))^-1 at "
                   "the centre of the box: the left inverse least sensitive to the state error in the state box",
           "state_scale": {str(names[j]): _num(S[j]) for j in range(len(S)) if any(e != 0 for e in Mcal.col(j))},
           "state_scale_source": ("the [state_bounds] widths" if not unboxed else
                                  f"the [state_bounds] widths; the model's unit for {', '.join(unboxed)} (no box)"),
           "weight_at": {str(k): v for k, v in sorted(centre.items(), key=lambda kv: str(kv[0]))},
           "weight": [[_num(e) for e in Om.row(i)] for i in range(Om.shape[0])],
           "singular_values": sv.tolist()}
    if U.shape[1]:
        out["redundant_output_combinations"] = (U / rows[:, None]).T.tolist()
    return G, out


def _derivative_orders(mats, base: tuple, boxes: dict) -> dict:
    """{base symbol: highest derivative order in ``mats``}, every one of them bounded.

    Raises
    ------
    SchedulingBoundsError
        naming the derivatives the parameter file does not bound.
    """
    used = set().union(*(sp.sympify(m).free_symbols for m in mats))
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
    return orders


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
    if square:
        Gamma_inv = _simplify_matrix(Gamma.inv())      # the only left inverse
    else:
        _derivative_orders((Mcal, Gamma), base, boxes)  # the weight is taken at the box's centre: bounded first
        Gamma_inv, certificates["left_inverse"] = left_inverse(lpv, Gamma, Mcal, boxes)
    Q = _simplify_matrix(D * Gamma_inv)
    P = _simplify_matrix(sp.eye(n) - Q * Mprev)
    F0 = _simplify_matrix(A - Q * Mcal)
    residual = _simplify_matrix(P * D)
    if any(not _is_zero(e) for e in residual):
        raise RankConditionError(f"decoupling (63) fails: P D = {residual.tolist()} != 0")
    orders = _derivative_orders((F0, Q, Mcal, Gamma, Gamma_inv), base, boxes)
    return Decoupling(lpv, tuple(degrees), tuple(M_all), Gamma, Mcal, Q, P, Gamma_inv, F0, base, orders, boxes,
                      certificates)
