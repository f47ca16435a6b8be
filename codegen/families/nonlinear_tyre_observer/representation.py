"""The numbers of a nonlinear-tyre model: force-affine dynamics and sound axle-slope bounds on a slip set.

Model (``model_defs/single_track_nonlinear_tyre.py``): x = (v_y, r), known inputs delta (the
steering angle) and any further measured signals the tyre laws read (a_x: combined slip),
measured v_x, outputs a_y and r; the dynamics and a_y are *affine in the body-frame axle forces*
Phi_k with constant coefficients, and Phi_k depends on the unmeasured v_y only through the
axle's slip t_k (``AXLES``).

The names are the model's own (:class:`Signals`): v_y, r, delta, v_x and a_y above name *roles*,
read from the model's structure (:func:`signals`): the yaw rate is the state an output measures
as itself (the second state; the lateral speed, unmeasured, the first), the lateral acceleration
the other output (checked to be ``A_Y_IN_FORCES``), the steering angle the one known input the
axle slips read, the forward speed the one scheduling signal (its box ``[scheduling.NAME]``).
A model whose structure leaves a role open is refused, naming the role and how to declare it.

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
import sys
from dataclasses import dataclass

import numpy as np
import sympy as sp

from ...representation.bounds import Interval, range_bound
from ...errors import CertificateError, ModelDefinitionError, SchedulingBoundsError
from ...model import parameter_substitution
from ...model.real import real_valued


def numeric(expr, values: dict):
    """``expr`` with the numbers of ``values`` put in, unevaluated: sympy's own simplification of the
    Min/Max of the combined-slip capacity takes seconds per expression and changes nothing numerically.
    Every signal is real (conjugate(x) read as x: :func:`codegen.model.real.real_valued`)."""
    with sp.evaluate(False):
        return real_valued(sp.sympify(expr)).xreplace(values)


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
    input_boxes: tuple        # ((name, (lo, hi)), ...) of every known input, in the model's order
    symbols: tuple            # (v_y, r, known inputs..., v_x)
    lever: tuple              # (l_f, -l_r): slip t_k depends on v_y + lever_k r (yaw-rate noise enters there)
    signals: "Signals"        # the model's names of the roles, and their units
    through_set: tuple | None = None   # AxleBounds per axle at every slip (``through_sliding``), else None
    forms: tuple = ()         # (f, a_y, sliding, slips) with the parameters as symbols
    parameters: tuple = ()    # ((parameter symbol, value), ...): what f, a_y, sliding and slips have put in

    @property
    def theta(self) -> tuple:
        return tuple(b.theta for b in self.decay_set)

    @property
    def delta_box(self) -> tuple:
        return self.input_boxes[self.signals.steering_index][1]

    @functools.cached_property
    def numpy_functions(self) -> tuple:
        """(f, a_y, slip limits rho t_sl, slips) as plain-Python callables of ``symbols``, for the
        numpy reference step (built once per representation: lambdify is slow)."""
        mods = [{"Min": min, "Max": max, "Abs": abs}, "math"]
        return ([sp.lambdify(self.symbols, e, mods) for e in self.f], sp.lambdify(self.symbols, self.a_y, mods),
                [sp.lambdify(self.symbols, self.rho * e, mods) for e in self.sliding],
                [sp.lambdify(self.symbols, t, mods) for t in self.slips])


STRUCTURE = ("two states (the lateral speed, then the yaw rate), known inputs (the steering angle and any further "
             "measured signal the tyre laws read, e.g. the longitudinal acceleration), one scheduling signal (the "
             "forward speed, measured) and two outputs (the lateral acceleration and the yaw rate itself), under the "
             "model's own names")


def _check_structure(model, source):
    counts = (len(model.states), len(model.known_inputs), len(model.scheduling), len(model.outputs))
    if counts[0] != 2 or not counts[1] or counts[2] != 1 or counts[3] != 2:
        raise ModelDefinitionError(f"{source}: model {model.name!r} has {counts[0]} state(s), {counts[1]} known "
                                   f"input(s), {counts[2]} scheduling signal(s) and {counts[3]} output(s); the "
                                   f"nonlinear-tyre observer needs {STRUCTURE}. Another structure: the L-infinity UIO "
                                   f"(family linf_uio) takes outputs C(rho) x + Du(rho) u, the TS fuzzy UIO "
                                   f"(ts_fuzzy_uio) tyre laws of measured states")


AXLE_FIELDS = ("name", "law", "projection", "slip", "inverse", "sliding", "peak_symbol", "peak", "stiffness",
               "friction")
"""What the family reads of each element of a model's ``AXLES`` (:class:`codegen.model.Axle` says what each is
and checks it; an element of another class with these fields is read too)."""


def axles_of(module, source) -> tuple:
    """The model module's ``AXLES``, each with every field of :data:`AXLE_FIELDS` (else a
    ModelDefinitionError naming the model file, the axle and the missing fields: an axle written against
    an older contract was an AttributeError traceback inside the representation)."""
    model_file = getattr(module, "__file__", None) or source
    axles = getattr(module, "AXLES", None)
    name = getattr(getattr(module, "MODEL", None), "name", "?")
    if not axles:
        raise ModelDefinitionError(f"{model_file}: model module of {name!r} has no AXLES (how each axle force "
                                   f"depends on the lateral speed; see model_defs/single_track_nonlinear_tyre.py)")
    for k, a in enumerate(axles):
        missing = [f for f in AXLE_FIELDS if not hasattr(a, f)]
        if missing:
            label = f"AXLES[{k}]" + (f" ({a.name!r})" if hasattr(a, "name") else "")
            raise ModelDefinitionError(
                f"{model_file}: {label} of model {name!r} has no {', '.join(missing)}: each axle gives "
                f"{', '.join(AXLE_FIELDS)} (peak_symbol: the capacity symbol its law and sliding slip are written in; "
                f"build each with codegen.model.Axle, which checks its fields)")
    return tuple(axles)


@dataclass(frozen=True)
class Signals:
    """The model's own names of what the family reads, by role, and their units (the model's ``units``;
    a scheduling signal's own unit). Every signal of the observer is named from these."""

    lateral_speed: str        # the first state (unmeasured)
    yaw_rate: str             # the second state, measured as itself by an output
    known_inputs: tuple       # every known input, in the model's order
    steering_index: int       # the known input the axle slips read
    speed: str                # the scheduling signal: the measured forward speed
    outputs: tuple            # the model's output names, in its order
    a_y_index: int            # the output that is the lateral acceleration (A_Y_IN_FORCES)
    yaw_rate_index: int       # the output that is the yaw-rate state
    units: dict               # {name: unit} of the above ("" where the model declares none)

    @property
    def steering(self) -> str:
        return self.known_inputs[self.steering_index]

    @property
    def a_y(self) -> str:
        return self.outputs[self.a_y_index]

    @property
    def yaw_rate_output(self) -> str:
        return self.outputs[self.yaw_rate_index]

    def unit(self, name: str) -> str:
        return self.units.get(name, "") or "-"


