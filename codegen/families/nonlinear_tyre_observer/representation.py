"""The numbers of a nonlinear-tyre model: force-affine dynamics and sound axle-slope bounds on a slip set.

Model (``model_defs/single_track_nonlinear_tyre.py``): x = (v_y, r), known inputs delta (the
steering angle, first) and any further measured signals the tyre laws read (a_x: combined slip),
measured v_x, outputs a_y and r; the dynamics and a_y are *affine in the body-frame axle forces*
Phi_k with constant coefficients, and Phi_k depends on the unmeasured v_y only through the
axle's slip t_k (``AXLES``).

The slope bound of an axle (theta_k = v_x dPhi_k/dv_y) on the set |t_k| <= rho t_sl,k is the
product of two factors bounded soundly on their own (interval arithmetic, :mod:`codegen.representation.bounds`):

* the law's slope dF/dt written in the *normalized* slip tau = t / t_sl (so the set is the box
  |tau| <= rho whatever the capacity; the Fiala slope is C (1 - |tau|)^2), over tau and the
  declared ranges of the axle's stiffness and friction;
* the kinematic factor v_x dt/dv_y (times the projection to the body frame), a function of (t,
  delta) through the inverse map v_y(t), over |t| <= rho max t_sl (the largest sliding slip the
  capacity reaches over the measured inputs' box and the parameter ranges) and delta's box.

Their product encloses theta_k (sound, a little wider). The attained extremes are the jointly
evaluated product on a grid of the set (inner bounds, reported beside the sound ones).
"""
from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np
import sympy as sp

from ...representation.bounds import Interval, range_bound
from ...errors import CertificateError, ModelDefinitionError, SchedulingBoundsError
from ...model import parameter_substitution


def numeric(expr, values: dict):
    """``expr`` with the numbers of ``values`` put in, unevaluated: sympy's own simplification of the
    Min/Max of the combined-slip capacity takes seconds per expression and changes nothing numerically."""
    with sp.evaluate(False):
        return sp.sympify(expr).xreplace(values)


@dataclass(frozen=True)
class AxleBounds:
    """Sound bounds of one axle's theta = v_x dPhi/dv_y on |t| <= rho t_sl, and the values attained."""

    theta: tuple          # (lo, hi), sound
    attained: tuple       # (min, max) of theta evaluated on a grid of the set
    slope: tuple          # (lo, hi) of the law's slope dF/dt on |tau| <= rho
    kinematic: tuple      # (lo, hi) of the kinematic factor on |t| <= rho max t_sl
    slip_max: float       # rho max t_sl over the inputs' box and the parameter ranges


@dataclass(frozen=True)
class TyreRepresentation:
    """The model's numbers: force-affine dynamics, axle Jacobian bounds on the two sets, the boxes."""

    f: tuple                  # sympy x_dot (w = 0), in ``symbols``
    a_y: sp.Expr              # sympy a_y (w = 0)
    G_f: np.ndarray           # (2, 2) d f / d Phi
    G_a: np.ndarray           # (2,)  d a_y / d Phi
    decay_set: tuple          # AxleBounds per axle on |t| <= sliding_fraction t_sl
    gain_set: tuple           # AxleBounds per axle on |t| <= gain_sliding_fraction t_sl
    slips: tuple              # sympy t_k in ``symbols``
    sliding: tuple            # sympy t_sl,k in ``symbols`` (nominal parameters; a_x where the capacity reads it)
    rho: float                # sliding_fraction
    v_x_box: tuple
    input_boxes: tuple        # ((name, (lo, hi)), ...) of every known input, delta first
    symbols: tuple            # (v_y, r, known inputs..., v_x)
    lever: tuple              # (l_f, -l_r): slip t_k depends on v_y + lever_k r (yaw-rate noise enters there)

    @property
    def theta(self) -> tuple:
        return tuple(b.theta for b in self.decay_set)

    @property
    def delta_box(self) -> tuple:
        return self.input_boxes[0][1]

    @functools.cached_property
    def numpy_functions(self) -> tuple:
        """(f, a_y, slip limits rho t_sl, slips) as plain-Python callables of ``symbols``, for the
        numpy reference step (built once per representation: lambdify is slow)."""
        mods = [{"Min": min, "Max": max, "Abs": abs}, "math"]
        return ([sp.lambdify(self.symbols, e, mods) for e in self.f], sp.lambdify(self.symbols, self.a_y, mods),
                [sp.lambdify(self.symbols, self.rho * e, mods) for e in self.sliding],
                [sp.lambdify(self.symbols, t, mods) for t in self.slips])


