"""The single-precision (float32) build of an observer, and what its certificate says about it.

``render(b, "float32")`` (:mod:`codegen.emit`) gives the same C API in ``float``, every name
suffixed ``_f32``; it is emitted into ``build/float32/NAME/`` (never into ``generated_c/``: the
committed C is the double one) and compiled with the project's strict flags into a shared
library, called here through ctypes.

What the certificate means for the float step. The double step is certified to contract the
estimation error by ``c < 1`` per step (in the design's Lyapunov norm). The float step is the
double step plus a rounding error ``d_k`` per sample; the difference ``e_k`` between the float and
the double trajectories on the same inputs obeys ``|e_k+1| <= c |e_k| + |d_k|``, so
``|e_k| <= max|d| / (1 - c)``: the contraction margin ``1 - c`` divides the rounding. We measure
``max|d|`` (one float step from the double state against the double step, on the validation
scenarios' inputs, per output relative to its RMS), take ``bound = max|d| / (1 - c)``
(Euclidean figures: the Lyapunov norm's condition number is not in it, so the bound is the
certificate's reading, not a proof) and the measured deviation ``max|e|`` itself; a float build
whose bound or measured deviation exceeds :data:`TOLERANCE` of the signal's RMS is refused
(:class:`~codegen.errors.CertificateError`, with the figures).
"""
from __future__ import annotations

import ctypes
import json
from pathlib import Path

import numpy as np

from ..design import lock as design_lock
from ..emit import generate as emit
from ..project import observer_file as observers
from .. import pipeline
from ..errors import CertificateError, ModelDefinitionError
from ..emit.toolchain import STRICT_CFLAGS, compile_and_link

TOLERANCE = 1e-4          # largest deviation from the double step, relative to each signal's RMS


def _config(observer) -> observers.ObserverConfig:
    return observers.get(observer if isinstance(observer, observers.ObserverConfig) else str(observer))


def certified_contraction(art: dict) -> float:
    """The certified contraction per step of a design lock's typed certificate (the step's slowest,
    :class:`~codegen.certificate.certificate.Step`); 1 where the family proves a strict decrease
    but no rate (then the margin is 0 and no float build is accepted)."""
    from ..certificate.certificate import of_lock
    return of_lock(art, "design lock").step.contraction


def emit_float(observer, out_dir: Path | None = None) -> Path:
    """The float32 C of ``observer`` in ``out_dir/NAME/`` (default: its project's
    ``build/float32/NAME/``, :mod:`python_bindings.workspace`)."""
    config = _config(observer)
    b = pipeline.build(config)
    target = Path(out_dir or config.workspace.float32) / config.name
    target.mkdir(parents=True, exist_ok=True)
    for fname, text in emit.render(b, "float32").items():
        (target / fname).write_text(text)
    return target


def build_float(observer, out_dir: Path | None = None) -> Path:
    """Emit and compile the float32 step into a shared library (strict flags, -O2); its path."""
    config = _config(observer)
    d = emit_float(config, out_dir)
    name = f"{config.name}_f32"
    return compile_and_link([d / f"{name}_kernel.c", d / f"{name}.c"], d / f"lib{name}.so", include=[d],
                            flags=STRICT_CFLAGS, shared=True, object_dir=d)


