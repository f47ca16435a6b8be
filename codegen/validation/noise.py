"""The car's sensor noise in a simulated run: seeded white noise at the declared levels, and what
a run's figures say about it.

The levels are declared once, in the parameter file's ``[sensor_noise]`` table, read and checked
by :mod:`codegen.project.sensor_noise` (its names are re-exported here for the validation code):
``uiogen validate NAME --scenario excitation`` adds seeded white noise at these levels to what the
observer reads (:func:`add`; ``--noise-free``: without; no table: noise free, and the header says
so), and :func:`remark` names the estimates a run leaves below the noise floor.
"""
from __future__ import annotations

import numpy as np

from ..project.sensor_noise import column_signal, declared, measured_signals, observer_levels  # noqa: F401

#: the seed of the noise is the run's seed with this one: a run's noise differs from its inputs' draws
NOISE_STREAM = 0x5E4


def add(columns: np.ndarray, input_names, levels: dict, seed: int) -> np.ndarray:
    """``columns`` (one per input name) plus seeded white noise of ``levels`` (reproducible: the same
    seed, the same draws; each column its own stream, in the order of ``input_names``)."""
    rng = np.random.default_rng([int(seed), NOISE_STREAM])
    out = np.array(columns, dtype=float, copy=True)
    for j, col in enumerate(input_names):
        draw = rng.standard_normal(out.shape[0])       # drawn for every column: a level edited changes one column
        if levels.get(col):
            out[:, j] += levels[col] * draw
    return out


def uninformative(rows: dict) -> dict:
    """{signal: row} of the estimates that carry no information (error RMS >= the truth's RMS about its
    mean: :data:`codegen.validation.metrics.DEFINITIONS` ``no_information``)."""
    return {s: r for s, r in rows.items() if isinstance(r, dict) and r.get("no_information")}


def remark(rows: dict, noisy: bool | None = None) -> str:
    """One line naming each estimate that carries no information with its figures, or "" (``noisy``:
    the run's measurements carried the declared sensor noise, so the estimate is below its noise
    floor; False: they carried none; None: not said)."""
    bad = uninformative(rows)
    if not bad:
        return ""
    parts = [f"{s} (error RMS {r['rms']:.4g} >= {r['truth_std']:.4g} {r.get('unit') or ''}, its truth's RMS about "
             f"its mean; NMSE {r['nmse_percent']:.4g} %)".replace("  ", " ") for s, r in bad.items()]
    return (f"no information: {'; '.join(parts)}: the truth's mean (a constant) would estimate "
            f"{'it' if len(bad) == 1 else 'them'} as well"
            + {True: "; below the noise floor of the declared sensor noise", False: ", even without sensor noise",
               None: ""}[noisy])
