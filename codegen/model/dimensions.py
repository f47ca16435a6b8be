"""Dimensional analysis of a model, and the plausibility of a parameter file's numbers.

A model declares the units of its signals (``ModelDefinition.units``: states, inputs, outputs,
scheduling signals; parameters may be declared too). Every equation must be dimensionally
consistent: each term of ``x_i' = f_i`` has the unit of ``x_i`` per second, each output the unit
of the output, the argument of ``sin``, ``tanh``, ``exp`` ... is dimensionless, the terms of a sum
agree. Those rules are linear in the (log-)dimensions of the parameters, so :func:`infer` solves
them exactly (rational arithmetic) for every parameter's dimension in the base quantities
length, mass, time and electric current (an assist motor's A, V, Ohm, H). Angles are dimensionless, as in SI. A signal whose unit the model does
not declare is an unknown of the same system, so it constrains nothing by itself; a literal 0
fits any unit (``Min(a_x, 0)``).

:func:`check_units` refuses a model whose equations contradict its declared units, naming the
term or the declaration. It reads every number but 1, -1 and, in a product with a parameter, the
small ratios p/q with |p|, q <= 4 (:func:`_pure`: the 2 of ``t_f / 2``, ``0.5 * m``, pure numbers) as
one that may carry a unit (a ``3000 * sin(...)`` in newtons, a time constant ``(u - x) / 10``, a rate
``-3 * r``), so it refuses only what no
reading of the numbers makes consistent: ``- r`` in an acceleration, a time constant declared
in metres, torques used as forces in ``t_f / 2 * (T_fr - T_fl)``. An output declared in a unit of the same dimension as its signal but another scale
(``deg/s`` for a yaw rate in ``rad/s``) is refused too, since the step does not convert; so are
the parts of one sum fixed by the declarations at two scales of one dimension (``delta`` in deg
beside ``v_y / v_x``), a term at another scale than its equation needs and such an argument of
``sin``, ``exp``, ... (:func:`_scale_mixtures`). (The
plausibility checks read numbers as pure, which infers more: ``2 * C_f`` and ``2 * C_r`` are of
one kind.)

Equations alone fix only *relative* dimensions when the model has a scaling symmetry (a
single-track model is unchanged if mass and every stiffness are scaled together): the front and
the rear cornering stiffness then still have the same dimension, and one declared parameter
unit (``units={"M": "kg", ...}``) fixes all of them.

:func:`check_plausibility` uses this on a parameter file, before any design:

* a parameter whose unit the model declares is checked against the plausible range of that
  quantity for a road vehicle (:data:`PLAUSIBLE`), in SI units (a dimension inferred from the
  equations alone does not say what a parameter is: a drag coefficient can have the dimension
  of a mass, so inferred dimensions serve the next check only);
* two parameters of the same kind (the same dimension and the same name up to an axle or side
  suffix: ``C_f``/``C_r``, ``l_f``/``l_r``, ``K_fl``/``K_rr``) whose values differ by
  :data:`SAME_KIND_RATIO` or more are refused with the ratio: a kN beside an N, a mm beside an m.

A value that is right although it looks wrong is accepted by naming it in the parameter file's
``[plausibility] accept = ["C_f", ...]``.

Units are optional, so a parameter whose unit the model does not declare gets no range: its value
is checked against its sympy assumptions, the model's ``parameter_ranges`` and, with another of its
kind, against a unit slip, never against a plausible range. That is said, not silent:
:func:`unranged_parameters` names them, and ``uiogen design`` and ``uiogen analyze`` print
:func:`unranged_note` (a note, not an error).
"""
from __future__ import annotations

import re
import sys
from dataclasses import dataclass, field
from fractions import Fraction

import sympy as sp

from ..errors import ModelDefinitionError, UnitError

BASE = ("L", "M", "T", "I")     # length [m], mass [kg], time [s], electric current [A]
_ZERO = (0,) * len(BASE)


def _dim(L=0, M=0, T=0, I=0) -> tuple:
    return (L, M, T, I)


# unit symbol -> ((L, M, T, I) exponents, factor to SI); angles and "-" are dimensionless. The
# electrical units are there for actuator models (an assist motor's current, voltage, resistance,
# inductance, its torque constant in N m/A).
_UNITS = {
    "m": (_dim(L=1), 1.0), "mm": (_dim(L=1), 1e-3), "cm": (_dim(L=1), 1e-2), "km": (_dim(L=1), 1e3),
    "kg": (_dim(M=1), 1.0), "t": (_dim(M=1), 1e3),
    "s": (_dim(T=1), 1.0), "ms": (_dim(T=1), 1e-3), "min": (_dim(T=1), 60.0), "h": (_dim(T=1), 3600.0),
    "N": (_dim(1, 1, -2), 1.0), "kN": (_dim(1, 1, -2), 1e3), "Pa": (_dim(-1, 1, -2), 1.0), "W": (_dim(2, 1, -3), 1.0),
    "J": (_dim(2, 1, -2), 1.0), "Hz": (_dim(T=-1), 1.0), "rpm": (_dim(T=-1), 2 * 3.141592653589793 / 60),
    "A": (_dim(I=1), 1.0), "mA": (_dim(I=1), 1e-3), "V": (_dim(2, 1, -3, -1), 1.0), "mV": (_dim(2, 1, -3, -1), 1e-3),
    "Ohm": (_dim(2, 1, -3, -2), 1.0), "H": (_dim(2, 1, -2, -2), 1.0), "mH": (_dim(2, 1, -2, -2), 1e-3),
    "rad": (_ZERO, 1.0), "mrad": (_ZERO, 1e-3), "deg": (_ZERO, 3.141592653589793 / 180),
    "rev": (_ZERO, 2 * 3.141592653589793), "%": (_ZERO, 1e-2),
}
_SPELLING = {"²": "^2", "³": "^3", "·": " ", "*": " ", "Nm": "N m", "°": "deg", "Ω": "Ohm"}

