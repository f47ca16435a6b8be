"""Observer configurations: data files, built-in (``model_defs/observers/*.toml``) or anywhere on disk.

A configuration names the model, the parameter file, the family (:mod:`codegen.families`) and
the design settings of one observer; ``uiogen list`` shows the built-in ones. Adding an
observer for another car is a new TOML file, not new code.

A configuration outside the package (a user's project) may name its model and parameter file
by paths relative to its own folder (``model = "my_car.py"``: a module defining
``MODEL = ModelDefinition(...)``, exactly as in ``model_defs/``). Where its design lock, C and
extension go is its project's (:mod:`python_bindings.workspace`): its own folder, or the
``project`` given to :func:`get`.
"""
from __future__ import annotations

import dataclasses
import hashlib
import importlib
import importlib.util
import re
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ConfigurationError, ModelDefinitionError, UnknownObserverError
from ..model import ModelDefinition
from ..model.definition import check_unit_keys
from ..model.names import RULE as NAME_RULE, c_name_problem, suggest as suggest_name
from . import columns, model_reads, precision
from ..settings import Rule, config_error, parse_table, suggest, toml_error
from python_bindings.workspace import PACKAGE_ROOT, Workspace

MODELS_DIR = PACKAGE_ROOT / "model_defs"
PARAMS_DIR = MODELS_DIR / "params"
OBSERVERS_DIR = MODELS_DIR / "observers"

# Top level of an observer file: the keys every family reads; each family adds its own
# (Family.observer_keys). The [design] and [switching] tables are checked by the family's parser.
COMMON_KEYS = {
    "family": Rule(str, required=True, doc="an observer family (codegen.families)"),
    "model": Rule(str, required=True, doc="model_defs/MODEL.py, or a .py path relative to this file"),
    "parameters": Rule(str, required=True,
                       doc="a path relative to this file (a built-in observer: a file in model_defs/params)"),
    # a vehicle observer's step: 1 Hz (the slowest a vehicle-dynamics log is read at) to 100 kHz; beyond,
    # the design fails far from the cause (a gain bound of gain_bound_times_sample_time / sample_time)
    "sample_time": Rule(float, ge=1e-5, le=1.0, required=True, doc="s",
                        allowed="a finite number of seconds in [1e-05, 1] (a step at 1 Hz to 100 kHz)"),
    "design": Rule(dict),
    "data": Rule(dict, doc="the column map of a logged run (uiogen validate --data; codegen.project.columns)"),
    "precision": Rule(dict, doc="the float32 build's tolerances (codegen.project.precision)"),
    "substitute": Rule(dict, doc="{UNKNOWN_INPUT = \"NEW_NAME\"}: design for the value of the one expression an "
                                 "unknown input enters through (codegen.representation.substitution)"),
}


