"""Symbolic model definitions and their instantiation with a parameter file.

A model is written once, with sympy, as ``x_dot = f(x, u, d; rho, p)`` and
``y = h(x; rho, p)`` where ``rho`` are measured scheduling signals and ``p``
named physical parameters. Numbers live in a TOML parameter file, so a user with
another car edits that file, not code. :func:`instantiate` checks the definition
and the file against each other and returns the LPV matrices A(rho), B(rho),
D(rho), C(rho) as sympy matrices in the scheduling symbols only.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import sympy as sp

from ..errors import (MissingParameterError, ModelDefinitionError, NotAffineError, SchedulingBoundsError,
                      UnknownParameterError, brief)
from ..settings import Rule, check_keys, config_error, parse_table, parse_value, suggest
from .floats import FLOAT_NOISE, drop_zero_terms, merge_float_noise  # noqa: F401  (FLOAT_NOISE: re-exported)
from .names import RULE as NAME_RULE, c_name_problem, suggest as suggest_name
from .real import real_valued


@dataclass(frozen=True)
class SchedulingSignal:
    """A measured signal the model depends on non-affinely (e.g. the speed v_x).

    Bounds and rate bounds are read from the parameter file's
    ``[scheduling.NAME]`` table: ``min``, ``max``, ``rate_min``, ``rate_max``.
    ``derived`` makes the signal a function of measured outputs (symbols ``y_<output>``)
    and parameters, computed inside the observer step instead of being an input.
    """

    symbol: sp.Symbol
    unit: str = ""
    derived: sp.Expr | None = None


@dataclass(frozen=True)
class DerivedInput:
    """A known input computed inside the observer step from the measurements.

    A nonlinear term of the model that depends only on measured signals (Nguyen et al. 2021's
    "measured nonlinear consequents") enters the dynamics affinely as a known input whose
    value ``expr`` is a function of measured outputs (symbols ``y_<output>``), input
    scheduling signals and parameters. It is not an input of the generated step: the step
    evaluates it from the same measurements it receives.
    """

    symbol: sp.Symbol
    expr: sp.Expr
    unit: str = ""


@dataclass(frozen=True)
class SchedulingBox:
    """Numeric range of one scheduling signal and of its time derivative."""

    name: str
    lower: float
    upper: float
    rate_lower: float | None        # None (rate_min, rate_max not given): the signal may jump (a gear ratio)
    rate_upper: float | None

    @property
    def rate_bounded(self) -> bool:
        return self.rate_lower is not None


@dataclass(frozen=True)
class ModelDefinition:
    """A vehicle model written once, symbolically.

    Attributes
    ----------
    name : str
        Identifier of the model.
    states, known_inputs, unknown_inputs : tuple of sympy.Symbol
        Named signals; the order is the order of the vectors x, u, d.
    dynamics : sympy.Matrix
        Column of time derivatives of ``states``.
    outputs : tuple of (str, sympy.Expr)
        Measured outputs, each a named expression of the states.
    scheduling : tuple of SchedulingSignal
        Measured signals entering the matrices non-affinely.
    parameters : tuple of sympy.Symbol
        Physical parameters; each needs a value in the parameter file.
    units : mapping of str to str
        Units of states/inputs/outputs, for reports.
    derived_inputs : tuple of DerivedInput
        Known inputs computed inside the step from the measurements (not step inputs).
    parameter_ranges : mapping of str to tuple
        Admissible values of parameters beyond their sympy assumptions (``positive=True``: > 0,
        ``nonnegative=True``: >= 0, ``negative``, ``nonpositive``, ``nonzero``): ``NAME: (min, max)``,
        closed bounds, either None for no bound; a third element ``"()"``, ``"(]"`` or ``"[)"``
        opens them (``"mu": (0, 2, "(]")`` is 0 < mu <= 2). :func:`parameter_substitution` refuses
        a parameter file's value outside its range, before any design.
    """

    name: str
    states: tuple
    known_inputs: tuple
    unknown_inputs: tuple
    dynamics: sp.Matrix
    outputs: tuple
    scheduling: tuple
    parameters: tuple
    units: Mapping[str, str] = field(default_factory=dict)
    doc: str = ""
    derived_inputs: tuple = ()
    parameter_ranges: Mapping[str, tuple] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_field_types(self)
        _check_parameter_ranges(self)
        # every signal is real: sympy's conjugate/re/im of undeclared-real symbols read as identities (model/real.py)
        if isinstance(self.dynamics, sp.MatrixBase):
            object.__setattr__(self, "dynamics", self.dynamics.applyfunc(real_valued))
        object.__setattr__(self, "outputs", tuple((n, real_valued(e)) for n, e in self.outputs))
        for w in self.derived_inputs:
            if not isinstance(w, DerivedInput):
                raise ModelDefinitionError(f"model {self.name!r}: derived_inputs must hold DerivedInput, got {w!r}")
        names = [str(s) for s in (*self.states, *self.known_inputs, *self.unknown_inputs,
                                  *(g.symbol for g in self.scheduling), *self.parameters,
                                  *(w.symbol for w in self.derived_inputs))]
        allowed_derived = ({str(p) for p in self.parameters} | {f"y_{n}" for n, _ in self.outputs}
                           | {str(g.symbol) for g in self.scheduling if g.derived is None})
        for g in self.scheduling:
            if g.derived is not None:
                stray = {str(x) for x in sp.sympify(g.derived).free_symbols} - allowed_derived
                if stray:
                    raise ModelDefinitionError(
                        f"model {self.name!r}: derived scheduling signal {g.symbol} uses {', '.join(sorted(stray))}; "
                        f"it may only use parameters, measured outputs y_<name> and input scheduling signals")
        for w in self.derived_inputs:
            stray = {str(x) for x in sp.sympify(w.expr).free_symbols} - allowed_derived
            if stray:
                raise ModelDefinitionError(
                    f"model {self.name!r}: derived input {w.symbol} uses {', '.join(sorted(stray))}; "
                    f"it may only use parameters, measured outputs y_<name> and input scheduling signals")
        signals = [*(("state", s) for s in self.states), *(("known input", s) for s in self.known_inputs),
                   *(("unknown input", s) for s in self.unknown_inputs),
                   *(("scheduling signal", g.symbol) for g in self.scheduling),
                   *(("derived input", w.symbol) for w in self.derived_inputs),
                   *(("output", n) for n, _ in self.outputs)]
        for role, sym in signals:
            why = c_name_problem(str(sym))
            if why is not None:       # a field of the step's C structs and of the Python API (codegen.model.names)
                raise ModelDefinitionError(
                    f"model {self.name!r}: the {role} {str(sym)!r} {why}; a signal's name is a C and Python "
                    f"identifier of the generated step: {NAME_RULE} (e.g. {suggest_name(str(sym))!r})")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ModelDefinitionError(f"model {self.name!r}: symbol(s) declared twice: {', '.join(dup)}")
        # the step reads each output's measurement as the input y_NAME: no other signal may have that name
        taken = sorted({f"y_{n}" for n, _ in self.outputs} & set(names))
        if taken:
            raise ModelDefinitionError(
                f"model {self.name!r}: {', '.join(taken)} is the name of the measurement of output "
                f"{', '.join(t[2:] for t in taken)} (the step's input y_<output>), and also of a declared "
                f"symbol; rename the symbol")
        if not isinstance(self.dynamics, sp.MatrixBase) or self.dynamics.shape != (len(self.states), 1):
            shape = getattr(self.dynamics, "shape", None)
            raise ModelDefinitionError(
                f"model {self.name!r}: dynamics must be a column of {len(self.states)} expressions "
                f"(one per state), got shape {shape}")
        if not self.outputs:
            raise ModelDefinitionError(f"model {self.name!r}: no measured outputs declared")
        declared = set(names)
        for i, expr in enumerate(self.dynamics):
            stray = {str(s) for s in sp.sympify(expr).free_symbols} - declared
            if stray:
                raise ModelDefinitionError(
                    f"model {self.name!r}: d{self.states[i]}/dt uses undeclared symbol(s) "
                    f"{', '.join(sorted(stray))}")
        for out_name, expr in self.outputs:
            stray = {str(s) for s in sp.sympify(expr).free_symbols} - declared
            if stray:
                raise ModelDefinitionError(
                    f"model {self.name!r}: output {out_name!r} uses undeclared symbol(s) "
                    f"{', '.join(sorted(stray))}")
        for out_name, expr in self.outputs:
            # a measurement of no state tells the observer nothing of them (issue 42): refused, not ignored
            reads = sp.sympify(expr).free_symbols
            if not reads & set(self.states):
                what = (f"it reads only {', '.join(sorted(str(s) for s in reads))}" if reads else "it is a constant")
                raise ModelDefinitionError(
                    f"model {self.name!r}: output {out_name!r} = {expr} reads no state ({what}): it tells the "
                    f"observer nothing about the states; write it in the states it measures (e.g. "
                    f"({str(self.states[0])!r}, {self.states[0]}) for a sensor of {self.states[0]}), or drop it "
                    f"from outputs (a signal measured directly is a known input or a scheduling signal)")

    @property
    def state_names(self) -> tuple:
        return tuple(str(s) for s in self.states)

    @property
    def output_names(self) -> tuple:
        return tuple(n for n, _ in self.outputs)

    @property
    def output_symbols(self) -> tuple:
        """Symbols ``y_<output>`` that derived scheduling signals may use."""
        return tuple(sp.Symbol(f"y_{n}") for n in self.output_names)


def _nonzero(e) -> bool:
    """Whether a coefficient is not zero: as written, and again simplified (a coefficient that only
    simplifies to 0 -- a trigonometric identity, terms that cancel once expanded -- is no feedthrough)."""
    return e != 0 and sp.simplify(e) != 0


@dataclass(frozen=True)
class ParameterSet:
    """Values read from a parameter file."""

    source: str
    values: Mapping[str, float]
    scheduling: Mapping[str, SchedulingBox]
    meta: Mapping[str, str]
    plant: Mapping[str, float] = field(default_factory=dict)   # truth-plant-only values ([plant])
    state_bounds: Mapping[str, tuple] = field(default_factory=dict)   # [state_bounds] NAME = [min, max]
    inputs: Mapping[str, dict] = field(default_factory=dict)   # [inputs.NAME] min, max, bandwidth (excitation)
    accepted: tuple = ()      # [plausibility] accept: values right although they look implausible
    prior: Mapping[str, dict] = field(default_factory=dict)   # [prior] NAME = {value, rel_sigma, source}: published
    sensor_noise: Mapping[str, dict] = field(default_factory=dict)   # [sensor_noise] NAME = {std, unit}: the car's
    # sensors (codegen.validation.noise checks the names and units against the model)


@dataclass(frozen=True)
class LPVModel:
    """A model with its parameters substituted: matrices in the scheduling symbols only."""

    definition: ModelDefinition
    parameters: ParameterSet
    A: sp.Matrix
    B: sp.Matrix
    D: sp.Matrix
    C: sp.Matrix
    scheduling_symbols: tuple
    boxes: tuple
    Du: sp.Matrix = None        # output feedthrough of the known inputs: y = C x + Du u
    derived: tuple = ()         # (symbol, expression in y_<output>) with parameters substituted
    Bw: sp.Matrix = None        # dynamics of the derived inputs w: x' = A x + B u + Bw w + D d
    Duw: sp.Matrix = None       # output feedthrough of the derived inputs
    derived_inputs: tuple = ()  # (symbol, expression in y_<output>) with parameters substituted
    Dd: sp.Matrix = None        # unknown inputs reaching the outputs: y = C x + Du u + Dd d

    @property
    def has_ui_feedthrough(self) -> bool:
        return self.Dd is not None and any(_nonzero(e) for e in self.Dd)

    def require_no_ui_feedthrough(self, family: str, reason: str) -> None:
        """Refuse unknown inputs in the outputs for a family whose theory needs y = C x (the families
        that call this take no known-input feedthrough either, so the advice asks for neither).

        Raises
        ------
        NotAffineError
            naming the outputs and unknown inputs, and the family that takes the structure.
        """
        if not self.has_ui_feedthrough:
            return
        names = [n for n, _ in self.definition.outputs]
        hits = [f"{names[i]} <- {self.definition.unknown_inputs[j]}" for i in range(self.Dd.shape[0])
                for j in range(self.Dd.shape[1]) if _nonzero(self.Dd[i, j])]
        raise NotAffineError(
            f"model {self.definition.name!r}: unknown inputs reach the outputs ({', '.join(hits)}); the {family} "
            f"needs y = C x, no input in an output ({reason}). The L-infinity UIO (family linf_uio) takes this "
            f"feedthrough; or measure outputs that no input, known or unknown, reaches")

    def require_no_derived_inputs(self, family: str, reason: str) -> None:
        """Refuse derived inputs (and the constant terms carried by the input of value 1,
        :func:`constant_terms_as_input`) for a family whose step takes no such input.

        Raises
        ------
        NotAffineError
            naming the terms, the family and the family that takes them.
        """
        inputs = tuple(getattr(self.definition, "derived_inputs", ()))
        if not inputs:
            return
        constant = [w for w in inputs if _is_constant(w)]
        what = []
        if constant:
            col = self.Bw[:, inputs.index(constant[0])] if self.Bw is not None else ()
            terms = [f"d{self.definition.states[i]}/dt: {brief(e)}" for i, e in enumerate(col) if _nonzero(e)]
            what.append(f"terms independent of the states and inputs ({'; '.join(terms) or 'in the outputs'}: a "
                        f"known input of value 1)")
        others = [str(w.symbol) for w in inputs if not _is_constant(w)]
        if others:
            what.append(f"derived inputs ({', '.join(others)})")
        raise NotAffineError(
            f"model {self.definition.name!r} has {' and '.join(what)}; the {family} takes no such input ({reason}). "
            f"The L-infinity UIO (family linf_uio) takes them")

    @property
    def nx(self) -> int:
        return self.A.shape[0]

    @property
    def ny(self) -> int:
        return self.C.shape[0]

    @property
    def nu(self) -> int:
        return self.B.shape[1]

    @property
    def nd(self) -> int:
        return self.D.shape[1]


# Tables of a parameter file and the keys of a [scheduling.NAME] table (derivative_bounds is read by
# codegen.families.algebraic_uio.representation.derivative_boxes; exogenous and premise_bounds by
# codegen.families.interconnected_uio.representation).
PARAMETER_TABLES = ("parameters", "scheduling", "meta", "plant", "state_bounds", "exogenous", "premise_bounds",
                    "inputs", "plausibility", "prior", "sensor_noise")
PRIOR_KEYS = {"value": Rule(float, required=True, doc="the published or datasheet value, in the parameter's unit"),
              "rel_sigma": Rule(float, gt=0, required=True, doc="its stated uncertainty, one standard deviation "
                                                                 "relative to the value"),
              "source": Rule(str, doc="where the value is published")}
INPUT_KEYS = {"min": Rule(float, required=True), "max": Rule(float, required=True),
              "bandwidth": Rule(float, gt=0, doc="Hz, highest frequency of the excitation signal")}
SENSOR_NOISE_KEYS = {"std": Rule(float, ge=0, required=True, doc="standard deviation of the sensor's white noise, "
                                                                  "in unit"),
                     "unit": Rule(str, doc="the unit std is in (default: the signal's unit in the model)")}
SCHEDULING_KEYS = {"min": Rule(float), "max": Rule(float), "rate_min": Rule(float), "rate_max": Rule(float),
                   "derivative_bounds": Rule(list, doc="[[min, max], ...] of the derivatives of order 2, 3, ...")}
PLAUSIBILITY_KEYS = {"accept": Rule(list, items=Rule(str), doc="parameters whose values are right although "
                                                               "they look implausible (codegen.model.dimensions)")}
_NUMBER = Rule(float)
_STD = Rule(float, ge=0, allowed="a standard deviation >= 0 in the signal's unit (a finite number), or "
                                 "{ std = ..., unit = \"...\" }: the white noise of the measured signal's sensor")
_PAIR = Rule(list, items=Rule(float), allowed="[min, max], two finite numbers")


def _pair(value, path, section, key) -> tuple:
    """[min, max] of finite numbers (min < max is checked by the caller)."""
    pair = parse_value(value, _PAIR, source=str(path), section=section, key=key)
    if len(pair) != 2:
        raise config_error(str(path), section, key, value, "must be " + _PAIR.allowed)
    return pair[0], pair[1]


def _table(data, name, path) -> dict:
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise config_error(str(path), None, name, table, "must be a table")
    return table


def load_parameters(path: str | Path) -> ParameterSet:
    """Read a TOML parameter file.

    The file has a ``[parameters]`` table of name = number, a ``[scheduling.NAME]``
    table per scheduling signal with ``min``, ``max``, ``rate_min``, ``rate_max`` (and optionally
    ``derivative_bounds``), and an optional ``[meta]`` table of strings (source, car), an optional
    ``[plant]`` table of truth-plant-only numbers and an optional ``[state_bounds]`` table
    ``NAME = [min, max]`` (the compact state set of designs that bound unmeasured nonlinearities);
    ``[exogenous]`` and ``[premise_bounds]`` are read by the interconnected family; ``[inputs.NAME]``
    (``min``, ``max``, optional ``bandwidth`` in Hz) bounds a known or unknown input for the generic
    excitation scenario (:mod:`codegen.validation.excitation`; ``min = max`` holds it at that value);
    ``[sensor_noise]`` (``NAME = std`` or ``NAME = { std, unit }``) is the standard deviation of each
    measured signal's sensor noise (:mod:`codegen.validation.noise`: ``uiogen validate`` adds it).

    Raises
    ------
    ConfigurationError
        An unknown table or ``[scheduling.NAME]`` key (with a did-you-mean), or a value that is
        not a finite number (booleans, strings, nan and inf are refused).
    ModelDefinitionError, SchedulingBoundsError
        No file, not TOML, no ``[parameters]``, missing or inverted bounds.
    """
    path = Path(path)
    if path.is_dir():
        raise ModelDefinitionError(f"parameter file {path} is a folder, not a file: name the .toml file in it")
    try:
        # utf-8-sig: a byte-order mark (Windows editors write one) is read past, as the hashes do
        data = tomllib.loads(path.read_bytes().decode("utf-8-sig"))
    except FileNotFoundError:
        raise ModelDefinitionError(f"parameter file not found: {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ModelDefinitionError(f"parameter file {path} is not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ModelDefinitionError(f"parameter file {path} is not UTF-8 text ({exc.reason} at byte {exc.start}); "
                                   f"save it as UTF-8") from None
    check_keys(data, PARAMETER_TABLES, source=str(path), what="tables")
    raw = data.get("parameters")
    if not isinstance(raw, dict):
        raise ModelDefinitionError(f"parameter file {path} has no [parameters] table")
    values = {key: parse_value(value, _NUMBER, source=str(path), section="parameters", key=key)
              for key, value in raw.items()}
    boxes = {}
    for key, table in _table(data, "scheduling", path).items():
        section = f"scheduling.{key}"
        if not isinstance(table, dict):
            raise config_error(str(path), "scheduling", key, table, "must be a table [scheduling.NAME] with min, "
                               "max, rate_min, rate_max")
        missing = [k for k in ("min", "max") if k not in table]
        if missing:
            raise SchedulingBoundsError(
                f"{path}: scheduling signal {key!r} lacks {', '.join(missing)}")
        rates = [k for k in ("rate_min", "rate_max") if k in table]
        if len(rates) == 1:
            other = "rate_max" if rates == ["rate_min"] else "rate_min"
            raise SchedulingBoundsError(f"{path}: scheduling signal {key!r} gives {rates[0]} without {other}: both "
                                        f"(the bounds of its rate) or neither (a signal that may jump, as a gear "
                                        f"ratio: only designs that hold for any rate take it)")
        table = parse_table(table, SCHEDULING_KEYS, source=str(path), section=section)
        for m, pair in enumerate(table.get("derivative_bounds", ()), start=2):
            _pair(pair, path, section, f"derivative_bounds[{m - 2}]")
        box = SchedulingBox(key, table["min"], table["max"], table.get("rate_min"), table.get("rate_max"))
        if not box.lower < box.upper:
            raise SchedulingBoundsError(f"{path}: scheduling {key!r} needs min < max, got "
                                        f"[{box.lower}, {box.upper}]")
        if box.rate_bounded and not box.rate_lower <= box.rate_upper:
            raise SchedulingBoundsError(f"{path}: scheduling {key!r} needs rate_min <= rate_max")
        boxes[key] = box
    meta = {k: str(v) for k, v in _table(data, "meta", path).items()}
    plant = {key: parse_value(value, _NUMBER, source=str(path), section="plant", key=key)
             for key, value in _table(data, "plant", path).items()}
    for key, value in _table(data, "exogenous", path).items():
        parse_value(value, _NUMBER, source=str(path), section="exogenous", key=key)
    for key, value in _table(data, "premise_bounds", path).items():
        _pair(value, path, "premise_bounds", key)
    state_bounds = {}
    for key, value in _table(data, "state_bounds", path).items():
        if (not isinstance(value, list) or len(value) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            raise SchedulingBoundsError(f"{path}: state bound {key!r} must be [min, max], got {value!r}")
        lo, hi = _pair(value, path, "state_bounds", key)
        if not lo < hi:
            raise SchedulingBoundsError(f"{path}: state bound {key!r} needs min < max, got [{lo}, {hi}]")
        state_bounds[key] = (lo, hi)
    inputs = {}
    for key, table in _table(data, "inputs", path).items():
        if not isinstance(table, dict):
            raise config_error(str(path), "inputs", key, table, "must be a table [inputs.NAME] with min, max")
        table = parse_table(table, INPUT_KEYS, source=str(path), section=f"inputs.{key}")
        if not table["min"] <= table["max"]:      # min = max: the input held at that value
            raise config_error(str(path), f"inputs.{key}", "max", table["max"], f"must be >= min = {table['min']}")
        inputs[key] = table
    plausibility = parse_table(_table(data, "plausibility", path), PLAUSIBILITY_KEYS, source=str(path),
                               section="plausibility")
    accepted = tuple(plausibility.get("accept", ()))
    stray = [a for a in accepted if a not in values]
    if stray:
        raise config_error(str(path), "plausibility", "accept", stray,
                           f"names of [parameters] ({', '.join(values)})", suggest(stray[0], list(values)))
    prior = {}
    for key, table in _table(data, "prior", path).items():
        if key not in values:
            raise config_error(str(path), "prior", key, table, f"the name of a [parameters] value ({', '.join(values)})",
                               suggest(key, list(values)))
        if not isinstance(table, dict):
            raise config_error(str(path), "prior", key, table, "an inline table { value = ..., rel_sigma = ..., "
                               "source = \"...\" } (the published value and its relative uncertainty)")
        prior[key] = parse_table(table, PRIOR_KEYS, source=str(path), section=f"prior.{key}")
    sensor_noise = {key: _sensor_noise(value, path, key) for key, value in _table(data, "sensor_noise", path).items()}
    return ParameterSet(str(path), values, boxes, meta, plant, state_bounds, inputs, accepted, prior, sensor_noise)


def _sensor_noise(value, path, key) -> dict:
    """``[sensor_noise] NAME = std`` (in the signal's unit) or ``NAME = { std = ..., unit = "..." }``
    as {"std", "unit" (None: the model's)}; a negative, non-numeric or non-finite std is refused."""
    if isinstance(value, dict):
        table = parse_table(value, SENSOR_NOISE_KEYS, source=str(path), section=f"sensor_noise.{key}")
        return {"std": float(table["std"]), "unit": table.get("unit")}
    std = parse_value(value, _STD, source=str(path), section="sensor_noise", key=key)
    return {"std": float(std), "unit": None}


def _affine_part(expr_column: sp.Matrix, symbols: tuple, what: str, model: str, hint=None) -> sp.Matrix:
    """Jacobian of ``expr_column`` w.r.t. ``symbols``, checked to be constant in them (``hint(symbol)``:
    a sentence on how to make it so)."""
    if not symbols:
        return sp.zeros(expr_column.shape[0], 0)
    jac = expr_column.jacobian(sp.Matrix(symbols))
    for (i, j), entry in zip(((i, j) for i in range(jac.shape[0]) for j in range(jac.shape[1])), jac):
        if entry.free_symbols & set(symbols):
            raise NotAffineError(
                f"model {model!r}: row {i} is not affine in {what} (d/d{symbols[j]} = {brief(entry)} "
                f"still depends on {', '.join(sorted(map(str, entry.free_symbols & set(symbols))))})"
                + (f"; {hint(symbols[j])}" if hint is not None else ""),
                unknown_inputs=(symbols[j],) if what == "the unknown inputs" else ())
    return jac


_BRACKETS = ("[]", "[)", "(]", "()")
_OPS = {">": lambda v, b: v > b, ">=": lambda v, b: v >= b, "<": lambda v, b: v < b, "<=": lambda v, b: v <= b,
        "!=": lambda v, b: v != b}


_SYMBOL_FIELDS = ("states", "known_inputs", "unknown_inputs", "parameters")


def _check_field_types(model) -> None:
    """Refuse a field of the wrong type with the field's name and what it takes.

    Without this, a misplaced type surfaced as whatever Python raised first (``not enough values
    to unpack`` for outputs given as a dict, an AttributeError traceback for a parameter given as
    a string), and a state given as the string "v_x" became a symbol without the assumptions
    (``positive=True``) of the ``v_x`` the equations use: another symbol of the same name.
    """
    who = f"model {model.name!r}" if isinstance(model.name, str) else "model"
    if not isinstance(model.name, str) or not model.name:
        raise ModelDefinitionError(f"model: name must be a non-empty string, got {model.name!r}")
    for key in _SYMBOL_FIELDS:
        value = getattr(model, key)
        if not isinstance(value, (tuple, list)):
            raise ModelDefinitionError(f"{who}: {key} must be a tuple of sympy symbols, got {type(value).__name__} "
                                       f"{value!r}")
        for item in value:
            if not isinstance(item, sp.Symbol):
                hint = (f"; declare it with sp.symbols({str(item)!r}) (with the assumptions the equations use, "
                        f"e.g. positive=True)" if isinstance(item, str) else "")
                raise ModelDefinitionError(f"{who}: {key} must hold sympy symbols, got {type(item).__name__} "
                                           f"{item!r}{hint}")
    if not isinstance(model.outputs, (tuple, list)) or not all(
            isinstance(o, (tuple, list)) and len(o) == 2 and isinstance(o[0], str) for o in model.outputs):
        raise ModelDefinitionError(f"{who}: outputs must be a tuple of (name, expression) pairs, e.g. "
                                   f"((\"r\", r), (\"a_y\", F / m)), got {model.outputs!r}"[:400])
    for name, expr in model.outputs:
        if not isinstance(expr, (sp.Expr, int, float)):
            raise ModelDefinitionError(f"{who}: output {name!r} must be a sympy expression, got "
                                       f"{type(expr).__name__} {expr!r}")
    if not isinstance(model.scheduling, (tuple, list)):
        raise ModelDefinitionError(f"{who}: scheduling must be a tuple of SchedulingSignal, got "
                                   f"{type(model.scheduling).__name__}")
    for g in model.scheduling:
        if not isinstance(g, SchedulingSignal) or not isinstance(g.symbol, sp.Symbol):
            raise ModelDefinitionError(f"{who}: scheduling must hold SchedulingSignal(symbol, unit), got "
                                       f"{type(g).__name__} {g!r}" + (f"; write SchedulingSignal({g}, \"UNIT\")"
                                                                       if isinstance(g, sp.Symbol) else ""))
    if not isinstance(model.dynamics, sp.MatrixBase):
        raise ModelDefinitionError(f"{who}: dynamics must be a sympy Matrix, one row per state "
                                   f"(sp.Matrix([...])), got {type(model.dynamics).__name__}")
    if not isinstance(model.units, Mapping) or not all(
            isinstance(k, str) and isinstance(v, str) for k, v in model.units.items()):
        raise ModelDefinitionError(f"{who}: units must map signal or parameter names to unit strings, e.g. "
                                   f"{{\"v_x\": \"m/s\"}}, got {model.units!r}"[:400])


def check_unit_keys(model) -> None:
    """Refuse a units key that looks misspelt (called on a model read from a user's file: models
    derived inside the toolchain keep the units of signals they replaced, a substituted input's).

    A units key that looks like a misspelt name of the model ("vy" beside a state "v_y" that has
    no unit of its own) declares nothing: the signal would silently stay without its unit, and its
    dimensions, plausibility and the data map's conversions unchecked. Other keys are kept: a model
    may name the units of signals its plants and logs use (a roll model's "a_x")."""
    known = {str(x) for x in (*model.states, *model.known_inputs, *model.unknown_inputs, *model.parameters,
                              *(g.symbol for g in model.scheduling), *(w.symbol for w in model.derived_inputs))}
    known |= {n for n, _ in model.outputs}
    for k in model.units:
        if k in known:
            continue
        near = suggest(k, sorted(known))
        if near is not None and near not in model.units:
            raise ModelDefinitionError(
                f"model {model.name!r}: units[{k!r}] names no signal or parameter of the model (did you mean "
                f"{near!r}? it has no unit); allowed: {', '.join(sorted(known))}")


def _check_parameter_ranges(model) -> None:
    """``model.parameter_ranges`` names parameters of the model, with (min, max[, brackets]) ranges."""
    names = [str(p) for p in model.parameters]
    for name, rng in (getattr(model, "parameter_ranges", None) or {}).items():
        if name not in names:
            raise ModelDefinitionError(f"model {model.name!r}: parameter_ranges names {name!r}, which is not a "
                                       f"parameter (declared: {', '.join(names)})"
                                       + (f"; did you mean {suggest(name, names)!r}?" if suggest(name, names) else ""))
        bounds = rng[:2] if isinstance(rng, tuple) else ()
        if (len(bounds) != 2 or len(rng) > 3 or (len(rng) == 3 and rng[2] not in _BRACKETS)
                or not all(b is None or (isinstance(b, (int, float)) and not isinstance(b, bool) and math.isfinite(b))
                           for b in bounds)
                or (None not in bounds and not bounds[0] <= bounds[1])):
            raise ModelDefinitionError(f"model {model.name!r}: parameter_ranges[{name!r}] must be (min, max) or "
                                       f"(min, max, one of {', '.join(_BRACKETS)}) with finite min <= max or None, "
                                       f"got {rng!r}")


def parameter_conditions(model, symbol) -> list:
    """[(op, bound, reason)] every value of parameter ``symbol`` must satisfy (op in >, >=, <, <=, !=).

    From the symbol's sympy assumptions and the model's ``parameter_ranges``.
    """
    conds = []
    if symbol.is_positive:
        conds.append((">", 0.0, "positive=True"))
    elif symbol.is_negative:
        conds.append(("<", 0.0, "negative=True"))
    else:
        if symbol.is_nonnegative:
            conds.append((">=", 0.0, "nonnegative=True"))
        elif symbol.is_nonpositive:
            conds.append(("<=", 0.0, "nonpositive=True"))
        if symbol.is_nonzero:
            conds.append(("!=", 0.0, "nonzero=True"))
    rng = (getattr(model, "parameter_ranges", None) or {}).get(str(symbol))
    if rng:
        brackets = rng[2] if len(rng) == 3 else "[]"
        why = f"parameter_ranges {rng[:2]!r}" + (f" {brackets}" if len(rng) == 3 else "")
        if rng[0] is not None:
            conds.append((">" if brackets[0] == "(" else ">=", float(rng[0]), why))
        if rng[1] is not None:
            conds.append(("<" if brackets[1] == ")" else "<=", float(rng[1]), why))
    return conds


def check_parameter_values(model, values: Mapping[str, float], source: str, section: str = "parameters") -> None:
    """Refuse a value of ``values`` outside the admissible range of its model parameter.

    Raises
    ------
    ConfigurationError
        Naming the file, the parameter, its value and the allowed range (and where it is declared).
    """
    for p in model.parameters:
        value = values[str(p)]
        conds = parameter_conditions(model, p)
        if not math.isfinite(value) or not all(_OPS[op](value, b) for op, b, _ in conds):
            allowed = " and ".join(f"{op} {b:g}" for op, b, _ in conds)
            reasons = "; ".join(dict.fromkeys(why for _, _, why in conds))
            raise config_error(source, section, str(p), value,
                               f"must be a finite number{(' ' + allowed) if allowed else ''}"
                               + (f" (model {model.name!r} declares {p}: {reasons})" if reasons else ""))


def model_equations(model) -> list:
    """[(where, expression)] of every equation a design evaluates."""
    dynamics = list(getattr(model, "dynamics", ()))
    pairs = dynamics if dynamics and isinstance(dynamics[0], tuple) else zip(getattr(model, "states", ()), dynamics)
    out = [(f"d{x}/dt", e) for x, e in pairs]         # (state, expression) pairs: an interconnected model
    out += [(f"output {n}", e) for n, e in getattr(model, "outputs", ())]
    out += [(f"derived input {w.symbol}", w.expr) for w in getattr(model, "derived_inputs", ())]
    out += [(f"scheduling signal {g.symbol}", g.derived) for g in getattr(model, "scheduling", ())
            if g.derived is not None]
    return out


def check_singular_values(model, values: Mapping[str, float], source: str) -> None:
    """Refuse parameter values that make a part of the model's equations made of parameters alone
    infinite, undefined or complex (``1/M`` with M = 0, ``sqrt(l_f - l_r)`` with l_f < l_r): the
    design would otherwise fail deep inside with a numeric error, or go on with a model that is not
    the one written. Each largest such part is evaluated once with the file's values.

    Raises
    ------
    ConfigurationError
        naming the file, the parameters and their values, the equation and the part.
    """
    params = set(model.parameters)
    subs = {p: sp.Float(values[str(p)]) for p in params if str(p) in values}
    seen = set()

    def visit(where, e):
        if e in seen or not isinstance(e, sp.Basic) or e.is_Atom:
            return
        seen.add(e)
        free = e.free_symbols
        if free and free <= params:
            v = e.xreplace(subs)
            bad = v.has(sp.zoo, sp.oo, -sp.oo, sp.nan) or (v.is_number and v.is_extended_real is False)
            if not bad and v.is_number:
                try:
                    bad = not math.isfinite(float(v))
                except (TypeError, ValueError):
                    bad = True
            if bad:
                names = sorted(str(q) for q in free)
                what = ("infinite (a division by zero)" if v.has(sp.zoo, sp.oo, -sp.oo) else
                        "undefined" if v.has(sp.nan) else f"complex ({brief(sp.N(v, 6))}: a root or log of a negative "
                                                         f"number)")
                raise config_error(source, "parameters", ", ".join(names),
                                   values[names[0]] if len(names) == 1 else [values[q] for q in names],
                                   f"model {model.name!r}: with this value its {where} holds {brief(e)}, which is "
                                   f"{what}; the values must keep every part of the equations finite and real")
            return
        for a in e.args:
            visit(where, a)
    for where, expr in model_equations(model):
        visit(where, sp.sympify(expr))


def check_signal_tables(model: ModelDefinition, params: ParameterSet) -> None:
    """Refuse an entry of the parameter file's ``[scheduling.NAME]``, ``[state_bounds]`` or
    ``[inputs.NAME]`` tables that names no signal of the model (a misspelt signal would otherwise
    be silently unused, its box never applied). Whether a signal may have the entry (a state's
    ``[inputs]`` range, a box for an input the family wants scheduled) is the family's and the
    excitation scenario's to say, with what the model needs instead.

    Raises
    ------
    ConfigurationError
        naming the file, the table, the key, the model's signals and the nearest one.
    """
    from ..settings import check_keys
    signals = {*model.state_names, *(str(s) for s in (*model.known_inputs, *model.unknown_inputs)),
               *(str(g.symbol) for g in model.scheduling), *model.output_names,
               *(str(w.symbol) for w in model.derived_inputs)}
    what = f"(the signals of model {model.name!r})"
    check_keys({k: {"min": b.lower, "max": b.upper} for k, b in params.scheduling.items()}, signals,
               source=params.source, section="scheduling", what=what)
    check_keys(params.inputs, signals, source=params.source, section="inputs", what=what)
    check_keys(params.state_bounds, signals, source=params.source, section="state_bounds", what=what)


def parameter_substitution(model: ModelDefinition, params: ParameterSet) -> dict:
    """{parameter symbol: value}, after checking the file sets exactly the model's parameters.

    Every value must lie in the parameter's admissible range (:func:`parameter_conditions`: its
    sympy assumptions and the model's ``parameter_ranges``); this is the one parameter check of
    every family, so a negative mass or a zero inertia is refused before any design.

    Raises
    ------
    MissingParameterError, UnknownParameterError, ConfigurationError
    """
    needed = [str(p) for p in model.parameters]
    missing = [n for n in needed if n not in params.values]
    unknown = sorted(set(params.values) - set(needed))
    if missing:
        import difflib
        hints = [f"{u} (did you mean {m[0]}?)" for u in unknown
                 for m in [difflib.get_close_matches(u, missing, n=1)] if m]
        raise MissingParameterError(
            f"model {model.name!r}: parameter file {params.source} lacks {', '.join(missing)}"
            + (f"; it sets {', '.join(hints)}" if hints else ""))
    if unknown:
        raise UnknownParameterError(
            f"parameter file {params.source} sets {', '.join(unknown)}, which model "
            f"{model.name!r} does not use (declared: {', '.join(needed)})")
    check_parameter_values(model, params.values, params.source)
    check_singular_values(model, params.values, params.source)
    from .dimensions import check_plausibility, check_units
    check_units(model)
    check_plausibility(model, params.values, params.source, params.accepted)
    return {p: params.values[str(p)] for p in model.parameters}


CONSTANT_INPUT = "one"
"""The name of the known input of value 1 that carries a model's constant terms
(:func:`constant_terms_as_input`; ``one_w``, ``one_w_w``... where the model uses the name)."""


def _is_constant(w) -> bool:
    """Whether a derived input is the input of value 1 (:func:`constant_terms_as_input`)."""
    return sp.sympify(w.expr) == 1


def constant_terms_as_input(model: ModelDefinition, rest, h_rest) -> ModelDefinition:
    """The model with its terms free of states and inputs (``rest`` in the dynamics, ``h_rest`` in
    the outputs: parameters and scheduling signals only) carried by a derived input ``one`` of value 1.

    Rolling resistance ``-f_r g`` is such a term: x' = A x + B u + D d + b0(rho) is x' = A x + B u
    + D d + b0(rho) * 1, a known input whose column is b0 and whose value the step sets to 1 (no
    input of the step: the step computes it as it computes every derived input). The equations are
    unchanged where ``one`` = 1: each row becomes ``f + b0 (one - 1)``, so the plant simulated from
    the model (derived inputs substituted by their values) is the model as written."""
    import dataclasses
    used = {str(s) for s in (*model.states, *model.known_inputs, *model.unknown_inputs, *model.parameters,
                             *(g.symbol for g in model.scheduling), *(w.symbol for w in model.derived_inputs))}
    used |= {n for n, _ in model.outputs} | {f"y_{n}" for n, _ in model.outputs}
    name = CONSTANT_INPUT
    while name in used:
        name += "_w"
    one = sp.Symbol(name)
    dynamics = sp.Matrix([e + r * (one - 1) for e, r in zip(sp.Matrix(model.dynamics), rest)])
    outputs = tuple((n, sp.sympify(e) + r * (one - 1)) for (n, e), r in zip(model.outputs, h_rest))
    units = {**model.units, str(one): "-"}
    return dataclasses.replace(model, dynamics=dynamics, outputs=outputs, units=units,
                               derived_inputs=(*model.derived_inputs, DerivedInput(one, sp.Integer(1), "-")))


def instantiate(model: ModelDefinition, params: ParameterSet, unknown_input_hint=None) -> LPVModel:
    """Substitute a parameter set into a model and extract its LPV matrices.

    ``unknown_input_hint(model, d, params, subs)``: the sentence a "not affine in the unknown inputs" error
    ends with, for the unknown input ``d`` (the pipeline passes
    :func:`codegen.representation.substitution.offer`: the change of variables that makes it affine, proven
    on the parameter file's boxes); None: the error without one.

    Raises
    ------
    MissingParameterError, UnknownParameterError, SchedulingBoundsError, NotAffineError
    """
    subs = parameter_substitution(model, params)
    missing = [str(sig.symbol) for sig in model.scheduling if str(sig.symbol) not in params.scheduling]
    if missing:
        raise SchedulingBoundsError(
            f"model {model.name!r}: scheduling signal(s) {', '.join(missing)} {'has' if len(missing) == 1 else 'have'} "
            f"no bounds in {params.source}: add " + "; ".join(f"[scheduling.{n}] with min, max, rate_min, rate_max"
                                                            for n in missing))
    boxes = [params.scheduling[str(sig.symbol)] for sig in model.scheduling]
    # structure is checked exactly, with the parameters still symbolic; numbers come after (floats
    # the model writes that differ only by rounding are one number: merge_float_noise)
    signals = (*model.states, *model.known_inputs, *model.unknown_inputs, *(g.symbol for g in model.scheduling),
               *(w.symbol for w in model.derived_inputs))
    # a term that is 0 (simplified, or cancelled once expanded) is no term: dropped before the parameters
    # are numbers, which would leave a residue of 1e-16 (a coupling, a premise, a feedthrough)
    rows = merge_float_noise(drop_zero_terms([*model.dynamics, *(expr for _, expr in model.outputs)], signals))
    f = sp.Matrix(rows[:len(model.states)])
    h = sp.Matrix(rows[len(model.states):])
    x, u, d = tuple(model.states), tuple(model.known_inputs), tuple(model.unknown_inputs)
    w = tuple(g.symbol for g in model.derived_inputs)
    A = _affine_part(f, x, "the states", model.name)
    B = _affine_part(f, u, "the known inputs", model.name)
    Bw = _affine_part(f, w, "the derived inputs", model.name)
    hint = None if unknown_input_hint is None else (lambda s: unknown_input_hint(model, s, params, subs))
    D = _affine_part(f, d, "the unknown inputs", model.name, hint=hint)
    C = _affine_part(h, x, "the states", model.name)
    Du = _affine_part(h, u, "the known inputs", model.name)
    Duw = _affine_part(h, w, "the derived inputs", model.name)
    Dd = _affine_part(h, d, "the unknown inputs", model.name, hint=hint)
    col = lambda syms: sp.Matrix(len(syms), 1, list(syms))   # a (k, 1) column, also for k = 0
    # what is left once the affine parts are taken, in exact arithmetic: the model's floats as the exact
    # rationals they are (sympy's simplify on floats inside a denominator, 1/(v_x + 1.1), leaves a
    # residue of 1e-12 where the exact difference is 0), back to floats for the column it may become
    exact = {v: sp.Rational(v) for m in (f, h) for e in m for v in sp.sympify(e).atoms(sp.Float)}
    back = {r: v for v, r in exact.items()}
    ex = lambda m: m.xreplace(exact)          # noqa: E731
    rest = sp.simplify(ex(f) - ex(A) * col(x) - ex(B) * col(u) - ex(D) * col(d)
                       - (ex(Bw) * sp.Matrix(w) if w else sp.zeros(*f.shape))).xreplace(back) if x else f
    h_rest = sp.simplify(ex(h) - ex(C) * col(x) - ex(Du) * col(u) - ex(Dd) * col(d)
                         - (ex(Duw) * sp.Matrix(w) if w else sp.zeros(*h.shape))).xreplace(back)
    if any(sp.simplify(e) != 0 for e in (*rest, *h_rest)):
        if not x or any(_is_constant(w) for w in model.derived_inputs):
            raise NotAffineError(f"model {model.name!r}: dynamics or outputs have a term independent of states and "
                                 f"inputs that is left over: {list(rest)}, {list(h_rest)}")
        # a term free of states and inputs (rolling resistance -f_r g, a drag c v_x^2 of a scheduling
        # signal) is a known input of value 1: its column is the term, its value computed in the step
        return instantiate(constant_terms_as_input(model, rest, h_rest), params, unknown_input_hint)
    for mat, label in ((B, "B"), (D, "D"), (C, "C"), (Du, "Du"), (Bw, "Bw"), (Duw, "Duw"), (Dd, "Dd")):
        if any(e.free_symbols & set(x + u + d + w) for e in mat):
            raise NotAffineError(f"model {model.name!r}: {label} depends on states or inputs")
    # an unknown input's coefficient in an output that is 0 once simplified is no feedthrough (decided
    # exactly here, with the parameters symbolic: a float residue of 1e-17 after substitution is not 0)
    Dd = Dd.applyfunc(lambda e: e if _nonzero(e) else sp.S.Zero)
    A, B, D, C, Du, Bw, Duw, Dd = (m.subs(subs) for m in (A, B, D, C, Du, Bw, Duw, Dd))
    # and after the parameter values: one number computed in two orders (C_f / M and C_f * (1 / M))
    merged = merge_float_noise([e for m in (A, B, D, C, Du, Bw, Duw, Dd) for e in m])
    sizes = [len(m) for m in (A, B, D, C, Du, Bw, Duw, Dd)]
    A, B, D, C, Du, Bw, Duw, Dd = (sp.Matrix(m.shape[0], m.shape[1], merged[sum(sizes[:k]):sum(sizes[:k + 1])])
                                   for k, m in enumerate((A, B, D, C, Du, Bw, Duw, Dd)))
    sched = tuple(sig.symbol for sig in model.scheduling)
    allowed = set(sched)
    for mat, label in ((A, "A"), (B, "B"), (D, "D"), (C, "C"), (Du, "Du"), (Bw, "Bw"), (Duw, "Duw"), (Dd, "Dd")):
        stray = set().union(*(e.free_symbols for e in mat)) - allowed if len(mat) else set()
        if stray:
            raise ModelDefinitionError(
                f"model {model.name!r}: {label} depends on {', '.join(sorted(map(str, stray)))}, "
                f"which is neither a parameter nor a scheduling signal")
    derived = tuple((g.symbol, sp.sympify(g.derived).subs(subs)) for g in model.scheduling if g.derived is not None)
    derived_inputs = tuple((g.symbol, sp.sympify(g.expr).subs(subs)) for g in model.derived_inputs)
    return LPVModel(model, params, A, B, D, C, sched, tuple(boxes), Du, derived, Bw, Duw, derived_inputs, Dd)