def _check_structure(model, source):
    if len(model.states) != 2 or not model.known_inputs or len(model.scheduling) != 1 \
            or [n for n, _ in model.outputs] != ["a_y", str(model.states[1])]:
        raise ModelDefinitionError(f"{source}: model {model.name!r}: the nonlinear-tyre observer needs states "
                                   f"(v_y, r), known inputs (delta first, then any measured signal the tyre laws "
                                   f"read, e.g. a_x), one scheduling signal (v_x) and outputs (a_y, r). Another "
                                   f"structure: the L-infinity UIO (family linf_uio) takes outputs C(rho) x + "
                                   f"Du(rho) u, the TS fuzzy UIO (ts_fuzzy_uio) tyre laws of measured states")


def _axle_bounds(k, a, subs, measured_boxes, rho, delta, d_box, t_sym, vx, vy, stiffness_range, friction_range,
                 source, rel_tol) -> AxleBounds:
    """Sound bounds of v_x dPhi_k/dv_y on |t| <= rho t_sl (see the module docstring)."""
    F = a.peak_symbol
    ranged = {}                  # the axle's stiffness and friction: symbols with their declared range
    for sym, (lo, hi) in ((a.stiffness, stiffness_range), (a.friction, friction_range)):
        if sym is not None:
            nominal = float(subs[sym])
            ranged[sym] = (nominal * lo, nominal * hi)
    fixed = {s: v for s, v in subs.items() if s not in ranged}
    law = sp.sympify(a.law).subs(fixed)
    sliding = sp.sympify(a.sliding).subs(fixed)
    peak = numeric(a.peak, fixed)
    tau = sp.Symbol("tau", real=True)
    dlaw = sp.expand(sp.diff(law, t_sym).subs(sp.sign(t_sym), sp.Abs(t_sym) / t_sym))   # t sign(t) = |t|
    slope = sp.simplify(sp.expand(dlaw.subs(t_sym, tau * sliding)))
    box = {**{s: measured_boxes[s] for s in peak.free_symbols if s in measured_boxes}, **ranged}
    stray = peak.free_symbols - set(box)
    if stray:
        raise ModelDefinitionError(f"{source}: axle {a.name}: its capacity depends on {sorted(map(str, stray))}, "
                                   f"which are neither parameters nor known inputs with a box")
    pk = range_bound(peak, box, rel_tol=rel_tol, relative_cuts=True)
    if not pk.lower > 0:
        raise CertificateError(f"{source}: axle {a.name}: its lateral capacity reaches {pk.lower:.4g} N over the "
                               f"inputs' box: the sliding slip is 0 there")
    slope_box = {tau: (-rho, rho), **({F: (pk.lower, pk.upper)} if F in slope.free_symbols else {}), **ranged}
    stray = slope.free_symbols - set(slope_box)
    if stray:
        raise ModelDefinitionError(f"{source}: axle {a.name}: its law's slope in the normalized slip still depends "
                                   f"on {sorted(map(str, stray))}")
    # a slope proportional to the stiffness (the Fiala law's is C (1 - |tau|)^2) is bounded without it
    # and scaled by its range (a positive factor: exact), else jointly
    factor = (1.0, 1.0)
    if a.stiffness in ranged and a.stiffness not in sp.simplify(slope / a.stiffness).free_symbols:
        factor, slope_b = ranged[a.stiffness], sp.simplify(slope / a.stiffness)
    else:
        slope_b = slope
    rl = range_bound(slope_b, {s: v for s, v in slope_box.items() if s in slope_b.free_symbols}, rel_tol=rel_tol,
                     relative_cuts=True)
    if factor != (1.0, 1.0) or slope_b is not slope:
        scaled = Interval(rl.lower, rl.upper) * Interval(*factor)          # rounded outward
        rl = type(rl)(scaled.lo, scaled.hi, rl.attained_min * factor[0], rl.attained_max * factor[1],
                      rl.boxes_examined)
    t_sl_max = range_bound(sliding, {s: v for s, v in {F: (pk.lower, pk.upper), **ranged}.items()
                                     if s in sliding.free_symbols}, rel_tol=rel_tol, relative_cuts=True).upper
    t_lim = (Interval(rho, rho) * Interval(t_sl_max, t_sl_max)).hi       # rounded up: the set is covered
    kin = sp.factor(sp.trigsimp(sp.cancel((vx * sp.diff(sp.sympify(a.slip).subs(subs), vy)).subs(
        vy, sp.sympify(a.inverse).subs(subs)))))
    geo = sp.sympify(a.projection).subs(subs) * kin
    stray = geo.free_symbols - {t_sym, delta}
    if stray:
        raise ModelDefinitionError(f"{source}: axle {a.name}: v_x dt/dv_y in slip coordinates still depends on "
                                   f"{sorted(map(str, stray))} (AXLES[{k}].inverse is not v_y(t))")
    rg = range_bound(geo, {t_sym: (-t_lim, t_lim), delta: d_box}, rel_tol=rel_tol, relative_cuts=True)
    if not (rl.lower > 0 and rg.upper < 0):
        raise CertificateError(f"{source}: axle {a.name}: on |t| <= {rho:g} t_sl the tyre slope's sound lower bound is "
                               f"{rl.lower:.4g} N (the kinematic factor's upper bound {rg.upper:.4g}), not > 0 (< 0): "
                               f"near full sliding v_y is not observable from (a_y, r); lower the sliding fraction")
    product = Interval(rl.lower, rl.upper) * Interval(rg.lower, rg.upper)   # rounded outward
    theta = (product.lo, product.hi)
    # attained: the product evaluated jointly on a grid of the set (tau, the ranged parameters, the
    # capacity's range, delta); every value lies inside the sound bounds
    slope_fn = sp.lambdify([tau, F, *ranged], slope, "math")
    sliding_fn = sp.lambdify([F, *ranged], sliding, "math")
    geo_fn = sp.lambdify([t_sym, delta], geo, "math")
    values = []
    for tv, Fv, dv, *pv in itertools.product(np.linspace(-rho, rho, 41), np.linspace(pk.lower, pk.upper, 3),
                                             np.linspace(*d_box, 9), *[np.linspace(lo, hi, 3) for lo, hi in
                                                                       ranged.values()]):
        values.append(slope_fn(tv, Fv, *pv) * geo_fn(tv * sliding_fn(Fv, *pv), dv))
    attained = (min(values), max(values))
    if not (theta[0] <= attained[0] and attained[1] <= theta[1]):
        raise CertificateError(f"{source}: axle {a.name}: theta attains [{attained[0]:.6g}, {attained[1]:.6g}] "
                               f"outside its bounds [{theta[0]:.6g}, {theta[1]:.6g}] (unsound bounds)")
    return AxleBounds(theta, attained, (rl.lower, rl.upper), (rg.lower, rg.upper), t_lim)