def signals(module, source: str) -> Signals:
    """The roles of the model's signals, read from its structure (see the module docstring); a
    :class:`~codegen.errors.ModelDefinitionError` naming the role the structure leaves open and how
    to declare it."""
    model = module.MODEL
    _check_structure(model, source)
    where = f"{source}: model {model.name!r}"
    states = [str(x) for x in model.states]
    names = [n for n, _ in model.outputs]
    measured = [(k, str(e)) for k, (_, e) in enumerate(model.outputs)
                if isinstance(sp.sympify(e), sp.Symbol) and sp.sympify(e) in model.states]
    if len(measured) != 1:
        found = ("no output is a state itself" if not measured else
                 f"both outputs {names} are states themselves (the lateral speed must stay unmeasured)")
        raise ModelDefinitionError(f"{where}: the yaw-rate role is open: {found}. The nonlinear-tyre observer "
                                   f"needs the yaw rate measured as it is: in MODEL.outputs, declare one output as the "
                                   f"yaw-rate state itself, e.g. (\"{states[1]}\", {states[1]}), and the other as the "
                                   f"lateral acceleration (A_Y_IN_FORCES with the axle forces substituted)")
    r_out, r_state = measured[0]
    if r_state != states[1]:
        raise ModelDefinitionError(f"{where}: output {names[r_out]!r} measures the state {r_state}, the yaw rate; the "
                                   f"nonlinear-tyre observer takes the states in the order (lateral speed, yaw rate): "
                                   f"declare states = ({states[1]}, {states[0]}) in MODEL")
    axles = axles_of(module, source)
    inputs = [str(u) for u in model.known_inputs]
    read = [k for k, u in enumerate(model.known_inputs)
            if any(u in sp.sympify(a.slip).free_symbols for a in axles)]
    if len(read) != 1:
        found = ("no known input enters an axle slip (AXLES[k].slip)" if not read else
                 f"the known inputs {[inputs[k] for k in read]} all enter the axle slips (AXLES[k].slip)")
        raise ModelDefinitionError(f"{where}: the steering-angle role is open: {found}. The nonlinear-tyre observer "
                                   f"needs one known input, the road-wheel steering angle, in the slips (e.g. the front "
                                   f"slip tan(delta - atan((v_y + l_f r)/v_x))); further known inputs may enter the "
                                   f"axles' lateral capacity only (AXLES[k].peak, e.g. a_x of the friction circle)")
    sched = model.scheduling[0]
    if sched.derived is not None:
        raise ModelDefinitionError(f"{where}: the forward-speed role: the scheduling signal {sched.symbol} is derived "
                                   f"from outputs ({sched.derived}); the nonlinear-tyre observer reads the forward "
                                   f"speed as a measured input: declare SchedulingSignal({sched.symbol}, unit) "
                                   f"without derived")
    speed = str(sched.symbol)
    units = {k: str(v) for k, v in (model.units or {}).items()}
    if getattr(sched, "unit", ""):
        units[speed] = sched.unit
    y_r = names[r_out]
    units.setdefault(y_r, units.get(r_state, ""))
    return Signals(states[0], states[1], tuple(inputs), read[0], speed, tuple(names), 1 - r_out, r_out, units)