#: plausible ranges of road-vehicle parameters, by dimension (L, M, T, I), in SI units
PLAUSIBLE = {
    _dim(M=1): ("mass", "kg", 0.5, 1.0e5),
    _dim(2, 1, 0): ("moment of inertia", "kg m^2", 1.0e-5, 1.0e6),
    _dim(L=1): ("length", "m", 1.0e-4, 100.0),
    _dim(1, 1, -2): ("force (or force per radian)", "N", 1.0, 1.0e7),
    _dim(2, 1, -2): ("torque (or torque per radian)", "N m", 1.0e-4, 1.0e7),
    _dim(2, 1, -1): ("rotational damping", "N m s", 1.0e-5, 1.0e5),
    _dim(1, 0, -2): ("acceleration", "m/s^2", 0.1, 100.0),
}
#: kinds whose value is a body's own property and positive (a length or a force can be signed)
POSITIVE_KINDS = ("mass", "moment of inertia")
#: a ratio this large between two parameters of the same kind is refused (a kN beside an N)
SAME_KIND_RATIO = 100.0

# axle / side / wheel suffixes: parameters differing only by one are of the same kind
_SUFFIX = re.compile(r"^(?P<stem>.+?)_?(?:f|r|front|rear|fl|fr|rl|rr|left|right|1|2)$")


class DimensionError(ModelDefinitionError):
    """A unit string the analysis cannot read."""


def unit(text: str) -> tuple:
    """((L, M, T, I) exponents, factor to SI) of a unit such as ``"N m s/rad"``, ``"kg m^2"``,
    ``"m/s^2"``, ``"1/m"``, ``"kN/rad"``."""
    u = str(text).strip()
    for a, b in _SPELLING.items():
        u = u.replace(a, b)
    if u in ("", "-", "1"):
        return _ZERO, 1.0
    num, _, den = u.partition("/")
    dims, factor = [0] * len(BASE), 1.0
    for part, sign in ((num, 1), (den, -1)):
        for token in part.replace("(", " ").replace(")", " ").split():
            m = re.fullmatch(r"([A-Za-z%]+|1)(?:\^?(-?\d+))?", token)
            if not m or (m.group(1) not in _UNITS and m.group(1) != "1"):
                raise DimensionError(f"unit {text!r}: cannot read {token!r} (known: {', '.join(_UNITS)})")
            power = int(m.group(2)) if m.group(2) else 1
            d, f = _UNITS.get(m.group(1), (_ZERO, 1.0))
            for k in range(len(BASE)):
                dims[k] += sign * power * d[k]
            factor *= f ** (sign * power)
    return tuple(dims), factor


def parse_unit(text: str) -> tuple:
    """(L, M, T, I) exponents of a unit (:func:`unit`)."""
    return unit(text)[0]


def format_dims(d) -> str:
    if d is None:
        return "undetermined"
    parts = [f"{u}^{int(e) if Fraction(e).denominator == 1 else e}" if e != 1 else u
             for u, e in zip(("m", "kg", "s", "A"), d) if e != 0]
    return " ".join(parts) or "dimensionless"


@dataclass
class _Form:
    """A dimension as const + sum coef[p] * dim(p): one vector per base, the same coefficients."""

    const: tuple = _ZERO
    coef: dict = field(default_factory=dict)

    def __add__(self, other: "_Form") -> "_Form":
        coef = dict(self.coef)
        for p, c in other.coef.items():
            coef[p] = coef.get(p, 0) + c
        return _Form(tuple(a + b for a, b in zip(self.const, other.const)), {p: c for p, c in coef.items() if c})

    def scale(self, k) -> "_Form":
        return _Form(tuple(k * a for a in self.const), {p: k * c for p, c in self.coef.items() if k * c})

    def __sub__(self, other: "_Form") -> "_Form":
        return self + other.scale(-1)

    @property
    def trivial(self) -> bool:
        return not self.coef and not any(self.const)


