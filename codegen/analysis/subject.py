"""What ``uiogen analyze`` looks at: a model, its parameter file, the outputs taken as measured and
the inputs taken as unknown (:class:`Subject`), from a built-in observer name, an observer file
or a model file.

An observer file brings its model, its parameter file and its sample time; a model file needs a
parameter file (``--parameters``). ``--outputs`` picks the measured outputs among those the model
declares (the others are sensors the car could have: the analysis proposes them as fixes), and
``--unknown-inputs`` the unknown inputs among the model's known and unknown inputs (the rest are
known). An unknown input that enters only through one nonlinear expression (``g sin(phi_r)``) is
analyzed through that expression's value, as an observer file's ``[substitute]`` table has the
family design it: the file's own table, else the one the analysis finds and proves
(:func:`codegen.representation.substitution.propose`), applied by the same
:func:`codegen.representation.substitution.apply`. Nothing here writes a file.
"""
from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import sympy as sp

from ..errors import ConfigurationError, ModelDefinitionError, NotAffineError
from ..model import ParameterSet, load_parameters, parameter_substitution
from ..project import observer_file as observers
from ..settings import suggest

#: sample time of the analysis (TS discretization, trial designs) when no observer file gives one
DEFAULT_SAMPLE_TIME = 0.01


@dataclass(frozen=True)
class Equations:
    """The model in the one form every structural fact is computed from.

    ``x' = f(x, u, d)``, ``y = h(x, u, d)`` with the parameters substituted; ``box`` bounds the
    signals the Jacobians may depend on (scheduling signals, ``[state_bounds]``, ``[inputs]``);
    ``fixed`` holds signals set to nominal values (exogenous inputs).
    """

    states: tuple
    known: tuple
    unknown: tuple
    outputs: tuple          # names, in the order of h
    f: sp.Matrix
    h: sp.Matrix
    box: dict               # {symbol: (lo, hi)}
    fixed: dict             # {symbol: value}
    box_source: dict        # {symbol: "[scheduling.v_x]" | "[state_bounds]" | ...}


