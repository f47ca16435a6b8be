"""Sector-nonlinearity (polytopic LPV / Takagi-Sugeno) representations.

From the symbolic LPV matrices of :mod:`codegen.model` this module finds the
scheduling nonlinearities by itself (every distinct non-constant factor of the
matrix entries, e.g. 1/v_x and 1/v_x**2), and builds

* the plain sector polytope: one premise per nonlinearity, 2**p vertices,
  exact: sum_i eta_i A_i == A(rho);
* the Taylor-reduced form of Nguyen et al. 2019 eqs. (6)-(9): the first nonlinearity is
  normalized to theta in [-1, 1] and the others are replaced by their first-order
  Taylor expansion in theta at theta = 0; 2 vertices for one signal, with the
  approximation error reported by :func:`taylor_error`. An *approximation, error not in
  the LMI*: its certificate holds for the 2-vertex polytope, not for A(rho) (:data:`FORMS`).

Membership functions are products of sector weights; their time-derivative
bounds phi_kl (Nguyen et al. 2019 eq. (14)) come from the scheduling rate bounds, either
soundly over the whole box (``rate_bounds="exact"``) or, as the paper's eq. (11)
does, with the parameter map linearized at the expansion point
(``rate_bounds="at_expansion_point"``).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import sympy as sp

from ..errors import ModelDefinitionError, SchedulingBoundsError, brief
from ..model import LPVModel

APPROXIMATION = "approximation, error not in the LMI"
FORMS = {
    "sector": "exact: sum_i eta_i A_i = A(rho) on the whole scheduling box, which the certificate covers",
    "taylor_reduced": f"{APPROXIMATION}: the first-order Taylor reduction of Nguyen et al. 2019 eqs. (6)-(9) "
                      f"misses A(rho) by its reported Taylor error; the certificate holds for the 2-vertex "
                      f"polytope only",
}
"""What each polytope kind's certificate covers, in the words the summaries, the design lock and the
docs use (``polytope = "sector"`` is the exact form; ``"taylor_reduced"`` reproduces the paper)."""


@dataclass(frozen=True)
class Premise:
    """A normalized premise variable theta(rho) with its range."""

    name: str
    expr: sp.Expr        # theta as a function of the scheduling signal
    lower: float
    upper: float


@dataclass(frozen=True)
class Polytope:
    """Vertex matrices, membership functions and their rate bounds.

    ``A[i]`` etc. are the vertex matrices, ``memberships[i]`` the sympy
    expression of eta_i in the scheduling signal, ``rate_bounds[i] = (phi_i1,
    phi_i2)`` bounds of d eta_i / dt and ``rate_vertices`` the consistent
    corners (summing to zero) used by parameter-dependent Lyapunov designs.
    """

    kind: str
    signals: tuple
    lowers: tuple
    uppers: tuple
    premises: tuple
    nonlinearities: tuple
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    memberships: tuple
    rate_bounds: np.ndarray
    rate_bound_mode: str
    expansion_point: float | None
    Du: np.ndarray = None
    Bw: np.ndarray = None        # derived-input matrices (N, nx, nw); nw = 0 without derived inputs
    Duw: np.ndarray = None
    Dd: np.ndarray = None        # unknown inputs reaching the outputs (N, ny, nd); zeros without

    # the primary (first) scheduling signal, for the single-signal reports
    @property
    def signal(self):
        return self.signals[0]

    @property
    def signal_lower(self) -> float:
        return self.lowers[0]

    @property
    def signal_upper(self) -> float:
        return self.uppers[0]

    @property
    def n_vertices(self) -> int:
        return self.A.shape[0]

    @property
    def rate_vertices(self) -> np.ndarray:
        """Corners of the box of (eta_1', ..., eta_{N-1}') with eta_N' = -sum (sum of eta' is 0)."""
        n = self.n_vertices
        if not np.any(self.rate_bounds):          # no rate information: the single zero derivative
            return np.zeros((1, n))
        if n - 1 > 16:
            raise SchedulingBoundsError(
                f"{n} vertices give 2^{n - 1} membership-rate corners; use rate_bounds = \"none\" with the "
                f"quadratic design, or a reduced polytope")
        corners = []
        for pick in itertools.product((0, 1), repeat=n - 1):
            head = [self.rate_bounds[k, pick[k]] for k in range(n - 1)]
            corner = head + [-sum(head)]
            if corner not in corners:   # degenerate bounds (e.g. rate_bounds="none") repeat corners
                corners.append(corner)
        return np.array(corners, dtype=float)

    @cached_property
    def premise_functions(self) -> tuple:
        """Compiled numpy callables theta_j(*signals), built once per polytope."""
        return tuple(sp.lambdify(self.signals, p.expr, "numpy") for p in self.premises)

    def premise_values(self, rho) -> np.ndarray:
        """Premise variables theta_j(rho), shape (..., p); rho is (...,) for one signal, else (..., n_signals)."""
        rho = np.asarray(rho, dtype=float)
        if len(self.signals) == 1 and (rho.ndim == 0 or rho.shape[-1] != 1):
            rho = rho[..., None]
        cols = [rho[..., k] for k in range(len(self.signals))]
        return np.stack([np.broadcast_to(f(*cols), cols[0].shape) for f in self.premise_functions], axis=-1)

    def eta(self, rho) -> np.ndarray:
        """Membership values at scheduling value(s) ``rho`` (shape (..., N)), from the sector weights."""
        return sector_weights_product(self.premise_values(rho), self.premises)

    def A_of(self, rho) -> np.ndarray:
        return np.einsum("...i,ijk->...jk", self.eta(rho), self.A)

    def to_json(self) -> dict:
        return {
            "kind": self.kind,
            "form": FORMS[self.kind],
            "signals": [str(x) for x in self.signals],
            "signal_ranges": [[lo, hi] for lo, hi in zip(self.lowers, self.uppers)],
            "nonlinearities": [str(g) for g in self.nonlinearities],
            "premises": [{"name": p.name, "expr": str(p.expr), "range": [p.lower, p.upper]}
                         for p in self.premises],
            "memberships": [str(m) for m in self.memberships],
            "rate_bounds": self.rate_bounds.tolist(),
            "rate_bound_mode": self.rate_bound_mode,
            "expansion_point": self.expansion_point,
            "A": self.A.tolist(), "B": self.B.tolist(), "C": self.C.tolist(), "D": self.D.tolist(),
            "Du": self.Du.tolist(),
            **({"Bw": self.Bw.tolist(), "Duw": self.Duw.tolist()}
               if self.Bw is not None and self.Bw.shape[-1] else {}),
            **({"Dd": self.Dd.tolist()} if self.has_ui_feedthrough else {}),
        }

    @property
    def has_ui_feedthrough(self) -> bool:
        return self.Dd is not None and bool(np.any(self.Dd != 0))

    @property
    def D_varies(self) -> bool:
        """Whether the unknown-input matrix D depends on the scheduling (differs between vertices)."""
        return bool(np.ptp(self.D, axis=0).max(initial=0) > 0)


def nonlinear_factors(matrices, symbols) -> tuple:
    """Distinct non-constant factors in ``symbols`` of the matrices' entries, sorted by complexity.

    Each entry is expanded into a sum of terms ``c * g(symbols)``; the ``g`` are returned (for
    Nguyen et al. 2019: 1/v_x and 1/v_x**2; for Nguyen et al. 2021: 1/v_x and r).
    """
    symbols = set(symbols)
    found = {}
    for mat in matrices:
        for entry in mat:
            for term in sp.Add.make_args(sp.expand(entry)):
                if not term.free_symbols & symbols:
                    continue
                _, dep = term.as_independent(*symbols, as_Add=False)
                if dep != 1:
                    found[sp.srepr(dep)] = dep
    return tuple(sorted(found.values(), key=lambda g: (sp.count_ops(g), sp.default_sort_key(g))))


def _matrices(lpv: LPVModel) -> dict:
    """Every matrix of the LPV model by label; derived-input and UI-feedthrough matrices as zeros
    (zero columns without derived inputs) where the model has none."""
    nw = len(lpv.derived_inputs)
    return {"A": lpv.A, "B": lpv.B, "C": lpv.C, "D": lpv.D, "Du": lpv.Du,
            "Bw": lpv.Bw if lpv.Bw is not None else sp.zeros(lpv.nx, nw),
            "Duw": lpv.Duw if lpv.Duw is not None else sp.zeros(lpv.ny, nw),
            "Dd": lpv.Dd if lpv.Dd is not None else sp.zeros(lpv.ny, lpv.nd)}


def scheduling_nonlinearities(lpv: LPVModel) -> tuple:
    """:func:`nonlinear_factors` of A, B, C, D, Du, Bw, Duw, Dd in the scheduling signals."""
    return nonlinear_factors(tuple(_matrices(lpv).values()), lpv.scheduling_symbols)


def affine_decomposition(matrices: dict, symbols, nonlinearities: tuple) -> dict:
    """{label: (M0, [M_k])} with M(rho) = M0 + sum_k g_k(rho) M_k, constant M0 and M_k.

    Each entry is expanded into terms c * g(rho) and every term is assigned to its g (the
    same split that :func:`nonlinear_factors` uses to find them).
    """
    symbols = set(symbols)
    index = {sp.srepr(g): k for k, g in enumerate(nonlinearities)}
    out = {}
    for label, mat in matrices.items():
        base = np.zeros(mat.shape)
        coeffs = [np.zeros(mat.shape) for _ in nonlinearities]
        for (i, j) in itertools.product(range(mat.shape[0]), range(mat.shape[1])):
            for term in sp.Add.make_args(sp.expand(mat[i, j])):
                if not term.free_symbols & symbols:
                    base[i, j] += float(term)
                    continue
                c, dep = term.as_independent(*symbols, as_Add=False)
                k = index.get(sp.srepr(dep))
                if k is None or c.free_symbols:
                    raise ModelDefinitionError(f"{label}[{i},{j}] term {brief(term)} is not affine in the detected "
                                               f"nonlinearities {nonlinearities}")
                coeffs[k][i, j] += float(c)
        out[label] = (base, coeffs)
    return out


def _affine_decomposition(lpv: LPVModel, nonlinearities: tuple):
    return affine_decomposition(_matrices(lpv), lpv.scheduling_symbols, nonlinearities)


def _pole_on_box(den: sp.Expr, sym: sp.Symbol, bounds: dict) -> str | None:
    """Where the denominator ``den`` vanishes on the closed box (text: "v_x = 0"), or None.

    ``bounds`` is {signal: (lo, hi)}. Factors in ``sym`` alone that are polynomials: their real
    roots, exactly; other factors: a zero, a non-finite value or a sign change at the box corners.
    """
    _, factors = sp.factor_list(den)
    for f, _ in factors:
        used = sorted((s for s in f.free_symbols if s in bounds), key=str)
        if sym not in used:
            continue
        lo, hi = bounds[sym]
        if used == [sym] and f.is_polynomial(sym):
            for root in sp.real_roots(sp.Poly(f, sym)):
                if lo <= float(root) <= hi:
                    return f"{sym} = {float(root):g}"
            continue
        fn = sp.lambdify(used, f, "math")
        corners = list(itertools.product(*[bounds[s] for s in used]))
        values = []
        for c in corners:
            try:
                values.append(float(fn(*c)))
            except (ZeroDivisionError, ValueError, TypeError, OverflowError):
                values.append(float("nan"))
        bad = [c for c, v in zip(corners, values) if v == 0 or not np.isfinite(v)]
        if bad:
            return ", ".join(f"{s} = {v:g}" for s, v in zip(used, bad[0]))
        if min(values) < 0 < max(values):
            return f"a point of the box (the denominator factor {f} changes sign)"
    return None


def check_regular_on_box(lpv: LPVModel) -> None:
    """Refuse a scheduling box on which an entry of A, B, C, D, Du, Bw, Duw, Dd is singular (1/v_x, v_x in [0, 35]).

    Raises
    ------
    SchedulingBoundsError
        Naming the parameter file, the signal, its box and the singular entry, before any range
        computation divides by zero.
    """
    syms = set(lpv.scheduling_symbols)
    bounds = {s: (b.lower, b.upper) for s, b in zip(lpv.scheduling_symbols, lpv.boxes)}
    for label, mat in _matrices(lpv).items():
        if mat is None:
            continue
        for i, j in itertools.product(range(mat.shape[0]), range(mat.shape[1])):
            entry = sp.sympify(mat[i, j])
            if not entry.free_symbols & syms:
                continue
            _, den = sp.fraction(sp.together(entry))
            for sym in sorted(den.free_symbols & syms, key=str):
                at = _pole_on_box(den, sym, bounds)
                if at is not None:
                    lo, hi = bounds[sym]
                    text = str(entry) if len(str(entry)) <= 80 else str(entry)[:77] + "..."
                    raise SchedulingBoundsError(
                        f"{lpv.parameters.source}: [scheduling.{sym}] min = {lo!r}, max = {hi!r}: {label}[{i},{j}] = "
                        f"{text} is singular at {at}, which the box [{lo:g}, {hi:g}] of {sym} contains or touches; "
                        f"choose a box of {sym} that excludes it")


def _range_on_interval(expr: sp.Expr, x: sp.Symbol, lo: float, hi: float) -> tuple:
    """Exact min and max of a smooth rational ``expr`` over [lo, hi] (endpoints + real stationary points)."""
    _, den = sp.fraction(sp.together(expr))
    at = _pole_on_box(den, x, {x: (lo, hi)}) if x in den.free_symbols else None
    if at is not None:
        raise SchedulingBoundsError(f"{expr} is singular at {at}, in or at an end of [{lo:g}, {hi:g}]")
    candidates = [lo, hi]
    num, _ = sp.fraction(sp.together(sp.diff(expr, x)))
    poly = sp.Poly(sp.expand(num), x)
    if poly.degree() > 0:
        for root in sp.real_roots(poly):
            val = float(root)
            if lo < val < hi:
                candidates.append(val)
    f = sp.lambdify(x, expr, "math")
    values = [float(f(c)) for c in candidates]
    return min(values), max(values)


def _range_on_box(expr: sp.Expr, lpv: LPVModel) -> tuple:
    """Exact range of a premise over the scheduling box.

    One signal: endpoints and real stationary points. Several: the expression must be a
    monomial (product of powers) in the signals, which are positive on the box, so it is
    monotone in each and its extremes lie at the box corners.
    """
    used = [k for k, sym in enumerate(lpv.scheduling_symbols) if sym in expr.free_symbols]
    if len(used) == 1:
        k = used[0]
        return _range_on_interval(expr, lpv.scheduling_symbols[k], lpv.boxes[k].lower, lpv.boxes[k].upper)
    coeff, factors = expr.as_coeff_Mul()
    for f in sp.Mul.make_args(factors):
        base, exp = f.as_base_exp()
        if base not in lpv.scheduling_symbols:
            return _range_of_product(expr, lpv)
        k = lpv.scheduling_symbols.index(base)
        # monotone in each signal on the box: negative powers need a box away from 0,
        # nonnegative powers a box that does not change sign
        if lpv.boxes[k].lower < 0 or (exp < 0 and lpv.boxes[k].lower <= 0):
            return _range_of_product(expr, lpv)
    fn = sp.lambdify([lpv.scheduling_symbols[k] for k in used], expr, "math")
    values = [float(fn(*c)) for c in itertools.product(*[(lpv.boxes[k].lower, lpv.boxes[k].upper) for k in used])]
    return min(values), max(values)


def _range_of_product(expr: sp.Expr, lpv: LPVModel) -> tuple:
    """Range over the box of a premise of several signals that is not a monotone monomial.

    A product of factors each of one signal (``a_x / v_x`` with a_x crossing 0, ``1/(J(i_g) v_x)``):
    each factor's exact range on its interval (:func:`_range_on_interval`), multiplied as intervals,
    which is the exact range (the factors vary independently, and a product of intervals takes its
    extremes at their ends). Any other premise: a sound enclosure (interval arithmetic with bisection,
    :func:`codegen.representation.bounds.range_bound`, to 1e-9 relative): the polytope it spans holds
    every value the premise takes, wider than the exact one by that tolerance at most.

    Raises
    ------
    SchedulingBoundsError
        a premise that cannot be enclosed, naming the derived scheduling signal that replaces it.
    """
    from .bounds import BoundsError, range_bound
    box = {s: (b.lower, b.upper) for s, b in zip(lpv.scheduling_symbols, lpv.boxes)}
    coeff, rest = sp.factor(expr).as_coeff_Mul()
    groups = {}
    for f in sp.Mul.make_args(rest):
        used = f.free_symbols & set(box)
        if len(used) != 1:
            groups = None
            break
        (sym,) = used
        groups[sym] = groups.get(sym, sp.S.One) * f
    if groups:
        lo, hi = float(coeff), float(coeff)
        for sym, f in groups.items():
            a, b = _range_on_interval(f, sym, *box[sym])
            ends = (lo * a, lo * b, hi * a, hi * b)
            lo, hi = min(ends), max(ends)
        return lo, hi
    try:
        rb = range_bound(expr, {s: box[s] for s in expr.free_symbols if s in box}, rel_tol=1e-9)
    except BoundsError as exc:
        used = sorted(map(str, expr.free_symbols & set(box)))
        raise SchedulingBoundsError(
            f"{lpv.parameters.source}: premise {expr} of the scheduling signals {', '.join(used)} cannot be bounded "
            f"on their box ({exc}); declare it a scheduling signal of its own, derived from them in the step: "
            f"SchedulingSignal(z, derived=<the expression>) with its range in [scheduling.z], and write z where the "
            f"model has the expression") from None
    return rb.lower, rb.upper


def _single_signal(lpv: LPVModel):
    if len(lpv.scheduling_symbols) != 1:
        raise SchedulingBoundsError(
            f"model {lpv.definition.name!r}: polytopes are built for exactly one scheduling "
            f"signal, got {len(lpv.scheduling_symbols)}")
    return lpv.scheduling_symbols[0], lpv.boxes[0]


def memberships(premises: tuple) -> tuple:
    """Products of sector weights; vertex i uses bit j of i: 0 = lower, 1 = upper end of premise j.

    Left as the product of the weights: sympy's simplifier changed only how they print (they are
    recorded in the design artifacts and differentiated for rate bounds), and its cost grows with the
    2^p products of p factors each (a model with four scheduling signals spent minutes here)."""
    p = len(premises)
    etas = []
    for idx in range(2 ** p):
        eta = sp.Integer(1)
        for j, prem in enumerate(premises):
            bit = (idx >> (p - 1 - j)) & 1
            width = prem.upper - prem.lower
            w = (prem.expr - prem.lower) / width if bit else (prem.upper - prem.expr) / width
            eta = eta * w
        etas.append(eta)
    return tuple(etas)


def sector_weights_product(theta, premises, xp=np):
    """eta_i = prod_j w_j^{bit_j(i)}(theta_j); works on numpy arrays and CasADi SX (``xp``)."""
    p = len(premises)
    weights = []
    for j, prem in enumerate(premises):
        width = prem.upper - prem.lower
        t = theta[..., j] if xp is np else theta[j]
        weights.append(((prem.upper - t) / width, (t - prem.lower) / width))
    if xp is np and p > 0:
        # every vertex at once, premise after premise: each vertex's product is formed in the
        # same order as the loop below (the same bits), without 2^p x p Python multiplications
        vertex = np.arange(2 ** p)
        eta = np.ones(np.shape(theta)[:-1] + (2 ** p,))
        for j, (lower_w, upper_w) in enumerate(weights):
            bit = (vertex >> (p - 1 - j)) & 1
            eta = eta * np.where(bit == 1, np.asarray(upper_w)[..., None], np.asarray(lower_w)[..., None])
        return eta
    etas = []
    for idx in range(2 ** p):
        eta = 1.0
        for j in range(p):
            eta = eta * weights[j][(idx >> (p - 1 - j)) & 1]
        etas.append(eta)
    return np.stack(etas, axis=-1) if xp is np else etas


def vertex_matrices(decomp, premise_values_at_vertex):
    mats = {}
    for label, (base, coeffs) in decomp.items():
        mats[label] = np.array([base + sum(c * z for c, z in zip(coeffs, zvals))
                                for zvals in premise_values_at_vertex])
    return mats


def _rate_bounds(memberships, signal, box, mode, expansion_point, source=""):
    if mode == "none":
        # no rate information: only valid for designs whose Lyapunov matrix does not depend
        # on the memberships (the quadratic variant); the PDLF design refuses it
        return np.zeros((len(memberships), 2))
    if not box.rate_bounded:
        raise SchedulingBoundsError(
            f"{source}: [scheduling.{box.name}] gives no rate_min, rate_max, and rate_bounds = {mode!r} bounds the "
            f"membership rates by them: declare them, or, for a signal that jumps (a gear ratio), set rate_bounds = "
            f"\"none\" and lyapunov = \"quadratic\" in the observer file (one Lyapunov matrix for every rate)")
    bounds = []
    for eta in memberships:
        # simplified first: the stationary points come from the numerator of the derivative, whose
        # float coefficients (and so the bounds' last bits, and the design solved on them) depend on
        # the form; one signal only, so the 2^p products are few
        deta = sp.diff(sp.simplify(eta), signal)
        if mode == "exact":
            lo, hi = _range_on_interval(deta, signal, box.lower, box.upper)
        elif mode == "at_expansion_point":
            if expansion_point is None:
                raise ModelDefinitionError("rate_bounds='at_expansion_point' needs a Taylor-reduced polytope")
            lo = hi = float(deta.subs(signal, expansion_point))
        else:
            raise ModelDefinitionError(f"unknown rate bound mode {mode!r}")
        prods = [lo * box.rate_lower, lo * box.rate_upper, hi * box.rate_lower, hi * box.rate_upper]
        bounds.append((min(prods), max(prods)))
    return np.array(bounds, dtype=float)


def sector_polytope(lpv: LPVModel, rate_bounds: str = "exact") -> Polytope:
    """Plain sector-nonlinearity polytope: one premise per nonlinearity, 2**p exact vertices."""
    if len(lpv.scheduling_symbols) > 1 and rate_bounds != "none":
        raise SchedulingBoundsError(
            f"model {lpv.definition.name!r}: membership rate bounds are derived for one scheduling signal; "
            f"with {len(lpv.scheduling_symbols)} signals use rate_bounds = \"none\" and the quadratic design")
    check_regular_on_box(lpv)
    nonlin = scheduling_nonlinearities(lpv)
    if not nonlin:
        raise ModelDefinitionError(f"model {lpv.definition.name!r} does not depend on its scheduling signal")
    premises = []
    for k, g in enumerate(nonlin):
        lo, hi = _range_on_box(g, lpv)
        if not hi > lo:
            raise SchedulingBoundsError(f"premise {g} is constant on the scheduling box")
        premises.append(Premise(f"z{k}", g, lo, hi))
    premises = tuple(premises)
    decomp = _affine_decomposition(lpv, nonlin)
    p = len(premises)
    corners = [[(pr.upper if (idx >> (p - 1 - j)) & 1 else pr.lower) for j, pr in enumerate(premises)]
               for idx in range(2 ** p)]
    mats = vertex_matrices(decomp, corners)
    etas = memberships(premises)
    rates = _rate_bounds(etas, lpv.scheduling_symbols[0], lpv.boxes[0], rate_bounds, None, lpv.parameters.source)
    return Polytope("sector", tuple(lpv.scheduling_symbols), tuple(b.lower for b in lpv.boxes),
                    tuple(b.upper for b in lpv.boxes), premises, nonlin, mats["A"], mats["B"],
                    mats["C"], mats["D"], etas, rates, rate_bounds, None, mats["Du"], mats["Bw"], mats["Duw"],
                    mats["Dd"])


def taylor_reduced_polytope(lpv: LPVModel, rate_bounds: str = "exact") -> Polytope:
    """Reduced polytope of Nguyen et al. 2019 eqs. (6)-(9).

    The simplest nonlinearity g_0 (1/v_x) is written g_0 = 1/v0 + theta/v1 with
    theta in [-1, 1]; every other g_k is replaced by its first-order Taylor
    expansion in theta at theta = 0 (rho = v0). For g_0 = 1/v_x this gives
    v0 = 2 vmin vmax/(vmin+vmax), v1 = -2 vmin vmax/(vmax-vmin) and
    1/v_x**2 ~ (1 + 2 v0/v1 theta)/v0**2, as in the paper.
    """
    signal, box = _single_signal(lpv)
    check_regular_on_box(lpv)
    nonlin = scheduling_nonlinearities(lpv)
    if not nonlin:
        raise ModelDefinitionError(f"model {lpv.definition.name!r} does not depend on its scheduling signal")
    g0 = nonlin[0]
    g_lo, g_hi = _range_on_interval(g0, signal, box.lower, box.upper)
    center, half = (g_hi + g_lo) / 2, (g_hi - g_lo) / 2
    # Orient theta to increase with the signal (the paper's v1 < 0 for g0 = 1/v_x), so vertex 1
    # is the low end of the signal, as in eq. (9): A_1 = A(theta_min) = A(v_min).
    g_at_lo = float(g0.subs(signal, box.lower))
    if g_at_lo > center:
        half = -half
    theta_expr = (g0 - center) / half
    theta = sp.Symbol("theta")
    # rho as a function of theta (g0 must be invertible on the box)
    sols = [s for s in sp.solve(sp.Eq(g0, center + half * theta), signal)]
    rho_of_theta = None
    for s in sols:
        val = complex(s.subs(theta, 0))
        if abs(val.imag) < 1e-12 and box.lower <= val.real <= box.upper:
            rho_of_theta = s
    if rho_of_theta is None:
        raise ModelDefinitionError(f"nonlinearity {g0} cannot be inverted on [{box.lower}, {box.upper}]")
    expansion_point = float(rho_of_theta.subs(theta, 0))
    decomp = _affine_decomposition(lpv, nonlin)
    # premise values at theta = -1, +1 for every nonlinearity (first-order Taylor in theta)
    lines = []
    for g in nonlin:
        g_theta = sp.simplify(g.subs(signal, rho_of_theta))
        value0 = float(g_theta.subs(theta, 0))
        slope0 = float(sp.diff(g_theta, theta).subs(theta, 0))
        lines.append((value0, slope0))
    corners = [[v0 + s0 * t for v0, s0 in lines] for t in (-1.0, 1.0)]
    mats = vertex_matrices(decomp, corners)
    premise = Premise("theta", sp.simplify(theta_expr), -1.0, 1.0)
    etas = memberships((premise,))
    return Polytope("taylor_reduced", (signal,), (box.lower,), (box.upper,), (premise,), nonlin, mats["A"],
                    mats["B"], mats["C"], mats["D"], etas,
                    _rate_bounds(etas, signal, box, rate_bounds, expansion_point, lpv.parameters.source), rate_bounds,
                    expansion_point, mats["Du"], mats["Bw"], mats["Duw"], mats["Dd"])


def exact_matrix_function(lpv: LPVModel, label: str = "A"):
    """Numeric callable rho -> exact matrix (for error reports and nonlinear simulation)."""
    mat = {"A": lpv.A, "B": lpv.B, "C": lpv.C, "D": lpv.D}[label]
    f = sp.lambdify(lpv.scheduling_symbols, mat, "numpy")
    return lambda rho: np.array(f(rho), dtype=float)


def taylor_error(lpv: LPVModel, poly: Polytope, n_grid: int = 2001) -> dict:
    """Largest entrywise error between the polytope's A and the exact A(rho) on a dense grid."""
    exact = exact_matrix_function(lpv, "A")
    grid = np.linspace(poly.signal_lower, poly.signal_upper, n_grid)
    worst, where, entry = 0.0, float(grid[0]), (0, 0)
    worst_rel = 0.0
    for rho in grid:
        err = np.abs(poly.A_of(rho) - exact(rho))
        k = np.unravel_index(np.argmax(err), err.shape)
        if err[k] > worst:
            worst, where, entry = float(err[k]), float(rho), (int(k[0]), int(k[1]))
            worst_rel = float(err[k] / max(abs(exact(rho)[k]), 1e-300))
    return {"max_abs_error": worst, "at": where, "entry": list(entry), "relative_error_there": worst_rel}