def represent(module, params, settings, source: str) -> TyreRepresentation:
    """model -> force form, the two slip sets' slope bounds, the boxes (see the module docstring)."""
    model = module.MODEL
    _check_structure(model, source)
    axles = getattr(module, "AXLES", None)
    if not axles:
        raise ModelDefinitionError(f"{source}: model module of {model.name!r} has no AXLES (how each axle force "
                                   f"depends on v_y; see model_defs/single_track_nonlinear_tyre.py)")
    vy, r = model.states
    delta, measured = model.known_inputs[0], model.known_inputs[1:]
    vx = model.scheduling[0].symbol
    subs = parameter_substitution(model, params)
    zero_w = {w: 0 for w in model.unknown_inputs}
    if "v_x" not in params.scheduling:
        raise SchedulingBoundsError(f"{params.source}: no [scheduling.v_x] box")
    boxes = []
    for u in model.known_inputs:
        if str(u) not in params.state_bounds:
            raise SchedulingBoundsError(f"{params.source}: no [state_bounds] {u} = [min, max] (the certified set "
                                        f"covers the known inputs' box)")
        boxes.append((str(u), tuple(params.state_bounds[str(u)])))
    v_box = (params.scheduling["v_x"].lower, params.scheduling["v_x"].upper)
    if not v_box[0] > 0:
        raise SchedulingBoundsError(f"{params.source}: [scheduling.v_x] min must be > 0, got {v_box[0]}")
    if not hasattr(module, "FORCES") or not hasattr(module, "DYNAMICS_IN_FORCES"):
        raise ModelDefinitionError(f"{source}: model module of {model.name!r} needs FORCES, DYNAMICS_IN_FORCES and "
                                   f"A_Y_IN_FORCES (the equations written in the axle forces)")
    Phi = tuple(module.FORCES)
    in_forces = [sp.sympify(e).subs(subs) for e in (*module.DYNAMICS_IN_FORCES, module.A_Y_IN_FORCES)]
    G = sp.Matrix(in_forces).jacobian(sp.Matrix(Phi))
    if any(e.free_symbols for e in G) or any(sp.diff(e, vy) != 0 for e in in_forces):
        raise ModelDefinitionError(f"{source}: the equations in the axle forces must be affine in them with constant "
                                   f"coefficients and free of v_y elsewhere")
    G = np.array(G.tolist(), dtype=float)
    measured_boxes = {u: dict(boxes)[str(u)] for u in measured}
    d_box = boxes[0][1]
    t = module.t_sym
    sets = []
    for rho in (settings.sliding_fraction, settings.gain_sliding_fraction):
        sets.append(tuple(_axle_bounds(k, a, subs, measured_boxes, rho, delta, d_box, t, vx, vy,
                                       settings.stiffness_range, settings.friction_range, source,
                                       settings.bounds_rel_tol) for k, a in enumerate(axles)))
    f = tuple(numeric(e, {**subs, **zero_w}) for e in model.dynamics)
    a_y = numeric(dict(model.outputs)["a_y"], {**subs, **zero_w})
    slips = tuple(sp.sympify(a.slip).subs(subs) for a in axles)
    sliding = tuple(numeric(numeric(a.sliding, {a.peak_symbol: a.peak}), subs) for a in axles)
    # slip t_k depends on v_y + lever_k r: read from the slip expressions (checked, not assumed)
    lever = []
    for a, tk in zip(axles, slips):
        ratio = sp.simplify(sp.diff(tk, r) / sp.diff(tk, vy))
        if ratio.free_symbols:
            raise ModelDefinitionError(f"{source}: axle {a.name}: its slip depends on v_y and r other than through "
                                       f"v_y + c r (dt/dr / dt/dv_y = {ratio})")
        lever.append(float(ratio))
    # the model is the force form with the (clamped) Fiala forces: checked at random points of S
    symbols = (vy, r, *model.known_inputs, vx)
    mods = [{"Min": min, "Max": max, "Abs": abs}, "math"]
    model_forces = [sp.lambdify(symbols, numeric(e, {**subs, **zero_w}), mods) for e in (module.Phi_f, module.Phi_r)]
    in_force_fns = [sp.lambdify([*symbols, *Phi], e, mods) for e in in_forces]
    model_fns = [sp.lambdify(symbols, e, mods) for e in (*f, a_y)]
    rng = np.random.default_rng(0)
    for _ in range(5):
        pt = [rng.uniform(-1, 1), rng.uniform(-0.5, 0.5), *[rng.uniform(*b) for _, b in boxes], rng.uniform(*v_box)]
        fp = [F_(*pt) for F_ in model_forces]
        for e_model, e_force in zip(model_fns, in_force_fns):
            a_, b_ = float(e_model(*pt)), float(e_force(*pt, *fp))
            if not abs(a_ - b_) <= 1e-9 * max(1.0, abs(a_)):
                raise ModelDefinitionError(f"{source}: MODEL is not DYNAMICS_IN_FORCES with the axle forces substituted")
    return TyreRepresentation(f, a_y, G[:2], G[2], sets[0], sets[1], slips, sliding, settings.sliding_fraction,
                              v_box, tuple(boxes), symbols, tuple(lever))
