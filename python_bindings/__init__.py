"""Thin Python API over the compiled observer steps.

>>> from python_bindings import load
>>> obs = load("lpv_linf_driver_torque")
>>> state = obs.initial_state()
>>> out = np.empty(obs.n_output)
>>> status = obs.step(state, inputs, out)       # one sample, in place, C speed
>>> outputs, status, final = obs.run(inputs_2d)  # whole array, loop in C

``step`` is the C function itself (no Python wrapper on the hot path); it checks
shapes and dtypes and raises TypeError/ValueError on bad arrays.
"""
from __future__ import annotations

import importlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from codegen.errors import SampleError, UnknownObserverError

HERE = Path(__file__).resolve().parent
GENERATED_DIR = HERE.parent / "generated_c"


@dataclass(frozen=True)
class CompiledObserver:
    """A compiled observer step and the names of its vectors."""

    name: str
    module: object
    state_names: tuple
    input_names: tuple
    sample_time: float
    output_names: tuple = ()

    @property
    def step(self):
        return self.module.step

    @property
    def n_state(self) -> int:
        return self.module.N_STATE

    @property
    def n_input(self) -> int:
        return self.module.N_INPUT

    @property
    def n_output(self) -> int:
        return self.module.N_OUTPUT

    @property
    def status_bits(self) -> dict:
        return {k: getattr(self.module, k) for k in
                ("OK", "SCHEDULING_CLAMPED", "NONFINITE_INPUT", "NUMERICAL_FAILURE", "WARMING_UP")}

    def output_index(self, signal: str) -> int:
        """Column of ``signal`` in the outputs."""
        try:
            return self.output_names.index(signal)
        except ValueError:
            raise UnknownObserverError(f"{self.name} has no output {signal!r}; outputs: "
                                       f"{', '.join(self.output_names)}") from None

    def initial_state(self) -> np.ndarray:
        return np.zeros(self.n_state)

    def run(self, inputs, state=None):
        """Run over an (n, n_input) array; returns (outputs (n, n_output), status (n,), final state)."""
        inputs = np.ascontiguousarray(inputs, dtype=np.float64)
        if inputs.ndim != 2 or inputs.shape[1] != self.n_input:
            raise SampleError(f"{self.name}: inputs must have shape (n, {self.n_input}) with columns "
                              f"{', '.join(self.input_names)}; got {inputs.shape}")
        state = self.initial_state() if state is None else np.array(state, dtype=np.float64)
        if state.shape != (self.n_state,):
            raise SampleError(f"{self.name}: state must have shape ({self.n_state},), got {state.shape}")
        n = inputs.shape[0]
        outputs = np.empty((n, self.n_output))
        status = np.empty(n, dtype=np.int32)
        self.module.run(state, inputs, outputs, status, n)
        return outputs, status, state


def load(name: str) -> CompiledObserver:
    """Import the compiled extension of observer ``name`` (built by ``make build``)."""
    design = GENERATED_DIR / name / f"{name}_design.json"
    if not design.is_file():
        raise UnknownObserverError(f"observer {name!r} has not been generated (no {design}); run `make generate`")
    try:
        module = importlib.import_module(f"python_bindings._ext._{name}")
    except ModuleNotFoundError:
        raise UnknownObserverError(f"observer {name!r} is generated but not compiled; run `make build`") from None
    art = json.loads(design.read_text())
    signals = art["signals"]
    return CompiledObserver(name, module, tuple(signals["state"]), tuple(signals["input"]),
                            float(art["config"]["sample_time"]), tuple(signals.get("output", signals["state"])))