AXLE_BOUNDS = "tyre_axle_bounds"
"""The kind of the cached slope bounds (:mod:`codegen.model.cache`)."""


def _axle_bounds(k, a, subs, measured_boxes, rho, delta, d_box, t_sym, vx, vy, stiffness_range, friction_range,
                 source, rel_tol, through: bool = False) -> AxleBounds:
    """:func:`_derive_axle_bounds`, kept across runs (:mod:`codegen.model.cache`): the interval arithmetic
    is most of a design's symbolic work and gives the same bounds for the same axle, parameters, boxes,
    set and code every time. Keyed by all of them (sympy objects by srepr, the deriving modules byte for
    byte, sympy's version); a refusal is never kept (it is raised again, with its message)."""
    from ...model import cache
    from ...representation import bounds as bounds_module
    digest = cache.key(AXLE_BOUNDS, {
        "axle": cache.canonical(a), "subs": cache.canonical(subs), "boxes": cache.canonical(measured_boxes),
        "rho": rho, "delta": cache.canonical(delta), "d_box": list(d_box), "t": cache.canonical(t_sym),
        "vx": cache.canonical(vx), "vy": cache.canonical(vy), "stiffness_range": list(stiffness_range),
        "friction_range": list(friction_range), "rel_tol": rel_tol, "through": through, "sympy": sp.__version__,
        "numpy": np.__version__, "code": cache.code_digest(sys.modules[__name__], bounds_module)})
    stored = cache.read(AXLE_BOUNDS, digest)
    if stored is not None:
        return AxleBounds(*(tuple(stored[f]) if isinstance(stored[f], list) else stored[f]
                            for f in ("theta", "attained", "slope", "kinematic", "slip_max")))
    b = _derive_axle_bounds(k, a, subs, measured_boxes, rho, delta, d_box, t_sym, vx, vy, stiffness_range,
                            friction_range, source, rel_tol, through)
    cache.write(AXLE_BOUNDS, digest, {"theta": [float(x) for x in b.theta], "attained": [float(x) for x in b.attained],
                                      "slope": [float(x) for x in b.slope], "kinematic": [float(x) for x in b.kinematic],
                                      "slip_max": float(b.slip_max)})
    return b