@dataclass(frozen=True)
class ObserverConfig:
    """One observer: model + parameters + representation + design settings."""

    name: str
    family: str
    model: str
    parameters: str
    polytope: str
    rate_bounds: str
    sample_time: float
    design: dict = field(default_factory=dict)
    ui_filter: dict = field(default_factory=dict)
    doc: str = ""
    source: str = ""
    switching: dict = field(default_factory=dict)     # switched families: the rule, as data

    project: str = ""       # its project folder (python_bindings.workspace); "" = the default rule
    # [data]: how a logged run's columns map onto the observer's inputs. Not part of to_json (so
    # not of the design hash): editing the map of a log never re-solves the design.
    column_map: object = None
    # [precision]: the float32 build's tolerances (codegen.project.precision); not part of the
    # design either.
    precision: object = None
    # [substitute]: unknown inputs designed for through the value of their carrier expression
    substitute: dict = field(default_factory=dict)

    @property
    def folder(self) -> Path:
        """The folder of the observer file (relative model and parameter paths start there)."""
        return Path(self.source).resolve().parent if self.source else OBSERVERS_DIR

    @property
    def builtin(self) -> bool:
        """A built-in observer (``model_defs/observers/NAME.toml``)."""
        return not self.source or Path(self.source).resolve().parent == OBSERVERS_DIR

    @property
    def command_name(self) -> str:
        """What a ``uiogen`` command takes to find this observer again: a built-in's name, else
        its file's path (a name resolves to the built-ins first)."""
        return self.name if self.builtin else self.source

    @property
    def workspace(self) -> Workspace:
        """The folders its generated files go to (:mod:`python_bindings.workspace`)."""
        if self.project:
            return Workspace(Path(self.project))
        return Workspace.for_observer_file(self.source, builtin=self.builtin)

    @property
    def model_path(self) -> Path:
        """The model's source file."""
        return _model_file(self.model, self.folder)

    @property
    def model_module(self) -> str:
        """Importable name of the model module (``model_defs.NAME`` for the built-in models)."""
        f = self.model_path
        if f.parent == MODELS_DIR:
            return f"model_defs.{f.stem}"
        return module_name(f)

    def load_model_module(self):
        return load_module(self.model_path, self.model_module)

    def load_definition(self):
        """The model file's ``MODEL`` as written: a :class:`~codegen.model.ModelDefinition`, or the
        definition of a family that needs more structure (an ``InterconnectedModelDefinition``:
        the states partitioned into subsystems). A family's ``build`` checks the class it takes."""
        module = self.load_model_module()
        model = getattr(module, "MODEL", None)
        if model is None:
            raise ModelDefinitionError(f"{self.model_path} does not define MODEL = ModelDefinition(...) (model of "
                                       f"observer file {self.source or self.name})")
        if not (isinstance(model, ModelDefinition) or callable(getattr(model, "as_model_definition", None))):
            raise ModelDefinitionError(f"{self.model_path}: MODEL is a {type(model).__name__}, not a "
                                       f"ModelDefinition(...) (codegen.model)")
        return model

    def load_model(self) -> ModelDefinition:
        """The model as one system of equations (:class:`~codegen.model.ModelDefinition`), the form
        every family-independent path reads (the excitation scenario, campaign plants, logs,
        conformance): ``MODEL`` itself, or ``MODEL.as_model_definition()`` for a family's richer
        definition (the same equations, its extra structure dropped)."""
        model = self.load_definition()
        return model if isinstance(model, ModelDefinition) else model.as_model_definition()

    def design_model(self) -> ModelDefinition:
        """The model the family designs with: :meth:`load_model`, with the unknown inputs of the
        ``[substitute]`` table replaced by the values of their carriers (:meth:`substitutions`)."""
        return self._substituted()[0]

    def substitutions(self) -> list:
        """[:class:`~codegen.representation.substitution.Substitution`] of the ``[substitute]`` table."""
        return self._substituted()[1]

    def _substituted(self) -> tuple:
        model = self.load_model()
        if not self.substitute:
            return model, []
        from ..model import load_parameters
        from ..model.definition import parameter_substitution
        from ..representation.substitution import apply
        params = load_parameters(self.parameter_path)
        return apply(model, params, parameter_substitution(model, params), self.substitute, self.source)

    @property
    def observer_family(self):
        """The observer's family (a :class:`~codegen.contract.family.Family`), the one this file names: the
        reader of the observer file resolves the name (:mod:`codegen.contract.registry`); every stage below
        is handed the family on the configuration, never looks it up."""
        from ..contract import registry
        return registry.get(self.family)

    @property
    def family_type(self) -> type:
        """The class of :attr:`observer_family` (what a design's stamp follows)."""
        return type(self.observer_family)

    @property
    def parameter_path(self) -> Path:
        return _parameter_file(self.parameters, self.folder)

    def to_json(self) -> dict:
        return {"name": self.name, "family": self.family, "model": self.model,
                "parameters": self.parameters, "polytope": self.polytope,
                "rate_bounds": self.rate_bounds, "sample_time": self.sample_time,
                "design": dict(self.design), "ui_filter": dict(self.ui_filter),
                **({"switching": self.switching} if self.switching else {}),
                **({"substitute": dict(self.substitute)} if self.substitute else {})}