@dataclass
class Analysis:
    """What :func:`infer` found: each parameter's dimension (None: not fixed by the model), which
    parameters share a dimension even where it is not fixed, and the model's inconsistencies."""

    dims: dict                 # {parameter name: (L, M, T, I) as Fractions, or None}
    same: list                 # [(p, q)] parameters whose dimensions are equal in every solution
    inconsistencies: list      # [text]


def _dimensionless(f: _Form, where: str, constraints: list) -> None:
    if not f.trivial:
        constraints.append((f, where))


class _Unknowns(set):
    """Names of the unknown dimensions: parameters, signals without a declared unit, and with
    ``free_numbers`` one per number other than 0, 1, -1 (:meth:`fresh`)."""

    def __init__(self, names=(), free_numbers: bool = False):
        super().__init__(names)
        self.free_numbers = free_numbers

    def fresh(self, label: str) -> str:
        name = f"{label} #{len(self)}"
        self.add(name)
        return name


# Min and Max re-evaluate when sympy's expand rebuilds them, and their constructor searches for
# dominated arguments with the general simplifier (seconds per equation of a Fiala tyre, on every
# verb): the dimension analysis reads their arguments only, so they are expanded as inert functions
# printed under the same names.
_INERT = {sp.Min: sp.Function("Min"), sp.Max: sp.Function("Max")}
_MINMAX = (sp.Min, sp.Max, *_INERT.values())


def _expanded(expr, parameters=frozenset()):
    """``expr`` expanded into a sum of products, Min and Max kept inert (a Piecewise is left whole), each small
    ratio written as a factor beside one of ``parameters`` marked pure first (:func:`_mark_pure`)."""
    expr = _mark_pure(expr, parameters)
    if expr.has(sp.Piecewise):
        return expr
    return sp.expand(_inert(expr))


PURE = sp.Symbol("pure number")
"""Stands for a small ratio written beside a parameter (dimensionless; the space keeps it apart from any name)."""


def _mark_pure(expr, parameters):
    """``expr`` with every small ratio (:func:`_pure`) that is a factor of a product *as written* beside a
    parameter factor replaced by :data:`PURE`: the 2 of ``t_f / 2 * (T_fr - T_fl)`` and of ``2 * C_f``, but not
    the 1.5 m of ``C_r * (1.5 * r - v_y)``, a length inside a sum that only expanding puts beside ``C_r``."""
    if expr.is_Atom or not parameters:
        return expr
    args = [_mark_pure(a, parameters) for a in expr.args]
    if expr.is_Mul and any((a.is_Symbol and str(a) in parameters)
                           or (a.is_Pow and a.base.is_Symbol and str(a.base) in parameters) for a in args):
        args = [PURE if (a.is_Number and _pure(a)) else a for a in args]
    if all(a is b for a, b in zip(args, expr.args)):
        return expr
    if expr.is_Add or expr.is_Mul or expr.is_Pow or isinstance(expr, (sp.Min, sp.Max)):
        return expr.func(*args, evaluate=False)
    return expr.func(*args)


def _inert(expr):
    """``expr`` with every Min and Max inert, rebuilt from the leaves (sympy's replace would rebuild an
    outer Max from its new arguments and evaluate it)."""
    if expr.is_Atom or not expr.has(sp.Min, sp.Max):
        return expr
    args = [_inert(a) for a in expr.args]
    return _INERT[expr.func](*args) if isinstance(expr, (sp.Min, sp.Max)) else expr.func(*args)


def _is_minmax(expr) -> bool:
    return isinstance(expr, _MINMAX[:2]) or expr.func in _MINMAX[2:]