def _derive_axle_bounds(k, a, subs, measured_boxes, rho, delta, d_box, t_sym, vx, vy, stiffness_range,
                        friction_range, source, rel_tol, through: bool = False) -> AxleBounds:
    """Sound bounds of v_x dPhi_k/dv_y on |t| <= rho t_sl (see the module docstring). ``through``: rho = 1 and
    the bounds are widened to hold 0, the slope beyond sliding (checked by :func:`_check_constant_beyond`), so
    they hold at every slip; the slope bound reaching 0 is then expected, not refused."""
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
    if not through and not (rl.lower > 0 and rg.upper < 0):
        raise CertificateError(f"{source}: axle {a.name}: on |t| <= {rho:g} t_sl the tyre slope's sound lower bound is "
                               f"{rl.lower:.4g} N (the kinematic factor's upper bound {rg.upper:.4g}), not > 0 (< 0): "
                               f"near full sliding v_y is not observable from (a_y, r); lower the sliding fraction")
    product = Interval(rl.lower, rl.upper) * Interval(rg.lower, rg.upper)   # rounded outward
    theta = (product.lo, product.hi) if not through else (min(product.lo, 0.0), max(product.hi, 0.0))
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
    model_file = getattr(module, "__file__", None) or source       # where a structure error is the model's
    _check_structure(model, model_file)
    axles = axles_of(module, model_file)
    lacking = [k for k in ("FORCES", "DYNAMICS_IN_FORCES", "A_Y_IN_FORCES", "Phi_f", "Phi_r", "t_sym")
               if not hasattr(module, k)]
    if lacking:
        raise ModelDefinitionError(f"{model_file}: model module of {model.name!r} lacks {', '.join(lacking)}: the "
                                   f"nonlinear-tyre observer reads the equations written in the axle forces (FORCES, "
                                   f"DYNAMICS_IN_FORCES, A_Y_IN_FORCES), the forces themselves (Phi_f, Phi_r) and the "
                                   f"slip symbol of the tyre laws (t_sym), as model_defs/single_track_nonlinear_tyre.py "
                                   f"defines them")
    names = signals(module, model_file)
    vy, r = model.states
    delta = model.known_inputs[names.steering_index]
    measured = tuple(u for u in model.known_inputs if u != delta)
    vx = model.scheduling[0].symbol
    subs = parameter_substitution(model, params)
    zero_w = {w: 0 for w in model.unknown_inputs}
    speed = names.speed
    if speed not in params.scheduling:
        others = sorted(set(params.scheduling))
        raise SchedulingBoundsError(
            f"{params.source}: no [scheduling.{speed}] table (min, max, rate_min, rate_max): the box of the forward "
            f"speed {speed}, the scheduling signal of model {model.name!r}"
            + (f"; the file's [scheduling] has {', '.join(others)}, which the model does not schedule on" if others
               else ""))
    boxes = []
    for u in model.known_inputs:
        if str(u) not in params.state_bounds:
            raise SchedulingBoundsError(f"{params.source}: no [state_bounds] {u} = [min, max] (the certified set "
                                        f"covers the known inputs' box)")
        boxes.append((str(u), tuple(params.state_bounds[str(u)])))
    v_box = (params.scheduling[speed].lower, params.scheduling[speed].upper)
    if not v_box[0] > 0:
        raise SchedulingBoundsError(f"{params.source}: [scheduling.{speed}] min must be > 0 (the forward speed "
                                    f"divides the slips), got {v_box[0]}")
    Phi = tuple(module.FORCES)
    in_forces = [sp.sympify(e).subs(subs) for e in (*module.DYNAMICS_IN_FORCES, module.A_Y_IN_FORCES)]
    G = sp.Matrix(in_forces).jacobian(sp.Matrix(Phi))
    if any(e.free_symbols for e in G) or any(sp.diff(e, vy) != 0 for e in in_forces):
        raise ModelDefinitionError(f"{source}: the equations in the axle forces must be affine in them with constant "
                                   f"coefficients and free of the lateral speed {vy} elsewhere")
    G = np.array(G.tolist(), dtype=float)
    measured_boxes = {u: dict(boxes)[str(u)] for u in measured}
    d_box = boxes[names.steering_index][1]
    t = module.t_sym
    sets = []
    for rho in (settings.sliding_fraction, settings.gain_sliding_fraction):
        sets.append(tuple(_axle_bounds(k, a, subs, measured_boxes, rho, delta, d_box, t, vx, vy,
                                       settings.stiffness_range, settings.friction_range, source,
                                       settings.bounds_rel_tol) for k, a in enumerate(axles)))
    through = None
    if getattr(settings, "through_sliding", False):
        # 1e-3 of the slope's range below its true 0 at sliding is a positive theta of ~100 N: a slope that
        # drives the error at a few 0.01 1/s, above any sensible sliding_growth; 1e-6 leaves ~0.1 N
        through = tuple(_axle_bounds(k, a, subs, measured_boxes, 1.0, delta, d_box, t, vx, vy,
                                     settings.stiffness_range, settings.friction_range, source,
                                     min(settings.bounds_rel_tol, THROUGH_REL_TOL), through=True)
                        for k, a in enumerate(axles))
    # the step's expressions with the parameters as symbols, then with their numbers
    forms = (tuple(numeric(e, zero_w) for e in model.dynamics), numeric(dict(model.outputs)[names.a_y], zero_w),
             tuple(numeric(a.sliding, {a.peak_symbol: a.peak}) for a in axles), tuple(sp.sympify(a.slip) for a in axles))
    f = tuple(numeric(e, subs) for e in forms[0])
    a_y = numeric(forms[1], subs)
    sliding = tuple(numeric(e, subs) for e in forms[2])
    slips = tuple(e.subs(subs) for e in forms[3])
    # slip t_k depends on v_y + lever_k r: read from the slip expressions (checked, not assumed)
    lever = []
    for a, tk in zip(axles, slips):
        ratio = _lever(tk, r, vy)
        if ratio.free_symbols:
            raise ModelDefinitionError(f"{source}: axle {a.name}: its slip depends on v_y and r other than through "
                                       f"v_y + c r (dt/dr / dt/dv_y = {ratio})")
        lever.append(float(ratio))
    # the model is the force form with the (clamped) Fiala forces: checked at random points of S
    symbols = (vy, r, *model.known_inputs, vx)
    mods = [{"Min": min, "Max": max, "Abs": abs}, "math"]
    model_forces = [_with_parameters(symbols, numeric(e, zero_w), subs) for e in (module.Phi_f, module.Phi_r)]
    in_force_fns = [sp.lambdify([*symbols, *Phi], e, mods) for e in in_forces]
    model_fns = [_with_parameters(symbols, numeric(e, zero_w), subs)
                 for e in (*model.dynamics, dict(model.outputs)[names.a_y])]
    rng = np.random.default_rng(0)
    for _ in range(5):
        pt = [rng.uniform(-1, 1), rng.uniform(-0.5, 0.5), *[rng.uniform(*b) for _, b in boxes], rng.uniform(*v_box)]
        fp = [F_(*pt) for F_ in model_forces]
        for row, (e_model, e_force) in enumerate(zip(model_fns, in_force_fns)):
            a_, b_ = float(e_model(*pt)), float(e_force(*pt, *fp))
            if not abs(a_ - b_) <= 1e-9 * max(1.0, abs(a_)):
                if row == len(f):
                    raise ModelDefinitionError(f"{source}: the output {names.a_y!r} of MODEL (the lateral acceleration: "
                                               f"the output that is not the yaw rate) is not A_Y_IN_FORCES with the "
                                               f"axle forces substituted")
                raise ModelDefinitionError(f"{source}: MODEL is not DYNAMICS_IN_FORCES with the axle forces substituted")
    if through is not None:
        _check_constant_beyond(axles, model_forces, symbols, subs, boxes, v_box, t, model_file, rng)
    return TyreRepresentation(f, a_y, G[:2], G[2], sets[0], sets[1], slips, sliding, settings.sliding_fraction,
                              v_box, tuple(boxes), symbols, tuple(lever), names, through, forms,
                              tuple((p, float(v)) for p, v in subs.items()))