@dataclass(frozen=True)
class Subject:
    """A model with its parameters, the measured outputs and the unknown inputs to analyze.

    Attributes
    ----------
    target : str
        What was named on the command line.
    model : object
        The model definition (``MODEL`` of the model file): a
        :class:`~codegen.model.ModelDefinition`, or another family's model class.
    model_path, parameter_path : Path
    parameters : ParameterSet
    config : ObserverConfig or None
        The observer file, when one was named (its family's own settings are tried as written).
    sample_time : float
    selected : dict
        ``{"outputs": names or None, "unknown_inputs": names or None}``: what ``--outputs`` and
        ``--unknown-inputs`` changed (None: as declared).
    declared_outputs : tuple
        Every output the model file declares (those not measured are candidate sensors).
    """

    target: str
    model: object
    model_path: Path
    parameters: ParameterSet
    parameter_path: Path
    config: object
    sample_time: float
    selected: dict
    declared_outputs: tuple
    base_model: object
    module: object = None
    substitutions: tuple = ()       # [substitute] applied: Substitution, one per unknown input replaced
    substitution_origin: str = ""   # "the observer file" | "the analysis" (when substitutions)
    substitution_refusals: dict = dataclasses.field(default_factory=dict)  # {unknown input: why no change}

    @property
    def model_module(self):
        """The model file's module with ``MODEL`` as analyzed (families that read more of the
        module than ``MODEL``, such as tyre descriptions, see the chosen sensors too)."""
        import types
        return types.SimpleNamespace(**{**vars(self.module), "MODEL": self.model})

    # -- names ------------------------------------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.model.name

    @property
    def states(self) -> tuple:
        return tuple(str(s) for s in self.model.states)

    @property
    def outputs(self) -> tuple:
        return tuple(n for n, _ in self.model.outputs)

    @property
    def unknown_inputs(self) -> tuple:
        return tuple(str(s) for s in self.model.unknown_inputs)

    @property
    def known_inputs(self) -> tuple:
        return tuple(str(s) for s in getattr(self.model, "known_inputs", ()))

    @property
    def units(self) -> dict:
        return dict(getattr(self.model, "units", {}) or {})

    def unit(self, name: str) -> str:
        return self.units.get(name, "-")

    @property
    def substitute_table(self) -> dict:
        """The ``[substitute]`` table of what is analyzed ({unknown input: new name}), {} if none."""
        return {str(sub.unknown): str(sub.symbol) for sub in self.substitutions}

    @property
    def declared_unknown_inputs(self) -> tuple:
        """The unknown inputs in the model's own names (a substituted one by its own name, not its
        carrier's)."""
        back = {str(sub.symbol): str(sub.unknown) for sub in self.substitutions}
        return tuple(back.get(n, n) for n in self.unknown_inputs)

    @property
    def restricted(self) -> bool:
        """Whether ``--outputs``/``--unknown-inputs`` changed the model as declared."""
        return any(v is not None for v in self.selected.values())

    @property
    def sample_time_source(self) -> str:
        return "the observer file" if self.config is not None else "the analysis default (no observer file)"

    @property
    def is_builtin_model(self) -> bool:
        return self.model_path.parent == observers.MODELS_DIR

    def equation_text(self, state: str, limit: int = 160) -> str:
        """The model's own right-hand side of d(state)/dt, as written (parameters by name)."""
        names = self.states
        rhs = (self.model.rhs[self.model.states[names.index(state)]] if hasattr(self.model, "rhs")
               else self.model.dynamics[names.index(state)])
        text = str(rhs)
        return text if len(text) <= limit else text[:limit - 3] + "..."

    def unmeasured_declared_outputs(self) -> tuple:
        """Outputs the model declares that ``--outputs`` left out: sensors the car could add."""
        return tuple(n for n in self.declared_outputs if n not in self.outputs)

    # -- the equations --------------------------------------------------------------------------------
    @property
    def lpv(self):
        """:func:`codegen.model.instantiate` of the model, once for every family that asks (its typed
        error, NotAffineError and the like, is raised again on every ask, without deriving it again)."""
        value, error = self._lpv_outcome
        if error is not None:
            raise error
        return value

    @cached_property
    def _lpv_outcome(self) -> tuple:
        from ..errors import UiogenError
        from ..model import instantiate
        from ..representation.substitution import offer
        try:
            return instantiate(self.model, self.parameters, unknown_input_hint=offer), None
        except UiogenError as exc:
            return None, exc

    @cached_property
    def equations(self) -> Equations:
        return equations_of(self.model, self.parameters)

    def with_outputs(self, extra: tuple) -> "Subject":
        """The same subject with more measured outputs: ``extra`` are (name, sympy expression) pairs
        (a state measured directly, or a declared output left out), for "what if" checks."""
        model = dataclasses.replace(self.model, outputs=tuple(self.model.outputs) + tuple(extra))
        return dataclasses.replace(self, model=model)


EQUATIONS = "analysis_equations"
"""The kind of the kept :class:`Equations` (:func:`codegen.model.cache.remembered`): the parameters put into a
model's equations give the same expressions every run (sympy re-evaluating its tyre laws' Min/Max with the
numbers in is seconds, on every ``analyze``)."""


def equations_of(model, params: ParameterSet) -> Equations:
    """The :class:`Equations` of a model definition with its parameter file.

    A model that splits its states into subsystems (``subsystems``, ``rhs``, ``exogenous``,
    ``switched``: the interconnected vehicle of Sentouh et al. 2023) is read as one system: its
    switched signals by their definitions, its exogenous inputs at their nominal values
    (``[exogenous]``). Kept across runs, keyed by the model's content, the parameter set as read and
    the parameter file's bytes (its ``[exogenous]`` table), with this module's code.
    """
    import sys

    from ..model import cache
    parameter_file = Path(params.source)
    parts = {"model": cache.model_digest(model), "parameters": cache.canonical(params),
             "file": hashlib.sha256(parameter_file.read_bytes()).hexdigest() if parameter_file.is_file() else None}
    return cache.remembered(EQUATIONS, parts, lambda: _equations_of(model, params), sys.modules[__name__])


