"""``uiogen validate --scenario``: an observer's errors on a plant it was not derived from, beside baselines.

Simulated runs belong to the observer's family (``Scenarios.validate``: its plants, its paper's
table format); logged runs (``--data``) are common to every observer that reads the log's signals,
one path for every log format (:mod:`codegen.validation.logs`). Measurements carry seeded white sensor noise where the family's paper
does (:data:`codegen.validation.common.SENSOR_NOISE`); baselines see the same measurements, so
every figure is a ratio measured in one run.
"""
from __future__ import annotations

import json
import math

import numpy as np

from ..contract import registry
from ..project import observer_file as observers
from ..project import outputs
from ..errors import ConfigurationError, SampleError
from . import metrics
from .common import SETTLE_TIME

__all__ = ["SETTLE_TIME", "run_scenario", "format_table", "header", "plot", "to_json", "progress_bar"]


def progress_bar(label: str):
    """A progress callback (fraction done) drawing on stderr, or None when stderr is not a terminal."""
    import sys
    if not sys.stderr.isatty():
        return None

    def show(fraction: float) -> None:
        filled = int(30 * fraction)
        sys.stderr.write(f"\r{label} [{'#' * filled}{'.' * (30 - filled)}] {100 * fraction:3.0f}%")
        if fraction >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()
    return show


def run_scenario(name, scenario, plant: str = "nominal", duration: float | None = None,
                 seed: int = 0, progress=None, observer=None, noise: bool = True) -> dict:
    """Simulate the observer's family plant, run the compiled step and the baselines; returns the
    tables (``observer``, ``baselines``), the signals and ``family`` (which formats the table).
    ``observer``: the compiled observer to run (default: the observer's extension), e.g. a
    :class:`python_bindings.Recorder` of it. ``noise``: the excitation scenario's measurements carry
    the parameter file's ``[sensor_noise]`` (False: ``--noise-free``; a family's own scenarios carry
    their paper's noise, and refuse it)."""
    from ..extension.build import require_current
    config = observers.get(name) if isinstance(name, str) else name
    if duration is not None and not (isinstance(duration, (int, float)) and math.isfinite(duration)
                                     and duration > SETTLE_TIME):
        raise ConfigurationError(f"--duration {duration!r}: allowed: a number of seconds above {SETTLE_TIME:g} (the "
                                 f"scenario is truncated there, and the errors are taken after the first "
                                 f"{SETTLE_TIME:g} s)", source="--duration", key="--duration", value=duration)
    if scenario == "excitation" and plant == "commonroad":
        raise ConfigurationError("--plant commonroad: the excitation scenario runs on the observer's own model (the "
                                 "model plant); CommonRoad's vehicle models drive a family's named scenarios (uiogen "
                                 "validate NAME --scenario S --plant commonroad)", source="--plant", key="--plant",
                                 value=plant)
    if not noise and scenario != "excitation":
        raise ConfigurationError(f"--noise-free: scenario {scenario!r} is the {config.family} family's, with the sensor "
                                 f"noise of its paper (or none); --noise-free turns off the [sensor_noise] of the "
                                 f"excitation scenario (uiogen validate NAME --scenario excitation --noise-free)",
                                 source="--noise-free", key="--noise-free", value=True,
                                 allowed="--scenario excitation")
    require_current(config)                 # never the compiled step of an older design
    if scenario == "excitation":            # every model: its own equations, swept and excited
        from . import excitation
        return {"family": config.family, **excitation.run(config, duration, seed, progress=progress,
                                                          observer=observer, noise=noise)}
    from ..contract.capabilities import Scenarios, require
    family = require(config.observer_family, Scenarios)
    result = family.validate(config, scenario, plant, duration, seed, progress=progress, observer=observer)
    return {"family": config.family, **result}


def format_table(result: dict) -> str:
    """The validation table in the format of the observer family's paper (or the generic one of
    the excitation scenario)."""
    if result.get("table_format") == "generic":
        from . import excitation
        return excitation.format_table(result)
    return registry.get(result["family"]).validation_table(result)