class FloatObserver:
    """The float32 step through ctypes: ``run(inputs)`` like :meth:`CompiledObserver.run`."""

    def __init__(self, name: str, lib: Path, n_state: int, n_input: int, n_output: int):
        self.name, self.n_state, self.n_input, self.n_output = name, n_state, n_input, n_output
        self._lib = ctypes.CDLL(str(lib))
        self._run = getattr(self._lib, f"{name}_f32_run_flat")
        fp = ctypes.POINTER(ctypes.c_float)
        self._run.argtypes = [fp, fp, ctypes.c_size_t, fp, ctypes.POINTER(ctypes.c_int)]
        self._run.restype = None

    def run(self, inputs, state=None):
        inputs = np.ascontiguousarray(inputs, dtype=np.float32)
        state = np.zeros(self.n_state, np.float32) if state is None else np.array(state, dtype=np.float32)
        n = inputs.shape[0]
        out = np.empty((n, self.n_output), np.float32)
        status = np.empty(n, np.intc)
        fp = ctypes.POINTER(ctypes.c_float)
        self._run(state.ctypes.data_as(fp), inputs.ctypes.data_as(fp), n, out.ctypes.data_as(fp),
                  status.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
        return out, status, state


def load_float(observer, out_dir: Path | None = None) -> FloatObserver:
    from ..extension.build import load
    config = _config(observer)
    obs = load(config)
    return FloatObserver(config.name, build_float(config, out_dir), obs.n_state, obs.n_input, obs.n_output)


def _double_states(obs, inputs):
    """The double trajectory's state before each sample, and its outputs and status."""
    n = inputs.shape[0]
    states = np.empty((n, obs.n_state))
    outs = np.empty((n, obs.n_output))
    status = np.empty(n, np.int32)
    state = obs.initial_state()
    for k in range(n):
        states[k] = state
        status[k] = obs.step(state, inputs[k], outs[k])
    return states, outs, status


def compare(observer, scenarios=None, out_dir: Path | None = None) -> dict:
    """The float32 step against the double step on the observer's validation scenarios: per
    scenario and output, the largest deviation and the largest one-step rounding, both relative
    to the signal's RMS; the certified contraction; the bound; whether the float build passes."""
    from ..validation import run as validate
    from ..extension.build import load
    config = _config(observer)
    obs = load(config)
    fobs = load_float(config, out_dir)
    c = certified_contraction(json.loads(design_lock.path(config).read_text()))
    rows = {}
    todo = list(scenarios or validate.scenario_names(config))
    while todo:
        scenario = todo.pop(0)
        try:
            inputs = (validate.shared_log_inputs(obs.input_names) if scenario == validate.SHARED_LOG
                      else validate.scenario_inputs(config, scenario))
        except ModelDefinitionError:
            # the family's scenarios need a plant this model lacks: an observer of the real log is
            # validated on it; any other takes the generic excitation scenario on its own equations
            fallbacks = [validate.SHARED_LOG] if validate.reads_the_log(obs.input_names) else ["excitation"]
            if scenarios is not None or scenario in fallbacks:
                raise
            if not rows and not todo:
                todo += fallbacks
            continue
        states, out_d, status_d = _double_states(obs, inputs)
        out_f, status_f, _ = fobs.run(inputs)
        rms = np.sqrt(np.mean(out_d ** 2, axis=0))
        scale = np.where(rms > 0, rms, 1.0)
        dev = np.max(np.abs(out_f.astype(np.float64) - out_d), axis=0) / scale
        # one float step from the (rounded) double state, against the double step
        one = np.empty_like(out_d)
        for k in range(inputs.shape[0]):
            o, _, _ = fobs.run(inputs[k:k + 1], states[k])
            one[k] = o[0]
        rounding = np.max(np.abs(one.astype(np.float64) - out_d), axis=0) / scale
        rows[scenario] = {"samples": int(inputs.shape[0]),
                          "deviation": dict(zip(obs.output_names, dev.tolist())),
                          "rounding_per_step": dict(zip(obs.output_names, rounding.tolist())),
                          "max_deviation": float(dev.max()), "max_rounding_per_step": float(rounding.max()),
                          "status_equal": bool(np.array_equal(status_d, status_f))}
    worst_dev = max(r["max_deviation"] for r in rows.values())
    worst_round = max(r["max_rounding_per_step"] for r in rows.values())
    bound = worst_round / (1.0 - c) if c < 1 else float("inf")
    return {"observer": config.name, "contraction_per_step": c, "margin": 1.0 - c, "scenarios": rows,
            "max_deviation": worst_dev, "max_rounding_per_step": worst_round, "bound": bound,
            "tolerance": TOLERANCE, "passes": bool(worst_dev <= TOLERANCE and bound <= TOLERANCE)}


def check(observer, scenarios=None, out_dir: Path | None = None) -> dict:
    """:func:`compare`, refusing (CertificateError) a float build that does not pass."""
    r = compare(observer, scenarios, out_dir)
    if not r["passes"]:
        raise CertificateError(
            f"{r['observer']}: float32 build refused: largest deviation from the double step "
            f"{r['max_deviation']:.3g} of the signal RMS, one-step rounding {r['max_rounding_per_step']:.3g} / "
            f"contraction margin {r['margin']:.4g} (c = {r['contraction_per_step']:.6f}) = bound {r['bound']:.3g}; "
            f"the tolerance is {TOLERANCE:g}")
    return r


def format_report(r: dict) -> str:
    return (f"{r['observer']}: float32 {'accepted' if r['passes'] else 'REFUSED'}: max deviation "
            f"{r['max_deviation']:.2e} of RMS, one-step rounding {r['max_rounding_per_step']:.2e}, margin 1-c = "
            f"{r['margin']:.4g}, bound {r['bound']:.2e} (tolerance {r['tolerance']:g}; scenarios "
            f"{', '.join(r['scenarios'])})")