def _equations_of(model, params: ParameterSet) -> Equations:
    subs = parameter_substitution(model, params)
    states = tuple(model.states)
    unknown = tuple(model.unknown_inputs)
    fixed = {}
    if hasattr(model, "subsystems"):
        import tomllib
        with open(params.source, "rb") as fh:
            exo = tomllib.load(fh).get("exogenous", {})
        fixed = {e: float(exo.get(str(e), 0.0)) for e in model.exogenous}
        switched = {w.symbol: sp.sympify(w.definition).subs(subs) for w in model.switched}
        rhs = model.rhs
        f = sp.Matrix([sp.sympify(rhs[s]).subs(subs).subs(switched).subs(fixed) for s in states])
        known = ()
    else:
        f = sp.Matrix(model.dynamics).subs(subs)
        known = tuple(model.known_inputs) + tuple(w.symbol for w in getattr(model, "derived_inputs", ()))
    h = sp.Matrix([sp.sympify(e).subs(subs).subs(fixed) for _, e in model.outputs]) if model.outputs \
        else sp.zeros(0, 1)
    box, where = {}, {}
    for sig in getattr(model, "scheduling", ()):
        b = params.scheduling.get(str(sig.symbol))
        if b is not None:
            box[sig.symbol] = (b.lower, b.upper)
            where[sig.symbol] = f"[scheduling.{sig.symbol}]"
    for s in (*states, *known, *unknown):
        if s in box:
            continue
        if str(s) in params.state_bounds:
            box[s] = tuple(params.state_bounds[str(s)])
            where[s] = f"[state_bounds] {s}"
        elif str(s) in params.inputs:
            box[s] = (params.inputs[str(s)]["min"], params.inputs[str(s)]["max"])
            where[s] = f"[inputs.{s}]"
    return Equations(states, known, unknown, tuple(n for n, _ in model.outputs), f, h, box, fixed, where)


def _names(values, allowed, what: str, option: str) -> tuple:
    """Names given to ``--outputs``/``--unknown-inputs``, checked against what the model declares."""
    out = []
    for v in values:
        for name in (p.strip() for p in str(v).split(",")):
            if not name:
                continue
            if name not in allowed:
                raise ConfigurationError(
                    f"{option} {name}: not {what} of the model (declared: {', '.join(allowed) or 'none'})"
                    + (f"; did you mean {suggest(name, allowed)!r}?" if suggest(name, allowed) else ""),
                    key=option, value=name, allowed=", ".join(allowed))
            if name not in out:
                out.append(name)
    if not out:
        raise ConfigurationError(f"{option}: give at least one name", key=option)
    return tuple(out)


def _load_model(path: Path):
    """``MODEL`` of a model file (built-in or anywhere on disk)."""
    if not path.is_file():
        raise ConfigurationError(f"no model file {path}", source=str(path))
    if path.parent == observers.MODELS_DIR:
        module = observers.builtin_model(path.stem)
    else:
        module = observers.load_module(path, observers.module_name(path))
    model = getattr(module, "MODEL", None)
    if model is None or not hasattr(model, "states") or not hasattr(model, "outputs"):
        raise ModelDefinitionError(f"{path} does not define MODEL = ModelDefinition(...)")
    return module, model


