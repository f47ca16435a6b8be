"""The design artifact's shared parts: the head that names an observer and its signals, the
solver's certificate record, and the rounding of report figures."""
from __future__ import annotations

import numpy as np


def artifact_head(b, scheduling: list, **signals) -> dict:
    """The part of every family's design artifact that names the observer and its signals."""
    return {"observer": b.name, "config": b.config.to_json(),
            "signals": {"state": b.state_names, "input": b.input_names, "output": b.output_names,
                        "scheduling": [str(x) for x in scheduling], "input_boxes": b.input_boxes(), **signals}}


def solver_certificate(sol, **rechecks) -> dict:
    """Solver's worst block and the independent re-checks, as every family's artifact reports them."""
    return {"solver_blocks": len(sol.checks), "solver_worst_block": sol.worst.label,
            "solver_worst_min_eig": significant(sol.worst.min_eig), **{k: significant(v) for k, v in rechecks.items()}}


def significant(x, digits=6):
    """Round report figures so the committed artifact does not depend on last-bit noise."""
    if isinstance(x, dict):
        return {k: significant(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [significant(v, digits) for v in x]
    if isinstance(x, float) and np.isfinite(x):
        return float(f"{x:.{digits}g}")
    return x