@functools.lru_cache(maxsize=32)
def _lever(slip, r, vy):
    """dt/dr / dt/dv_y of a slip (simplified: the lever when the slip depends on v_y + lever r). Kept per slip
    expression in this process: the slips read the geometry alone, so the folds of ``uiogen fit``, which change
    only the tyre's numbers, simplify them once."""
    return sp.simplify(sp.diff(slip, r) / sp.diff(slip, vy))


@functools.lru_cache(maxsize=32)
def _parametric(args: tuple, expr):
    return sp.lambdify(args, expr, [{"Min": min, "Max": max, "Abs": abs}, "math"])


def _with_parameters(symbols: tuple, expr, subs: dict):
    """``expr`` as a function of ``symbols`` at the parameter values ``subs``, for the structure checks.

    Its parameters stay arguments: the compiled function is kept per model expression in this
    process (sympy's printing of a tyre law is most of a representation's time), so the folds of
    ``uiogen fit``, which change only the tyre's numbers, compile it once."""
    names = tuple(subs)
    fn = _parametric((*symbols, *names), expr)
    values = tuple(float(subs[k]) for k in names)
    return lambda *point: fn(*point, *values)


THROUGH_REL_TOL = 1e-6
"""Tightness of the through-sliding slope bounds (relative to the slope's range)."""

