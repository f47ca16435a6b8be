"""``[design] precision = "float32"``: a design that leaves room for single-precision rounding.

The float32 step's deviation from the double step is bounded by the certified contraction
(:mod:`codegen.targets.float32`): each step's rounding is divided by about the contraction
margin ``1 - c``, so a certificate that contracts by 0.9999 per step multiplies the rounding by
10^4. With ``precision = "float32"`` the family's LMIs require the margin ``float32_margin``
(default :data:`FLOAT32_MARGIN`: the accumulated rounding then stays within about a hundred
one-step roundings, ~1e-5 of the state's size in float32), each through its own decay setting,
and :func:`check` refuses a design whose certified contraction still falls short, naming the
setting that would fix it. Every family's settings carry the two fields (:func:`fields`).
"""
from __future__ import annotations

import math

from ..errors import DiscretizationError
from ..settings import setting

PRECISIONS = ("double", "float32")
FLOAT32_MARGIN = 0.01


def precision_field():
    return setting("double", choices=PRECISIONS,
                   doc="float32: the LMIs require the contraction margin float32_margin (codegen.design.precision)")


def margin_field():
    return setting(FLOAT32_MARGIN, gt=0, lt=1, doc="1 - c per step a precision = \"float32\" design must certify")


def required_margin(settings) -> float:
    """The certified ``1 - c`` per step the design must reach (0 for a double design)."""
    return float(settings.float32_margin) if settings.precision == "float32" else 0.0


def rate_for_backward_euler(margin: float, sample_time: float, factor: float = 2.0) -> float:
    """The decay rate ``a`` of ``V`` whose backward-Euler step contracts ``sqrt(V)`` by
    ``1 / sqrt(1 + factor a Ts) <= 1 - margin`` (``factor``: 2 for He(P A) <= -2 a P, 1 for
    He(P A) <= -a P)."""
    return ((1.0 / (1.0 - margin)) ** 2 - 1.0) / (factor * sample_time) if margin > 0 else 0.0


def rate_for_exact_step(margin: float, sample_time: float) -> float:
    """The decay rate ``a`` whose exact (ZOH) step contracts by ``exp(-a Ts) <= 1 - margin``."""
    return -math.log(1.0 - margin) / sample_time if margin > 0 else 0.0


def check(b) -> None:
    """Refuse a ``precision = "float32"`` design whose certified contraction margin is below its
    ``float32_margin`` (DiscretizationError naming the certificate and the setting to change)."""
    raw = dict(b.config.design)
    if raw.get("precision", "double") != "float32":
        return
    need = float(raw.get("float32_margin", FLOAT32_MARGIN))
    metrics = b.contraction_metrics()
    if not metrics:
        raise DiscretizationError(f"{b.name}: [design] precision = \"float32\": family {b.config.family!r} certifies no "
                                  f"contraction in a Lyapunov norm, so no margin for the rounding can be required")
    short = [m for m in metrics if m.margin < need * (1 - 1e-9)]
    if short:
        m = min(short, key=lambda m: m.margin)
        raise DiscretizationError(
            f"{b.name}: [design] precision = \"float32\" needs a certified contraction margin 1 - c >= {need:g} per "
            f"step; the design certifies {m.margin:.4g} (c = {m.contraction:.6f}, {m.source}). "
            f"Options: {m.knob or 'a faster design'}, or a smaller [design] float32_margin")