def _form(expr, known: dict, params: _Unknowns, constraints: list, where: str) -> _Form:
    """The dimension of ``expr`` as a form in the unknown dimensions (``params``: parameters,
    signals without a unit, numbers if ``params.free_numbers``); rules that must hold (sum terms
    equal, function arguments dimensionless) go to ``constraints``."""
    if expr.is_Number or expr in (sp.pi, sp.E) or expr.is_number:
        if params.free_numbers and not (expr.is_zero or expr in (sp.S.One, sp.S.NegativeOne)):
            return _Form(_ZERO, {params.fresh(f"number {expr}"): 1})
        return _Form()
    if expr == PURE:
        return _Form()                          # a small ratio beside a parameter, as written (_mark_pure)
    if expr.is_Symbol:
        name = str(expr)
        if name in known:
            return _Form(known[name])
        params.add(name)             # a parameter, or a signal without a declared unit: unknown
        return _Form(_ZERO, {name: 1})
    if expr.is_Add:
        forms = [_form(a, known, params, constraints, where) for a in expr.args]
        for f in forms[1:]:
            _dimensionless(f - forms[0], f"{where}: terms of a sum", constraints)
        return forms[0]
    if expr.is_Mul:
        out = _Form()
        for a in expr.args:
            out = out + _form(a, known, params, constraints, where)
        return out
    if expr.is_Pow:
        base, exp = expr.args
        if exp.is_Float and sp.nsimplify(exp).is_Rational and sp.nsimplify(exp).q <= 12:
            exp = sp.nsimplify(exp)          # v**0.5 is v**(1/2)
        if exp.is_Rational:
            return _form(base, known, params, constraints, where).scale(Fraction(int(exp.p), int(exp.q)))
        _dimensionless(_form(base, known, params, constraints, where), f"{where}: base of {expr}", constraints)
        _dimensionless(_form(exp, known, params, constraints, where), f"{where}: exponent of {expr}", constraints)
        return _Form()
    if isinstance(expr, (sp.Abs, sp.re, sp.im)):
        return _form(expr.args[0], known, params, constraints, where)
    if _is_minmax(expr):                             # a literal 0 fits any unit: Min(a_x, 0)
        forms = [_form(a, known, params, constraints, where) for a in expr.args if not a.is_zero]
        for f in forms[1:]:
            _dimensionless(f - forms[0], f"{where}: arguments of {expr.func}", constraints)
        return forms[0] if forms else _Form()
    if isinstance(expr, sp.Piecewise):
        forms = []
        for value, cond in expr.args:
            if not value.is_zero:
                forms.append(_form(value, known, params, constraints, where))
            _relational(cond, known, params, constraints, where)
        for f in forms[1:]:
            _dimensionless(f - forms[0], f"{where}: branches of a Piecewise", constraints)
        return forms[0] if forms else _Form()
    if isinstance(expr, sp.atan2):
        a, b = (_form(x, known, params, constraints, where) for x in expr.args)
        _dimensionless(a - b, f"{where}: arguments of atan2", constraints)
        return _Form()
    if isinstance(expr, (sp.sign, sp.Heaviside)):
        _form(expr.args[0], known, params, constraints, where)
        return _Form()
    if isinstance(expr, sp.Function):          # sin, tanh, exp, log, atan, ...: dimensionless in and out
        for a in expr.args:
            _dimensionless(_form(a, known, params, constraints, where), f"{where}: argument of {expr.func}",
                           constraints)
        return _Form()
    if isinstance(expr, sp.Derivative):
        raise DimensionError(f"{where}: a derivative inside the model ({expr})")
    return _Form()                             # relational booleans and anything else: no information


#: a number p/q with 1 <= |p|, q <= PURE_MAX beside a parameter is a pure number, never a unit (:func:`_pure`)
PURE_MAX = 4


def _pure(expr) -> bool:
    """Whether the number ``expr`` is a small ratio p/q (1 <= |p|, q <= :data:`PURE_MAX`, written exactly
    or as the float it rounds to: 2, 1/2, 0.5, 3/4, 1/3), which beside a parameter carries no unit (the
    parameter does): the half of a half-track ``t_f / 2``, the 2 of two tyres ``2 * C_f``, the 1/2 of
    ``m v^2 / 2``. A unit carried by such a number would hide a wrong term (torques used as forces in
    ``t_f / 2 * (T_fr - T_fl)`` passed). With signals alone it may be a rate or a gain (``-3 * r``, a
    rate of 3 1/s), and a larger number (3000 N, a time constant 1/10 s) may carry the unit its term
    needs."""
    import math
    try:
        value = float(expr)
    except TypeError:
        return False
    if not math.isfinite(value) or value == 0:
        return False
    f = Fraction(value).limit_denominator(PURE_MAX)
    return (0 < abs(f.numerator) <= PURE_MAX and f.denominator <= PURE_MAX
            and math.isclose(float(f), value, rel_tol=1e-12, abs_tol=0.0))


def _relational(cond, known, params, constraints, where) -> None:
    if isinstance(cond, sp.core.relational.Relational):
        a, b = (_form(x, known, params, constraints, where) for x in (cond.lhs, cond.rhs))
        if not (cond.rhs.is_number and cond.rhs == 0) and not (cond.lhs.is_number and cond.lhs == 0):
            _dimensionless(a - b, f"{where}: sides of {cond}", constraints)
    elif isinstance(cond, (sp.And, sp.Or, sp.Not)):
        for c in cond.args:
            _relational(c, known, params, constraints, where)


def _equations(model) -> list:
    """[(name of what the expression must have the unit of, unit exponents of it, expr)]."""
    units = dict(getattr(model, "units", None) or {})
    dyn = model.dynamics
    if isinstance(dyn, tuple) and dyn and isinstance(dyn[0], tuple):        # ((state, expr), ...)
        rows = [(str(s), e) for s, e in dyn]
    else:
        rows = [(str(s), e) for s, e in zip(model.states, list(dyn))]
    out = []
    for name, expr in rows:
        if name in units:
            d = parse_unit(units[name])
            out.append((f"d{name}/dt", d[:2] + (d[2] - 1,) + d[3:], sp.sympify(expr)))          # per second
    for name, expr in model.outputs:
        if name in units:
            out.append((f"output {name}", parse_unit(units[name]), sp.sympify(expr)))
    return out


