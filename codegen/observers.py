"""Observer configurations: data files in ``model_defs/observers/*.toml``.

A configuration names the model module, the parameter file, the representation
and the design settings of one observer; ``uiogen list`` shows them all. Adding
an observer for another car is a new TOML file, not new code.
"""
from __future__ import annotations

import importlib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from model_defs import PARAMS_DIR

from .errors import ModelDefinitionError, UnknownObserverError
from .model import ModelDefinition
from .settings import Rule, config_error, parse_table, suggest

OBSERVERS_DIR = PARAMS_DIR.parent / "observers"
MODELS_DIR = PARAMS_DIR.parent
FAMILIES = ("linf_uio", "ts_fuzzy_uio", "switched_pi", "algebraic_uio", "interconnected_uio")

# Top level of an observer file: the keys every family reads, and those only some families read.
# The [design] and [switching] tables are checked by the family's own parser (codegen.settings).
COMMON_KEYS = {
    "family": Rule(str, choices=FAMILIES, required=True),
    "model": Rule(str, required=True, doc="module model_defs/MODEL.py"),
    "parameters": Rule(str, required=True, doc="file in model_defs/params"),
    "sample_time": Rule(float, gt=0, required=True, doc="s"),
    "design": Rule(dict),
}
FAMILY_KEYS = {
    "linf_uio": {"polytope": Rule(str, choices=("taylor_reduced", "sector"), required=True),
                 "rate_bounds": Rule(str, choices=("exact", "at_expansion_point", "none")),
                 "ui_filter": Rule(dict)},
    "ts_fuzzy_uio": {},
    "switched_pi": {"switching": Rule(dict)},
    "algebraic_uio": {"validation": Rule(dict)},       # scenarios, read by codegen.validation.algebraic
    "interconnected_uio": {},
}
UI_FILTER_KEYS = {"time_constant": Rule(float, gt=0, doc="T_f of the UI filter, s")}


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

    def load_model(self) -> ModelDefinition:
        try:
            module = importlib.import_module(f"model_defs.{self.model}")
        except ModuleNotFoundError:
            raise ModelDefinitionError(f"observer {self.name!r}: no model module model_defs/{self.model}.py") from None
        model = getattr(module, "MODEL", None)
        if not isinstance(model, ModelDefinition):
            raise ModelDefinitionError(f"model_defs/{self.model}.py does not define MODEL = ModelDefinition(...)")
        return model

    @property
    def parameter_path(self) -> Path:
        return PARAMS_DIR / self.parameters

    def to_json(self) -> dict:
        return {"name": self.name, "family": self.family, "model": self.model,
                "parameters": self.parameters, "polytope": self.polytope,
                "rate_bounds": self.rate_bounds, "sample_time": self.sample_time,
                "design": dict(self.design), "ui_filter": dict(self.ui_filter),
                **({"switching": self.switching} if self.switching else {})}


def _parse(path: Path) -> ObserverConfig:
    with path.open("rb") as fh:
        try:
            data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise ModelDefinitionError(f"{path}: not valid TOML: {exc}") from None
    source = str(path)
    if "family" not in data:
        raise ModelDefinitionError(f"{path}: missing family (one of {', '.join(FAMILIES)})")
    parse_table({"family": data["family"]}, {"family": COMMON_KEYS["family"]}, source=source)
    family = data["family"]
    parse_table(data, {**COMMON_KEYS, **FAMILY_KEYS[family]}, source=source, what=f"for family {family}")
    parse_table(data.get("ui_filter", {}), UI_FILTER_KEYS, source=source, section="ui_filter")
    models = sorted(p.stem for p in MODELS_DIR.glob("*.py") if not p.stem.startswith("_"))
    if data["model"] not in models:
        raise config_error(source, None, "model", data["model"], f"no module model_defs/{data['model']}.py; "
                           f"known: {', '.join(models)}", suggest(data["model"], models))
    if not (PARAMS_DIR / data["parameters"]).is_file():
        files = sorted(p.name for p in PARAMS_DIR.glob("*.toml"))
        raise config_error(source, None, "parameters", data["parameters"], f"no file {PARAMS_DIR / data['parameters']}; "
                           f"known: {', '.join(files)}", suggest(data["parameters"], files))
    doc = ""
    with path.open() as fh:
        for line in fh:
            if line.startswith("#"):
                doc += line.lstrip("# ").rstrip() + " "
            else:
                break
    return ObserverConfig(path.stem, data["family"], data["model"], data["parameters"], data.get("polytope", ""),
                          data.get("rate_bounds", "exact"), float(data["sample_time"]),
                          dict(data.get("design", {})), dict(data.get("ui_filter", {})), doc.strip(), str(path),
                          dict(data.get("switching", {})))


def names() -> list:
    return sorted(p.stem for p in OBSERVERS_DIR.glob("*.toml"))


def get(name: str) -> ObserverConfig:
    path = OBSERVERS_DIR / f"{name}.toml"
    if not path.is_file():
        raise UnknownObserverError(f"no observer named {name!r}; known: {', '.join(names()) or 'none'}")
    return _parse(path)
