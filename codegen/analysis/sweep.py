"""Design studies: one observer designed over a grid of its settings (``uiogen sweep``).

A figure such as a guaranteed gain is only meaningful beside the settings that produce it: the
switched H∞ PI observer's γ is set by its pole radius, the L∞ observer's by its gain bound. A
sweep designs the observer at every point of a grid of overrides of its observer file
(``design.pole_radius = [30, 50, 100]`` …), each with the full pipeline (model, representation,
LMI solve, independent re-check, discrete step), and reports per point the figures of the
family's design summary, or the typed refusal (infeasible, not certified). It writes nothing:
the committed designs are untouched.
"""
from __future__ import annotations

import itertools
import time

from ..project import observer_file as observers
from .. import pipeline
from ..errors import REFUSALS, ConfigurationError

def _scalars(summary: dict) -> dict:
    """The numeric and text scalars of a design summary (tables and arrays left out)."""
    return {k: v for k, v in summary.items()
            if isinstance(v, (int, float, str, bool)) and k not in ("artifact", "observer")}


def point(name: str, overrides: dict) -> dict:
    """Design ``name`` with ``overrides``: its summary's scalars, or the refusal."""
    config = observers.get(name, overrides)
    t0 = time.perf_counter()
    try:
        b, _records = pipeline.solve(config)
    except REFUSALS as exc:
        return {"settings": overrides, "outcome": type(exc).__name__, "message": str(exc).splitlines()[0],
                "seconds": time.perf_counter() - t0}
    step = b.certificate.step
    return {"settings": overrides, "outcome": "certified", **_scalars(b.figures()),
            "certified_contraction_per_step": step.contraction, "seconds": time.perf_counter() - t0}


def run(name: str, grid: list, log=None) -> dict:
    """Every point of the product of ``grid`` (``[(key, values), ...]``), in order."""
    keys = [k for k, _ in grid]
    if len(set(keys)) != len(keys):
        raise ConfigurationError(f"--set: a key given twice in {keys}", source="--set", key=keys)
    observers.get(name)                     # the observer itself first: an unknown name is one error
    rows = []
    for values in itertools.product(*(v for _, v in grid)):
        row = point(name, dict(zip(keys, values)))
        rows.append(row)
        if log:
            log(row)
    return {"observer": name, "grid": {k: v for k, v in grid}, "points": rows}


#: the table's figure columns without --show: those of these a family reports, else the certified
#: contraction every certified point has (ts_fuzzy_uio reports no gamma)
DEFAULT_COLUMNS = ("gamma",)
FALLBACK_COLUMN = "certified_contraction_per_step"
_NOT_FIGURES = ("settings", "outcome", "message")


def figure_names(row: dict) -> list:
    """The figures a certified point reports (what ``--show`` may name)."""
    return [k for k in row if k not in _NOT_FIGURES]


def columns(name: str, row: dict, requested=None) -> list:
    """The table's figure columns, checked against the figures of the first certified point ``row``
    (a family's figures are known once it has designed): ``requested`` (``--show``) when every one
    is a figure of it, else ConfigurationError naming the unknown one, a did-you-mean and the
    figures there are; None: :data:`DEFAULT_COLUMNS` the family reports, else :data:`FALLBACK_COLUMN`."""
    from ..settings import suggest
    names = figure_names(row)
    if requested is None:
        return [c for c in DEFAULT_COLUMNS if c in names] or [FALLBACK_COLUMN]
    for c in requested:
        if c not in names:
            near = suggest(c, names)
            family = observers.get(name).family
            raise ConfigurationError(f"--show {c}: observer {name} ({family}) reports no figure {c!r}"
                                     + (f" (did you mean {near!r}?)" if near else "")
                                     + f"; its figures: {', '.join(names)}",
                                     source="--show", key="--show", value=c, allowed=", ".join(names))
    return list(requested)


def lines(result: dict, columns=("gamma",)) -> list:
    """A text table of a sweep: the settings, the outcome and the chosen summary figures."""
    keys = list(result["grid"])
    present = list(columns)
    head = keys + ["outcome"] + present
    out = ["  ".join(f"{h:>14}" for h in head)]
    for r in result["points"]:
        cells = [r["settings"][k] for k in keys] + [r["outcome"]] + [r.get(c, "") for c in present]
        out.append("  ".join(f"{(f'{c:.4g}' if isinstance(c, float) else str(c)):>14}" for c in cells))
    return out