def _signal_units(model, scale: bool = False) -> dict:
    """{signal name: (L, M, T, I) exponents} of every signal with a declared unit (the model's
    ``units`` less its parameters, and the scheduling signals' own units); ``scale=True``: the
    :func:`unit` pairs, exponents and factor to SI."""
    params = {str(p) for p in model.parameters}
    read = unit if scale else parse_unit
    known = {name: read(text) for name, text in (getattr(model, "units", None) or {}).items() if name not in params}
    for g in getattr(model, "scheduling", ()):
        if getattr(g, "unit", "") and str(g.symbol) not in known:
            known[str(g.symbol)] = read(g.unit)
    return known


def check_units(model) -> None:
    """Refuse a model whose equations contradict the units it declares (module docstring).

    Raises
    ------
    UnitError
        naming the model, each term in another unit than its equation needs (or each declared
        parameter unit the equations contradict), and each output declared at another scale than
        the signal it is.

    A model that passed is remembered by its content (:mod:`codegen.model.cache`, keyed also by this
    module's source and sympy's version): the analysis is sympy work that gives
    the same answer every time, and every verb checks the model again.
    """
    from . import cache
    digest = cache.key(UNITS_CHECKED, {"model": cache.model_digest(model), "sympy": sp.__version__,
                                       "code": cache.code_digest(sys.modules[__name__])})
    if cache.read(UNITS_CHECKED, digest) is not None:
        return
    _check_unit_strings(model)
    problems, analysis = [], analysis_of(model, free_numbers=True)
    if analysis.inconsistencies:
        problems = _term_mismatches(model) or _declaration_mismatches(model) or [
            f"the units do not agree in {', '.join(analysis.inconsistencies)}"]
    problems += _scale_mismatches(model) + _scale_mixtures(model)
    if problems:
        raise UnitError(f"model {model.name!r}: its equations contradict its declared units: {'; '.join(problems)} "
                        f"(each term of d x/dt must be in the unit of x per second, an output in its declared unit, "
                        f"the argument of sin, exp, ... dimensionless; angles are dimensionless; a small number "
                        f"such as 2, 1/2 or 3/4 beside a parameter is pure (t_f/2: the parameter carries the unit); "
                        f"a model in normalized time declares no unit for its states)")
    cache.write(UNITS_CHECKED, digest, {"units": "consistent"})


UNITS_CHECKED = "units_checked"


def _check_unit_strings(model) -> None:
    """Every unit the model declares reads (else a :class:`DimensionError` naming the key)."""
    declared = [(f"units[{k!r}]", t) for k, t in (getattr(model, "units", None) or {}).items()]
    declared += [(f"scheduling signal {g.symbol}", g.unit) for g in getattr(model, "scheduling", ()) if g.unit]
    for key, text in declared:
        try:
            unit(text)
        except DimensionError as exc:
            raise DimensionError(f"model {model.name!r}: {key} = {text!r}: {exc.args[0]}; write the unit with "
                                 f"these symbols, products by spaces, one '/' and powers by '^' (\"N m/A\", "
                                 f"\"m/s^2\"), or leave the signal without a unit") from None


def _term_mismatches(model) -> list:
    """The terms of an equation made of signals with declared units and pure numbers alone, whose
    unit is not the one the equation needs (``- r`` in an acceleration)."""
    known, params, out = _signal_units(model), [str(p) for p in model.parameters], []
    for what, dims, expr in _equations(model):
        e = _expanded(expr, frozenset(params))
        for term in (e.args if e.is_Add else (e,)):
            f = _form(term, known, _Unknowns(params, free_numbers=True), [], what)
            if not f.coef and tuple(f.const) != tuple(dims):
                out.append(f"{what}: the term {term} is in {format_dims(f.const)}, the equation needs "
                           f"{format_dims(dims)}")
    return out


def _declaration_mismatches(model) -> list:
    """Declared parameter units that the equations and the signals' units contradict."""
    free, out = infer(model, declared_parameters=False, free_numbers=True), []
    for name, text in (getattr(model, "units", None) or {}).items():
        d = free.dims.get(name)
        if d is not None and tuple(d) != tuple(parse_unit(text)):
            out.append(f"the declared unit of {name} is {text}, the equations make it {format_dims(d)}")
    return out


def _scale_mismatches(model) -> list:
    """Outputs that are a signal (times a number) declared in a unit of the signal's dimension but
    another scale, the number not converting: a gyro in deg/s equal to a yaw rate in rad/s."""
    import math
    units, known, out = getattr(model, "units", None) or {}, _signal_units(model, scale=True), []
    for name, expr in model.outputs:
        coeff, rest = sp.sympify(expr).as_coeff_Mul()
        if name not in units or not rest.is_Symbol or str(rest) not in known or not coeff.is_number:
            continue
        (d_out, f_out), (d_sig, f_sig) = unit(units[name]), known[str(rest)]
        ratio = f_sig / f_out
        if d_out == d_sig and not math.isclose(ratio, 1.0, rel_tol=1e-9) \
                and not math.isclose(float(coeff), ratio, rel_tol=1e-6):
            declared = units.get(str(rest)) or next(g.unit for g in model.scheduling if str(g.symbol) == str(rest))
            out.append(f"output {name} = {expr} is declared in {units[name]}, {rest} is in {declared}, and the step "
                       f"does not convert: declare {name} in {declared}, or write it as {ratio:.10g}*{rest}")
    return out