def header(name: str, result: dict) -> str:
    """The line above the table: scenario, plant, samples, flagged samples (:mod:`codegen.certificate.text`)."""
    from ..certificate.text import validation_header
    from .common import SETTLE_TIME
    return validation_header(registry.get(result["family"]), name, result, SETTLE_TIME)


def plot(result: dict, path: str) -> None:
    plt = outputs.pyplot()
    sig = result["signals"]
    names = [n for n in sig["estimate"] if n in sig["truth"]]
    fig, axes = plt.subplots(len(names), 1, figsize=(9, 2.2 * len(names)), sharex=True)
    for ax, n in zip(np.atleast_1d(axes), names):
        unit, scale, _ = metrics.reported_unit(result["units"].get(n))
        ax.plot(sig["t"], sig["truth"][n] * scale, "k", lw=1.0, label="truth")
        ax.plot(sig["t"], sig["estimate"][n] * scale, "r--", lw=1.0, label="observer")
        ax.set_ylabel(n + (f" [{unit}]" if unit else ""))
    np.atleast_1d(axes)[0].legend(loc="upper right")
    np.atleast_1d(axes)[-1].set_xlabel("t [s]")
    fig.suptitle(f"{result['scenario']} on the {result['plant']} plant")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def failure(result: dict) -> str:
    """Why a run says nothing of the observer's accuracy, or "": the step failed numerically (and
    reset its state) on some samples, or an estimate's error is not finite (it diverged)."""
    import math
    why = []
    failed = result.get("status_counts", {}).get("NUMERICAL_FAILURE", 0)
    if failed:
        why.append(f"the step reported NUMERICAL_FAILURE on {failed} of {result['samples']} samples and reset its "
                   f"state there")
    diverged = [s for s, row in result.get("observer", {}).items()
                if isinstance(row, dict) and isinstance(row.get("rms"), float) and not math.isfinite(row["rms"])]
    if diverged:
        why.append(f"the error of {', '.join(diverged)} is not finite (the estimate diverged)")
    return "; ".join(why)


def to_json(result: dict) -> str:
    """``uiogen validate --json``: every row in the one definition (``definitions`` says what each
    key means and in which unit), and the family's paper format beside it (``paper_format``)."""
    from . import noise
    keys = ("observer", "baselines", "plant", "plant_model", "scenario", "status_flags", "status_counts", "samples",
            "max_abs_ay", "paper_format", "noise")
    return json.dumps({**{k: result[k] for k in keys if k in result}, "definitions": metrics.DEFINITIONS,
                       "uninformative": sorted(noise.uninformative(result.get("observer", {})))},
                      indent=1, sort_keys=True)


def scenario_names(name) -> tuple:
    """The validation scenarios of an observer: for a built-in one those ``uiogen demo`` runs (its
    family's ``Scenarios.demo_scenarios``, the papers' on the library's plants), for a project's
    observer and a family without its own the generic excitation scenario on the model's own
    equations (the library's plants are of the built-in models)."""
    from ..contract.capabilities import Scenarios
    config = observers.get(name) if isinstance(name, str) else name
    family = config.observer_family
    own = tuple(family.demo_scenarios) if isinstance(family, Scenarios) and config.builtin else ()
    return own or ("excitation",)


def scenario_inputs(name, scenario, plant: str = "nominal", duration: float | None = None) -> np.ndarray:
    """The (n, n_input) input sequence the compiled observer is given on a validation scenario
    (recorded from the run itself: the noisy measurements, the derived scheduling signals)."""
    from python_bindings import Recorder
    from ..extension.build import load
    config = observers.get(name) if isinstance(name, str) else name
    recorder = Recorder(load(config))
    run_scenario(config, scenario, plant, duration=duration, observer=recorder)
    runs = [inputs for inputs, _ in recorder.calls]
    if not runs:
        raise SampleError(f"{config.name}: scenario {scenario!r} did not run the compiled observer")
    if runs[0].ndim == 1:           # sample by sample (step): the consecutive rows of the first run
        rows = []
        for r in runs:
            if r.ndim != 1:
                break
            rows.append(r)
        return np.vstack(rows)
    return runs[0]
