"""Vehicle models, written once symbolically, and their parameter files.

Each observer model module exposes ``MODEL`` (a :class:`codegen.model.ModelDefinition`);
numeric values live in ``params/*.toml``. ``baselines.py`` holds the symbolic models the
Kalman-filter baselines are generated from (:mod:`codegen.validation.kalman`).
"""
from pathlib import Path

PARAMS_DIR = Path(__file__).resolve().parent / "params"