def _scale_mixtures(model) -> list:
    """Parts of one sum (or Min/Max, Piecewise branches, atan2's arguments) whose units are fixed by
    the declarations alone and have one dimension but another scale, and such a part of an
    equation in another scale than the equation needs; and a fixed argument of sin, exp, ... not
    in radians or SI: ``delta - (v_y + l_f r)/v_x`` with ``delta`` in deg adds degrees to radians,
    and the step does not convert. A part's scale is fixed when it is made of declared signals,
    declared parameters and the numbers 1 and -1; a parameter without a unit, a signal without a
    unit or any other number may carry a scale (the dimension check reads numbers the same way).
    An output that is a number times a signal is :func:`_scale_mismatches`' (it checks the number)."""
    import math
    units = getattr(model, "units", None) or {}
    params = {str(p) for p in model.parameters}
    scales = {name: factor for name, (_, factor) in _signal_units(model, scale=True).items()}
    scales.update({name: unit(text)[1] for name, text in units.items() if name in params})   # declared parameters too
    declared = {**{str(g.symbol): g.unit for g in getattr(model, "scheduling", ()) if getattr(g, "unit", "")},
                **units}
    out: dict = {}          # {what is wrong: [where]}: a sum the equations share is named once

    def say(where, what):
        out.setdefault(what, []).append(where)

    def same(a, b):
        return math.isclose(a, b, rel_tol=1e-9)

    def desc(expr) -> str:
        names = sorted({str(x) for x in sp.sympify(expr).free_symbols if str(x) in declared})
        return ", ".join(f"{n} in {declared[n]}" for n in names) or "pure numbers"

    def agree(parts, what):
        # ``what`` = (where, (text, expr)): the message is only written when the parts disagree
        # (printing every sum of a tyre model on every check took most of its time)
        where, (text, shown) = what
        fixed = [(a, f) for a, f in parts if f is not None]
        for a, f in fixed[1:]:
            b, g = fixed[0]
            if not same(f, g):
                what = f"{text}{shown}"
                # name the simpler part first: it is usually the one declared in another unit
                (a, f), (b, g) = sorted(((a, f), (b, g)), key=lambda t: sp.count_ops(t[0]))
                say(where, f"{what}, {a} ({desc(a)}) is {f / g:.10g} times the unit of {b} ({desc(b)}), and "
                           f"the step does not convert: declare the units alike, or write the conversion")
        return fixed[0][1] if fixed else None

    def scale(expr, where):
        """Factor to SI of ``expr`` when the declarations fix it, else None."""
        if expr.is_number:
            return 1.0 if expr in (sp.S.One, sp.S.NegativeOne) else None
        if expr.is_Symbol:
            return scales.get(str(expr))
        if expr.is_Add:
            return agree([(a, scale(a, where)) for a in expr.args], (where, ("in the sum ", expr)))
        if expr.is_Mul:
            fs = [scale(a, where) for a in expr.args]
            return None if any(f is None for f in fs) else math.prod(fs)
        if expr.is_Pow:
            base, exp = expr.args
            f = scale(base, where)
            if exp.is_number and exp.is_real:
                return None if f is None else f ** float(exp)
            scale(exp, where)
            return None
        if isinstance(expr, (sp.Abs, sp.re, sp.im)):
            return scale(expr.args[0], where)
        if _is_minmax(expr):                             # a literal 0 fits any scale: Min(a_x, 0)
            return agree([(a, scale(a, where)) for a in expr.args if not a.is_zero], (where, ("in ", expr)))
        if isinstance(expr, sp.Piecewise):
            for _, cond in expr.args:
                if isinstance(cond, sp.core.relational.Relational):
                    agree([(x, scale(x, where)) for x in (cond.lhs, cond.rhs) if not x.is_zero],
                          (where, ("in the condition ", cond)))
            return agree([(v, scale(v, where)) for v, _ in expr.args if not v.is_zero],
                         (where, ("among the branches of a Piecewise", "")))
        if isinstance(expr, sp.atan2):
            agree([(x, scale(x, where)) for x in expr.args], (where, ("in ", expr)))
            return 1.0
        if isinstance(expr, (sp.sign, sp.Heaviside)):
            scale(expr.args[0], where)
            return 1.0
        if isinstance(expr, sp.Function):          # sin, exp, atan, ...: read their argument in radians / SI
            for a in expr.args:
                f = scale(a, where)
                if f is not None and not same(f, 1.0):
                    say(where, f"{expr.func} reads its argument {a} ({desc(a)}) in radians / SI units, "
                               f"{1 / f:.10g} times its unit, and the step does not convert: declare the "
                               f"units in radians / SI, or write {f:.10g}*({a})")
            return 1.0
        return None

    for what, _, expr in _equations(model):
        name = what[len("output "):] if what.startswith("output ") else what[1:-3]
        need = scales.get(name)
        coeff, rest = expr.as_coeff_Mul()
        if what.startswith("output ") and rest.is_Symbol and coeff.is_number:
            continue                                # a number times a signal: _scale_mismatches
        terms = expr.args if expr.is_Add else (expr,)
        for term in terms:
            f = scale(term, what)
            if f is not None and need is not None and not same(f, need):
                say(what, f"the term {term} ({desc(term)}) is {f / need:.10g} times the unit the equation "
                          f"needs ({declared[name]}{'' if what.startswith('output') else ' per s'}), and the step "
                          f"does not convert: declare the units alike, or write the conversion")
    return [f"{', '.join(dict.fromkeys(wheres))}: {what}" for what, wheres in out.items()]