BEYOND = (1.0, 1.05, 1.5, 3.0)
"""Normalized slips |tau| = |t| / t_sl at which :func:`_check_constant_beyond` compares each axle force."""


def _check_constant_beyond(axles, model_forces, symbols, subs, boxes, v_box, t, model_file, rng, points: int = 20):
    """The through-sliding bounds take each axle's slope as 0 beyond its sliding slip (the Fiala law's
    clamp). ``Axle.law`` is the law *without* its clamp, so this is a property of the model's own force
    (``Phi_f``, ``Phi_r``): compared at |tau| in :data:`BEYOND`, both signs, at random measured signals of
    their boxes (a ModelDefinitionError naming the axle where it changes: a law that keeps rising, or
    falls, beyond its peak is not covered)."""
    mods = [{"Min": min, "Max": max, "Abs": abs}, "math"]
    others = symbols[1:]                        # r, the known inputs, v_x
    for k, a in enumerate(axles):
        inverse = sp.lambdify([*others, t], sp.sympify(a.inverse).subs(subs), mods)
        t_sl = sp.lambdify(others, numeric(numeric(a.sliding, {a.peak_symbol: a.peak}), subs), mods)
        for _ in range(points):
            pt = [rng.uniform(-0.5, 0.5), *[rng.uniform(*b) for _, b in boxes], rng.uniform(*v_box)]
            for sign in (1.0, -1.0):
                forces = [float(model_forces[k](inverse(*pt, sign * tau * t_sl(*pt)), *pt)) for tau in BEYOND]
                if not all(abs(f - forces[0]) <= 1e-9 * max(1.0, abs(forces[0])) for f in forces):
                    raise ModelDefinitionError(
                        f"{model_file}: axle {a.name}: its force in MODEL is not constant beyond the sliding slip "
                        f"({', '.join(f'{f:.6g} N' for f in forces)} at |t| = {', '.join(map(str, BEYOND))} t_sl): "
                        f"[design] through_sliding certifies every slip only for a law whose slope is 0 beyond "
                        f"sliding (the Fiala law clamped at t_sl, model_defs/tyres.py); clamp the model's force, or "
                        f"set through_sliding = false")