def _model_file(model: str, folder: Path) -> Path:
    """``model``: a built-in module name (model_defs/NAME.py) or a .py path relative to ``folder``."""
    if model.endswith(".py") or "/" in model:
        return (folder / model).resolve()
    return MODELS_DIR / f"{model}.py"


def _parameter_file(parameters: str, folder: Path) -> Path:
    """A built-in observer's parameter file is the library's (``model_defs/params/NAME``); a user's
    observer file names its own, relative to its folder, and never a built-in of the same name: a
    project's file deleted or misspelt would otherwise design another car without a word, and a
    library file would change the user's design when uiogen is upgraded."""
    return PARAMS_DIR / parameters if folder == OBSERVERS_DIR else (folder / parameters).resolve()


def builtin_model(name: str):
    """A module of the built-in model library (``model_defs/NAME.py``), imported by name: the
    toolchain reads the library as data, as it reads a user's model from its file."""
    return load_module(MODELS_DIR / f"{name}.py", f"model_defs.{name}")


_READS: dict = {}       # {module name: the files it read when imported}


def module_name(path: Path) -> str:
    """The importable name of a user's model file: one per file (its path in the name's hash)."""
    return f"uiogen_user_model_{hashlib.sha256(str(path).encode()).hexdigest()[:12]}_{path.stem}"


def load_base(model_file, base: str):
    """The model module a model file builds on: ``base`` (its ``BASE_MODEL``, a path relative to the folder
    of ``model_file``, or absolute), loaded once per process under its own name (:func:`module_name`)."""
    path = (Path(model_file).resolve().parent / base).resolve()
    if not path.is_file():
        raise ModelDefinitionError(f"{model_file}: BASE_MODEL = {str(base)!r}: there is no file {path} (the model "
                                   f"file this one builds on, relative to its folder); allowed: the path of that "
                                   f"file (a project moved without it: move it along, or correct the path)")
    return load_module(path, module_name(path))