def infer(model, declared_parameters: bool = True, free_numbers: bool = False) -> Analysis:
    """Every parameter's dimension from the model's equations and declared units (module docstring);
    ``declared_parameters=False``: from the equations and the signals' units alone;
    ``free_numbers``: every number but 0, 1, -1 may carry a unit (:func:`check_units`)."""
    units = dict(getattr(model, "units", None) or {})
    params = [str(p) for p in model.parameters]
    known = _signal_units(model)
    constraints, unknowns = [], _Unknowns(params, free_numbers)
    for what, dims, expr in _equations(model):
        f = _form(_expanded(expr, frozenset(params)), known, unknowns, constraints, what)
        _dimensionless(f - _Form(dims), what, constraints)
    for name, text in units.items():           # declared parameter units fix the free scales
        if name in params and declared_parameters:
            _dimensionless(_Form(_ZERO, {name: 1}) - _Form(parse_unit(text)), f"declared unit of {name}",
                           constraints)
    names = params + sorted(unknowns - set(params))
    index = {p: k for k, p in enumerate(names)}
    system, inconsistencies = _Echelon(len(names)), []
    for f, where in constraints:            # sum coef d_p = -const, one system for every base
        row = [Fraction(0)] * len(names)
        for p, c in f.coef.items():
            row[index[p]] += Fraction(c)
        if not system.add(row, [-Fraction(c) for c in f.const]) and where not in inconsistencies:
            inconsistencies.append(where)
    dims = {p: system.value(_unit_row(len(names), index[p])) for p in params}
    same = []
    for i, p in enumerate(params):
        for q in params[i + 1:]:
            diff = _unit_row(len(names), index[p])
            diff[index[q]] -= 1
            d = system.value(diff)
            if d is not None and not any(d) and not (dims[p] is not None and not any(dims[p])):
                same.append((p, q))
    return Analysis(dims, same, inconsistencies)


def _unit_row(n, k):
    row = [Fraction(0)] * n
    row[k] = Fraction(1)
    return row


class _Echelon:
    """Rows of a linear system in reduced echelon form, exact (Fractions), grown one row at a time.

    Rows are sparse ({column: coefficient}): a model with a free unknown per number has hundreds of
    columns, each constraint a few."""

    def __init__(self, n: int):
        self.n = n
        self.rows = {}          # pivot column -> (row {column: coefficient} with 1 at the pivot, rhs vector)

    @staticmethod
    def _axpy(row, rhs, c, prow, prhs):
        """(row - c prow, rhs - c prhs), zeros dropped."""
        row = dict(row)
        for k, v in prow.items():
            w = row.get(k, 0) - c * v
            if w:
                row[k] = w
            else:
                row.pop(k, None)
        return row, [a - c * b for a, b in zip(rhs, prhs)]

    def _reduce(self, row, rhs):
        row, rhs = {k: Fraction(v) for k, v in enumerate(row) if v} if isinstance(row, list) else dict(row), list(rhs)
        # the pivot rows are zero on every other pivot column: one pass over the pivots the row holds
        for col in [k for k in row if k in self.rows]:
            c = row.get(col)
            if c:
                row, rhs = self._axpy(row, rhs, c, *self.rows[col])
        return row, rhs

    def add(self, row, rhs) -> bool:
        """Add ``row . d = rhs``; False (and nothing added) when it contradicts the rows so far."""
        row, rhs = self._reduce(row, rhs)
        if not row:
            return not any(rhs)
        pivot = min(row)
        c = row[pivot]
        row, rhs = {k: v / c for k, v in row.items()}, [v / c for v in rhs]
        for col, (prow, prhs) in list(self.rows.items()):     # keep the form reduced
            f = prow.get(pivot)
            if f:
                self.rows[col] = self._axpy(prow, prhs, f, row, rhs)
        self.rows[pivot] = (row, rhs)
        return True

    def value(self, vec):
        """vec . d when every solution gives the same value (vec in the row space), else None."""
        vec, acc = self._reduce(vec, [Fraction(0)] * len(BASE))
        return tuple(-a for a in acc) if not vec else None


