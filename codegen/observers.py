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

OBSERVERS_DIR = PARAMS_DIR.parent / "observers"
FAMILIES = ("linf_uio", "ts_fuzzy_uio", "switched_pi", "algebraic_uio", "interconnected_uio")


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
    required = ("family", "model", "parameters", "sample_time") + \
        (("polytope",) if data.get("family") == "linf_uio" else ())
    missing = [k for k in required if k not in data]
    if missing:
        raise ModelDefinitionError(f"{path}: missing {', '.join(missing)}")
    if data["family"] not in FAMILIES:
        raise ModelDefinitionError(f"{path}: unknown family {data['family']!r} (known: {', '.join(FAMILIES)})")
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