def load_module(path: Path, name: str):
    """Import a model module from its file (once per process; built-in models by their package name). What
    it read is kept with it (:mod:`.model_reads`): a model that loads it again counts those files too."""
    if name in sys.modules:
        model_reads.replay(_READS.get(name, ()))
        return sys.modules[name]
    if name.startswith("model_defs."):
        return importlib.import_module(name)
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ModelDefinitionError(f"cannot import a model from {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        with model_reads.watching(path) as reads:
            spec.loader.exec_module(module)
        with model_reads.unwatched():
            model_reads.check(path, reads)
            if isinstance(getattr(module, "MODEL", None), ModelDefinition):
                check_unit_keys(module.MODEL)
        _READS[name] = tuple(reads)
    except ModelDefinitionError as exc:
        del sys.modules[name]
        # a check of ModelDefinition itself (a field of the wrong type, a misspelt units key): name the file
        if exc.args and isinstance(exc.args[0], str) and str(path) not in exc.args[0]:
            exc.args = (f"{path}: {exc.args[0]}", *exc.args[1:])
        raise
    except Exception as exc:       # a user's module that does not run: say where, keep the cause
        del sys.modules[name]
        raise ModelDefinitionError(f"{path}: importing the model failed: {type(exc).__name__}: {exc}") from exc
    except SystemExit as exc:      # sys.exit() in a model file must not end (or succeed) the command
        del sys.modules[name]
        raise ModelDefinitionError(f"{path}: importing the model called sys.exit({exc.code!r}); a model file "
                                   f"defines MODEL = ModelDefinition(...) and returns") from None
    return module


def apply_overrides(data: dict, overrides: dict, source: str) -> dict:
    """A copy of an observer file's table with ``{"design.pole_radius": 50.0, ...}`` set in it.

    The dotted key names a table path inside the file; a missing table is created. The result
    goes through the same checks as the file itself, so a misspelt key or a value out of range is
    the same typed error, naming the file and the key.
    """
    import copy
    data = copy.deepcopy(data)
    for key, value in overrides.items():
        parts = key.split(".")
        if not all(parts):
            raise config_error(source, None, key, value, "a dotted key such as design.alpha")
        table = data
        for i, part in enumerate(parts[:-1]):
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise config_error(source, None, key, value, f"{'.'.join(parts[:i + 1])} is not a table")
        table[parts[-1]] = value
    return data


MAX_NAME_LENGTH = 64
"""Longest observer name: the name prefixes every identifier of its C API and names its
extension module (``_NAME``); C99 guarantees 63 significant characters of an identifier, and
names of up to 64 characters build and load (a 200-character one did not)."""


def check_name(name: str, source: str) -> str:
    """The observer's name (its file's stem) as the C identifier that prefixes its C API and
    names its extension, checked before anything is designed.

    Raises
    ------
    ConfigurationError
        not a C identifier (``my obs``, ``1abc``, ``my-obs``), a C keyword, or longer than
        :data:`MAX_NAME_LENGTH`.
    """
    why = c_name_problem(name)
    if why is None and len(name) > MAX_NAME_LENGTH:
        why = f"has {len(name)} characters"
    if why is None:
        return name
    raise ConfigurationError(
        f"{source}: the observer's name {name!r} (the file's name) {why}; allowed: {NAME_RULE}, at most "
        f"{MAX_NAME_LENGTH} characters (it prefixes the observer's C functions and CasADi functions and names its "
        f"extension): rename the file, e.g. {_suggest_name(name)}.toml", source=source, key="name", value=name,
        allowed=f"a C identifier of at most {MAX_NAME_LENGTH} characters ({NAME_RULE})")


def _suggest_name(name: str) -> str:
    s = suggest_name(name)
    return (s if s != "signal" else "my_observer")[:MAX_NAME_LENGTH].rstrip("_")


def _parse(path: Path, overrides: dict | None = None, project: str | Path | None = None) -> ObserverConfig:
    from ..contract import registry
    path = Path(path)
    from . import outputs           # a `uiogen fit --write` killed half-way: its files all new, first
    outputs.finish_pending(path, log=lambda text: print(f"uiogen: {text}", file=sys.stderr))
    if path.is_dir():
        raise UnknownObserverError(f"{path} is a folder, not an observer file: name the .toml file in it")
    try:
        # utf-8-sig: a byte-order mark (Windows editors write one) is read past, as load's hash does
        data = tomllib.loads(path.read_bytes().decode("utf-8-sig"))
    except FileNotFoundError:
        raise UnknownObserverError(f"no observer file {path}") from None
    except tomllib.TOMLDecodeError as exc:
        raise toml_error(str(path), path.read_text(encoding="utf-8", errors="replace"), exc) from None
    except UnicodeDecodeError as exc:
        raise ModelDefinitionError(f"{path}: not UTF-8 text: {exc}") from None
    source = str(path)
    check_name(path.stem, source)
    if overrides:
        data = apply_overrides(data, overrides, source)
    known = registry.names()
    if "family" not in data:
        raise config_error(source, None, "family", None, f"missing; one of {', '.join(known)}")
    parse_table({"family": data["family"]}, {"family": Rule(str, choices=known, required=True)}, source=source)
    family = registry.get(data["family"])
    parse_table(data, {**COMMON_KEYS, **family.observer_keys}, source=source, what=f"for family {family.name}")
    builtin = path.resolve().parent == OBSERVERS_DIR
    folder = path.resolve().parent
    model_file = _model_file(data["model"], folder)
    if not model_file.is_file():
        models = sorted(p.stem for p in MODELS_DIR.glob("*.py") if not p.stem.startswith("_"))
        raise config_error(source, None, "model", data["model"],
                           f"no model file {model_file}; built-in models: {', '.join(models)} (or a .py path "
                           f"relative to {folder})", suggest(data["model"], models))
    param_file = _parameter_file(data["parameters"], folder)
    if param_file.is_dir():
        raise config_error(source, None, "parameters", data["parameters"],
                           f"{param_file} is a folder; name a parameter .toml file (a path relative to {folder})")
    if not param_file.is_file():
        if builtin:
            files = sorted(p.name for p in PARAMS_DIR.glob("*.toml"))
            raise config_error(source, None, "parameters", data["parameters"],
                               f"no file {param_file}; built-in parameter files: {', '.join(files)}",
                               suggest(data["parameters"], files))
        library = PARAMS_DIR / Path(str(data["parameters"])).name
        files = sorted(p.name for p in folder.glob("*.toml") if p.resolve() != path.resolve())
        hint = (f"; the built-in parameter file of that name is {library}: to start from it, copy it beside the "
                f"observer file (cp {library} {folder}/)" if library.is_file() else "")
        raise config_error(source, None, "parameters", data["parameters"],
                           f"no file {param_file} (a path relative to {folder}: an observer file of your own names "
                           f"its own parameter file, never a built-in one){hint}", suggest(data["parameters"], files))
    doc = ""
    with path.open(encoding="utf-8-sig") as fh:
        for line in fh:
            if not line.startswith("#"):
                break
            text = line.lstrip("# ").rstrip()
            if not HINT_LINE.match(text):          # the description, not the starter's commands
                doc += text + " "
    config = ObserverConfig(path.stem, data["family"], data["model"], data["parameters"], data.get("polytope", ""),
                            data.get("rate_bounds", "exact"), float(data["sample_time"]),
                            dict(data.get("design", {})), dict(data.get("ui_filter", {})), doc.strip(), str(path),
                            dict(data.get("switching", {})),
                            str(Workspace.for_observer_file(path, project, builtin).root),
                            columns.parse(data["data"], source) if "data" in data else None,
                            precision.parse(data.get("precision"), source),
                            dict(data.get("substitute", {})))
    family.check_config(config, data)
    return config


#: a line of an observer file's header comment that is a command or a hint for its user (what
#: ``uiogen new`` writes: ``next: uiogen design ...``, notes, the trial design's outcome), not part
#: of the description the generated C, its header and the FMU carry
HINT_LINE = re.compile(r"^(next:|then:|note:|uiogen |trial design by uiogen|WARNING:)")


def names() -> list:
    """The built-in observers (``model_defs/observers/*.toml``)."""
    return sorted(p.stem for p in OBSERVERS_DIR.glob("*.toml"))


def is_path(name: str) -> bool:
    return name.endswith(".toml") or "/" in name


def get(name, overrides: dict | None = None, project: str | Path | None = None) -> ObserverConfig:
    """A built-in observer by name, or an observer file by path (``.toml``, anywhere on disk); a
    configuration is returned as it is.

    ``overrides`` (dotted key -> value, :func:`apply_overrides`) changes settings of the file as
    read, for studies such as ``uiogen sweep``; the file on disk is not touched. ``project``: the
    project folder its generated files go to, instead of the default
    (:meth:`python_bindings.workspace.Workspace.for_observer_file`).
    """
    if isinstance(name, ObserverConfig):
        if overrides:
            raise TypeError("overrides apply to an observer file as read; got a configuration")
        return name if project is None else dataclasses.replace(name, project=str(Workspace.of(project).root))
    if is_path(str(name)):
        return _parse(Path(name), overrides, project)
    path = OBSERVERS_DIR / f"{name}.toml"
    if not path.is_file():
        raise UnknownObserverError(f"no observer named {name!r}; known: {', '.join(names()) or 'none'} "
                                   f"(or give the path of an observer .toml file)")
    return _parse(path, overrides, project)