def check_plausibility(model, values: dict, source: str, accepted=()) -> None:
    """Refuse parameter values implausible for their dimension, or a kind's values a unit apart.

    Raises
    ------
    ConfigurationError
        naming the file, the parameter(s), the values, the dimension and the ratio, with the
        ``[plausibility] accept`` that overrides.
    """
    from ..settings import config_error
    analysis = analysis_of(model)
    accepted = set(accepted)
    declared = {p: u for p, u in (getattr(model, "units", None) or {}).items() if p in analysis.dims}
    # a range only where the unit is declared: a dimension alone does not say what a parameter is
    # (a drag coefficient can have the dimension of a mass)
    for p, text in declared.items():
        if p in accepted or p not in values:
            continue
        key, factor = unit(text)
        if key in PLAUSIBLE:
            kind, si, lo, hi = PLAUSIBLE[key]
            if kind in POSITIVE_KINDS and values[p] <= 0:
                raise config_error(source, "parameters", p, values[p],
                                   f"a {kind} is > 0 (model {model.name!r} declares {p} in {text}); if the value is "
                                   f"right, add [plausibility] accept = [\"{p}\"]")
            v = abs(values[p]) * factor
            if v != 0 and not lo <= v <= hi:
                raise config_error(source, "parameters", p, values[p],
                                   f"a {kind} of a road vehicle in {text} (model {model.name!r} declares it): "
                                   f"|value| in [{lo / factor:.4g}, {hi / factor:.4g}] {text}; if the value is "
                                   f"right, add [plausibility] accept = [\"{p}\"]")
    for p, q in analysis.same:
        if p in accepted or q in accepted or p not in values or q not in values:
            continue
        mp, mq = _SUFFIX.match(p), _SUFFIX.match(q)
        if not (mp and mq and mp.group("stem") == mq.group("stem")):
            continue
        a, b = abs(values[p]), abs(values[q])
        if a == 0 or b == 0:
            continue
        ratio = max(a, b) / min(a, b)
        if ratio >= SAME_KIND_RATIO:
            dim = analysis.dims.get(p)
            raise config_error(source, "parameters", f"{p}, {q}", [values[p], values[q]],
                               f"values of the same kind within a factor {SAME_KIND_RATIO:g} (both "
                               f"{format_dims(dim) if dim is not None else 'of one dimension'} by model "
                               f"{model.name!r}'s equations); they differ by {ratio:.4g}x: a unit slip (kN against "
                               f"N, mm against m)? If both are right, add [plausibility] accept = [\"{p}\", \"{q}\"]")


def unranged_parameters(model) -> tuple:
    """The parameters of ``model`` whose unit it does not declare, in its order: no plausible range
    applies to their values (:func:`check_plausibility`; a dimension inferred from the equations does
    not say what a parameter is)."""
    units = getattr(model, "units", None) or {}
    return tuple(str(p) for p in getattr(model, "parameters", ()) if str(p) not in units)


def unranged_note(model, model_path=None) -> str:
    """One line naming :func:`unranged_parameters` and how to have them checked, or "" when the
    model declares the unit of every parameter."""
    names = unranged_parameters(model)
    if not names:
        return ""
    one = len(names) == 1
    where = f" ({model_path})" if model_path else ""
    return (f"note: model {model.name!r}{where} declares no unit for {', '.join(names)}: "
            f"{'its value is' if one else 'their values are'} not checked against a plausible range (a value in kN "
            f"where N is meant can pass); to have {'it' if one else 'them'} checked, declare "
            f"{'its unit' if one else 'their units'} in the model's units={{...}} (as \"M\": \"kg\", "
            f"\"C_f\": \"N/rad\", \"I_z\": \"kg m^2\"; units such as m, kg, s, N, rad)")


_CACHE: dict = {}


def analysis_of(model, free_numbers: bool = False) -> Analysis:
    """:func:`infer`, once per model object and reading of the numbers (the analysis is exact and
    costs a few sympy solves), and across runs once per model content (:mod:`codegen.model.cache`)."""
    key = (id(model), free_numbers)
    hit = _CACHE.get(key)
    if hit is None or hit[0] is not model:
        hit = (model, _stored_analysis(model, free_numbers))
        _CACHE[key] = hit
    return hit[1]


ANALYSIS = "unit_analysis"


def _stored_analysis(model, free_numbers: bool) -> Analysis:
    from . import cache
    digest = cache.key(ANALYSIS, {"model": cache.model_digest(model), "free_numbers": free_numbers,
                                  "sympy": sp.__version__, "code": cache.code_digest(sys.modules[__name__])})
    stored = cache.read(ANALYSIS, digest)
    if stored is not None:
        try:
            dims = {p: None if d is None else tuple(Fraction(x) for x in d) for p, d in stored["dims"].items()}
            return Analysis(dims, [tuple(pq) for pq in stored["same"]], list(stored["inconsistencies"]))
        except (KeyError, TypeError, ValueError, ZeroDivisionError, AttributeError):
            pass                         # a record of another shape: computed again below
    out = infer(model, free_numbers=free_numbers)
    cache.write(ANALYSIS, digest, {"dims": {p: None if d is None else [str(x) for x in d] for p, d in out.dims.items()},
                                   "same": [list(pq) for pq in out.same], "inconsistencies": list(out.inconsistencies)})
    return out