def load(target: str, parameters: str | None = None, outputs=None, unknown_inputs=None) -> Subject:
    """The :class:`Subject` named by ``target``: a built-in observer name, an observer file
    (``.toml``) or a model file (``.py``, with ``parameters``).

    Raises
    ------
    ConfigurationError
        A model file without a parameter file, an output or input name the model does not declare.
    UnknownObserverError, ModelDefinitionError
        No such observer or model, a model that does not load.
    """
    config = None
    text = str(target)
    if text.endswith(".py"):
        model_path = Path(text).resolve()
        if parameters is None:
            raise ConfigurationError(
                f"{text}: a model file needs its parameter file to be numeric: uiogen analyze {text} --parameters "
                f"FILE.toml (or analyze an observer file that names both)", source=text, key="--parameters")
        sample_time = DEFAULT_SAMPLE_TIME
    else:
        config = observers.get(text)
        model_path = config.model_path
        sample_time = config.sample_time
    param_path = Path(parameters).resolve() if parameters is not None else config.parameter_path
    if not param_path.is_file():
        raise ConfigurationError(f"--parameters {parameters}: no file {param_path}", source=str(param_path),
                                 key="--parameters")
    module, base = _load_model(model_path)
    params = load_parameters(param_path)
    selected = {"outputs": None, "unknown_inputs": None}
    if unknown_inputs:
        if not hasattr(base, "known_inputs"):
            raise ConfigurationError(f"--unknown-inputs: model {base.name!r} declares no known inputs (it is a "
                                     f"{type(base).__name__}); its unknown inputs are fixed by the model",
                                     key="--unknown-inputs")
        inputs = (*base.known_inputs, *base.unknown_inputs)
        names = _names(unknown_inputs, [str(s) for s in inputs], "an input", "--unknown-inputs")
        base = dataclasses.replace(base, known_inputs=tuple(s for s in inputs if str(s) not in names),
                                   unknown_inputs=tuple(s for s in inputs if str(s) in names))
        selected["unknown_inputs"] = names
    base, params, subs, origin, refused = _substituted(base, params, config, parameters)
    model = base
    declared = tuple(n for n, _ in base.outputs)
    if outputs:
        names = _names(outputs, declared, "an output", "--outputs")
        model = dataclasses.replace(model, outputs=tuple(o for o in base.outputs if o[0] in names))
        selected["outputs"] = names
    return Subject(text, model, model_path, params, param_path, config, sample_time, selected, declared, base,
                   module, tuple(subs), origin, refused)


def _substituted(model, params: ParameterSet, config, parameters) -> tuple:
    """(model, params, [Substitution], origin, {unknown input: why not}): ``model`` with the unknown
    inputs that enter through a nonlinearity replaced by their carriers' values, through
    :func:`codegen.representation.substitution.apply`, the code path of an observer file's ``[substitute]``:
    the observer file's own table when it has one, else the table
    :func:`codegen.representation.substitution.propose` finds (each carrier proven invertible on the box),
    the inputs it cannot replace with the reason. ``params`` gains the range each carrier takes on
    the box, the box of the new unknown input. A model that is not a ModelDefinition (a family's
    richer definition) is analyzed as it is, an observer file's table applied as the family does."""
    from ..model import ModelDefinition
    from ..representation import substitution as substitution_rules
    if config is not None and config.substitute and parameters is None and not isinstance(model, ModelDefinition):
        model, subs = config.design_model(), config.substitutions()
        return model, _with_carrier_ranges(params, subs), subs, "the observer file", {}
    if not isinstance(model, ModelDefinition):
        return model, params, [], "", {}
    values = parameter_substitution(model, params)
    if config is not None and config.substitute:
        names = {str(u) for u in model.unknown_inputs}
        table = {k: v for k, v in config.substitute.items() if k in names}   # --unknown-inputs may drop one
        source, origin, refused = config.source, "the observer file", {}
    else:
        table, refused = substitution_rules.propose(model, params, values)
        source, origin = f"uiogen analyze {params.source}", "the analysis"
    if origin == "the observer file":
        model, subs = substitution_rules.apply(model, params, values, table, source)
    else:                       # one at a time: an input the change leaves in the equations is a refusal
        subs = []
        for key, name in table.items():
            try:
                model, done = substitution_rules.apply(model, params, values, {key: name}, source)
            except NotAffineError as exc:
                refused[key] = str(exc).removeprefix(f"{source}: [substitute] {key}: ")
                continue
            subs += done
    if not subs:
        return model, params, [], "", refused
    return model, _with_carrier_ranges(params, subs), subs, origin, refused


def _with_carrier_ranges(params: ParameterSet, subs) -> ParameterSet:
    """``params`` with the range each substituted carrier takes on the box as the [inputs] box of its
    new unknown input (the other keys, a bandwidth, those of the input it replaces)."""
    inputs = dict(params.inputs)
    for sub in subs:
        inputs[str(sub.symbol)] = {**inputs.get(str(sub.unknown), {}), "min": sub.lower, "max": sub.upper}
    return dataclasses.replace(params, inputs=inputs)
