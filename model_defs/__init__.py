"""Vehicle models, written once symbolically, and their parameter files.

Each model module exposes ``MODEL`` (a :class:`codegen.model.ModelDefinition`);
numeric values live in ``params/*.toml``.
"""
from pathlib import Path

PARAMS_DIR = Path(__file__).resolve().parent / "params"
