"""Switched linear model (3) of Menhour et al. 2014 from a symbolic model and a switching rule (data).

A switching rule is data in the observer configuration (``[switching]`` of
``model_defs/observers/NAME.toml``), not code. It has one or more *axes*; each axis has a premise
variable (a sympy expression in the model's known inputs, scheduling inputs, parameters and state
estimates), a partition of the premise's range into bands, and per band an *operating point*:
values substituted into the model's parameters and scheduling signals. The modes are the
combinations of one band per axis (M = product of the band counts), ordered with the last axis
fastest; mode i's matrices (A_i, B_i, F_i, C_i) are the model's Jacobians evaluated at the merged
operating point. Two ways to give the bands:

* ``centres = [c_1, ..., c_k]`` (eq. (25)): band l is [c_l - Delta, c_l + Delta[ with Delta half the
  distance to the neighbour: thresholds at the midpoints, range [c_1 - (c_2 - c_1)/2,
  c_k + (c_k - c_{k-1})/2];
* ``thresholds = [t_1, ..., t_{k-1}]`` and ``range = [lo, hi]`` (eq. (27): one threshold alpha*).

The rule is deterministic and hysteresis-free: band l of an axis is selected when
t_{l-1} <= premise < t_l (t_0 = -inf, t_k = +inf), so every premise value selects one mode; a
premise outside its range still selects the nearest band and is flagged by the step.

Example (Menhour et al. 2014 Sec. IV-A, speed bands at 36, 63, 90 km/h)::

    [switching]
    performance = ["beta"]
    [[switching.axis]]
    name = "v_x"
    premise = "v_x"
    unit = "m/s"
    centres = [10.0, 17.5, 25.0]
    points = [{ v_x = 10.0 }, { v_x = 17.5 }, { v_x = 25.0 }]
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import sympy as sp

from ...errors import ModelDefinitionError, SchedulingBoundsError
from ...model import ModelDefinition, ParameterSet, instantiate
from ...representation.substitution import offer


@dataclass(frozen=True)
class SwitchingAxis:
    """One premise variable, its bands and the operating point of each band.

    Attributes
    ----------
    name, unit : str
    premise : sympy.Expr
        In the model's symbols, parameters substituted; state symbols stand for the observer's
        current estimate x_hat_k, known inputs and scheduling signals for the measured inputs.
    thresholds : tuple of float
        Increasing band boundaries (k - 1 of them for k bands).
    lower, upper : float
        Range of the premise; outside it the step raises SCHEDULING_CLAMPED.
    points : tuple of dict
        Per band, {symbol name: value} substituted into parameters / scheduling signals.
    """

    name: str
    unit: str
    premise: sp.Expr
    thresholds: tuple
    lower: float
    upper: float
    points: tuple

    @property
    def n_bands(self) -> int:
        return len(self.points)

    def band(self, value: float) -> int:
        """Band index (0-based) of a premise value: t_{l-1} <= value < t_l."""
        return int(sum(value >= t for t in self.thresholds))

    def to_json(self) -> dict:
        return {"name": self.name, "unit": self.unit, "premise": str(self.premise),
                "thresholds": list(self.thresholds), "range": [self.lower, self.upper],
                "points": [dict(p) for p in self.points]}


@dataclass(frozen=True)
class SwitchingRule:
    """Axes, values common to every mode and the performance output xi = L x of S2."""

    axes: tuple
    fixed: dict
    performance: tuple          # state names whose estimation error is xi

    @property
    def n_modes(self) -> int:
        return int(np.prod([a.n_bands for a in self.axes]))

    def bands_of_mode(self, mode: int) -> tuple:
        """Band per axis of mode ``mode`` (0-based, last axis fastest)."""
        out = []
        for a in reversed(self.axes):
            out.append(mode % a.n_bands)
            mode //= a.n_bands
        return tuple(reversed(out))

    def mode(self, premise_values) -> int:
        """Mode index (0-based) selected by the premise values (one per axis)."""
        idx = 0
        for a, v in zip(self.axes, premise_values):
            idx = idx * a.n_bands + a.band(v)
        return idx

    def operating_point(self, mode: int) -> dict:
        point = dict(self.fixed)
        for a, b in zip(self.axes, self.bands_of_mode(mode)):
            point.update(a.points[b])
        return point

    def to_json(self) -> dict:
        return {"axes": [a.to_json() for a in self.axes], "fixed": dict(self.fixed),
                "performance": list(self.performance), "modes": self.n_modes}


@dataclass(frozen=True)
class SwitchedModel:
    """The switched system (3): per mode A_i, B_i, F_i, C_i; xi = L x."""

    definition: ModelDefinition
    parameters: ParameterSet
    rule: SwitchingRule
    A: np.ndarray              # (M, n, n)
    B: np.ndarray              # (M, n, nu)
    F: np.ndarray              # (M, n, nw)
    C: np.ndarray              # (M, m, n)
    L: np.ndarray              # (r, n)
    points: tuple              # merged operating point of each mode
    scheduling_boxes: dict     # {scheduling input name: (lo, hi)}

    @property
    def n_modes(self) -> int:
        return self.A.shape[0]

    @property
    def n(self) -> int:
        return self.A.shape[1]

    @property
    def nu(self) -> int:
        return self.B.shape[2]

    @property
    def nw(self) -> int:
        return self.F.shape[2]

    @property
    def m(self) -> int:
        return self.C.shape[1]

    def to_json(self) -> dict:
        return {"rule": self.rule.to_json(), "points": [dict(p) for p in self.points],
                "A": self.A.tolist(), "B": self.B.tolist(), "F": self.F.tolist(), "C": self.C.tolist(),
                "L": self.L.tolist(),
                "scheduling_boxes": {k: list(v) for k, v in self.scheduling_boxes.items()}}


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ModelDefinitionError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _axis(raw: dict, k: int, model: ModelDefinition, params: ParameterSet, source: str) -> SwitchingAxis:
    where = f"{source}: [[switching.axis]] #{k + 1}"
    unknown = set(raw) - {"name", "premise", "unit", "centres", "thresholds", "range", "points"}
    if unknown:
        raise ModelDefinitionError(f"{where}: unknown keys {sorted(unknown)}")
    for key in ("premise", "points"):
        if key not in raw:
            raise ModelDefinitionError(f"{where}: missing {key!r}")
    symbols = {str(s): s for s in (*model.states, *model.known_inputs, *model.unknown_inputs,
                                   *(g.symbol for g in model.scheduling), *model.parameters)}
    try:
        premise = sp.sympify(raw["premise"], locals=symbols)
    except (sp.SympifyError, TypeError) as exc:
        raise ModelDefinitionError(f"{where}: premise {raw['premise']!r} is not an expression: {exc}") from None
    stray = {str(s) for s in premise.free_symbols} - set(symbols)
    if stray:
        raise ModelDefinitionError(f"{where}: premise uses {sorted(stray)}, which are not states, known inputs, "
                                   f"scheduling signals or parameters of model {model.name!r}")
    if any(s in model.unknown_inputs for s in premise.free_symbols):
        raise ModelDefinitionError(f"{where}: a premise cannot use an unknown input (it is not measured)")
    premise = premise.subs({p: params.values[str(p)] for p in model.parameters if str(p) in params.values})
    points = raw["points"]
    if not isinstance(points, list) or not points or not all(isinstance(p, dict) for p in points):
        raise ModelDefinitionError(f"{where}: points must be a non-empty list of tables")
    settable = {str(p) for p in model.parameters} | {str(g.symbol) for g in model.scheduling}
    clean = []
    for j, p in enumerate(points):
        bad = set(p) - settable
        if bad:
            raise ModelDefinitionError(f"{where}: point {j + 1} sets {sorted(bad)}, which are neither parameters "
                                       f"nor scheduling signals of model {model.name!r}")
        clean.append({name: _number(v, f"{where} point {j + 1} {name}") for name, v in p.items()})
    n = len(clean)
    if "centres" in raw:
        if "thresholds" in raw or "range" in raw:
            raise ModelDefinitionError(f"{where}: give either centres (eq. (25)) or thresholds + range")
        c = [_number(v, f"{where} centres") for v in raw["centres"]]
        if len(c) != n or n < 2 or any(b <= a for a, b in zip(c, c[1:])):
            raise ModelDefinitionError(f"{where}: centres must be {n} increasing values (one per point)")
        thresholds = tuple(0.5 * (a + b) for a, b in zip(c, c[1:]))
        lower, upper = c[0] - 0.5 * (c[1] - c[0]), c[-1] + 0.5 * (c[-1] - c[-2])
    else:
        if "thresholds" not in raw or "range" not in raw:
            raise ModelDefinitionError(f"{where}: needs centres, or thresholds and range")
        thresholds = tuple(_number(v, f"{where} thresholds") for v in raw["thresholds"])
        rng = raw["range"]
        if not isinstance(rng, list) or len(rng) != 2:
            raise ModelDefinitionError(f"{where}: range must be [min, max]")
        lower, upper = (_number(v, f"{where} range") for v in rng)
        if len(thresholds) != n - 1:
            raise ModelDefinitionError(f"{where}: {n} points need {n - 1} thresholds, got {len(thresholds)}")
        edges = (lower, *thresholds, upper)
        if any(b <= a for a, b in zip(edges, edges[1:])):
            raise ModelDefinitionError(f"{where}: need min < thresholds (increasing) < max, got {list(edges)}")
    return SwitchingAxis(str(raw.get("name", f"premise{k + 1}")), str(raw.get("unit", "")), premise,
                         thresholds, float(lower), float(upper), tuple(clean))


def parse_rule(raw: dict, model: ModelDefinition, params: ParameterSet, source: str = "") -> SwitchingRule:
    """The ``[switching]`` table of an observer configuration as a :class:`SwitchingRule`."""
    if not isinstance(raw, dict) or not raw.get("axis"):
        raise ModelDefinitionError(f"{source}: a switched observer needs [switching] with at least one "
                                   f"[[switching.axis]]")
    unknown = set(raw) - {"axis", "fixed", "performance"}
    if unknown:
        raise ModelDefinitionError(f"{source}: unknown [switching] keys {sorted(unknown)}")
    axes = tuple(_axis(a, k, model, params, source) for k, a in enumerate(raw["axis"]))
    settable = {str(p) for p in model.parameters} | {str(g.symbol) for g in model.scheduling}
    fixed = dict(raw.get("fixed", {}))
    bad = set(fixed) - settable
    if bad:
        raise ModelDefinitionError(f"{source}: [switching] fixed sets {sorted(bad)}, unknown to model {model.name!r}")
    fixed = {k: _number(v, f"{source}: fixed {k}") for k, v in fixed.items()}
    perf = tuple(raw.get("performance", [str(model.states[0])]))
    missing = [p for p in perf if p not in model.state_names]
    if missing or not perf:
        raise ModelDefinitionError(f"{source}: performance outputs must be states of {model.name!r}, got {list(perf)}")
    return SwitchingRule(axes, fixed, perf)


def build(model: ModelDefinition, params: ParameterSet, raw_rule: dict, source: str = "") -> SwitchedModel:
    """Evaluate the model at the operating point of every mode of the rule.

    Raises
    ------
    ModelDefinitionError
        a rule that is not data of this model, a mode leaving a scheduling signal unassigned, or
        outputs whose matrix differs between modes.
    SchedulingBoundsError
        a scheduling signal used as an input without [scheduling.NAME] bounds.
    """
    rule = parse_rule(raw_rule, model, params, source)
    sched = [g.symbol for g in model.scheduling]
    A, B, F, C, points = [], [], [], [], []
    lpvs = {}          # one instantiation per distinct set of parameter values (sympy work is the cost)
    for i in range(rule.n_modes):
        point = rule.operating_point(i)
        missing = [str(s) for s in sched if str(s) not in point]
        if missing:
            raise ModelDefinitionError(f"{source}: mode {i + 1} has no value for the scheduling signal(s) "
                                       f"{', '.join(missing)}; set them in the axis points or in [switching] fixed")
        overrides = tuple(sorted((k, v) for k, v in point.items() if k in params.values))
        if overrides not in lpvs:
            values = {**params.values, **dict(overrides)}
            # the scheduling boxes are irrelevant for fixed operating points; instantiate needs them
            boxed = replace(params, values=values, scheduling={**{str(s): _dummy_box(str(s)) for s in sched},
                                                               **params.scheduling})
            lpvs[overrides] = instantiate(model, boxed, unknown_input_hint=offer)
        lpv = lpvs[overrides]
        lpv.require_no_ui_feedthrough("switched H-infinity PI observer", "Menhour et al. 2014, eq. (2): y = C x")
        lpv.require_no_derived_inputs("switched H-infinity PI observer", "Menhour et al. 2014: x' = A x + B u + F d")
        subs = {s: point[str(s)] for s in sched}
        for mats, M in ((A, lpv.A), (B, lpv.B), (F, lpv.D), (C, lpv.C)):
            mats.append(np.array(M.subs(subs), dtype=float))
        if lpv.Du is not None and len(lpv.Du) and np.any(np.array(lpv.Du.subs(subs), dtype=float) != 0):
            raise ModelDefinitionError(f"model {model.name!r}: outputs with known-input feedthrough are not "
                                       f"supported by the switched PI observer (Menhour et al. 2014, eq. (2): "
                                       f"y = C x). The L-infinity UIO (family linf_uio) takes y = C x + Du u")
        points.append(point)
    C = np.array(C)
    if np.ptp(C, axis=0).max(initial=0.0) != 0.0:
        raise ModelDefinitionError(
            f"model {model.name!r}: the output matrix C differs between modes; the observer's "
            f"coordinates z = T_i x would jump at a switch, which the paper's proof does not cover. The L-infinity "
            f"UIO (family linf_uio) takes a scheduling-dependent C")
    L = np.array([[1.0 if str(s) == p else 0.0 for s in model.states] for p in rule.performance])
    boxes = {}
    used = set().union(*(a.premise.free_symbols for a in rule.axes))
    for s in sched:
        if s not in used:
            continue
        box = params.scheduling.get(str(s))
        if box is None:
            raise SchedulingBoundsError(f"{source}: the premise uses {s}, which needs [scheduling.{s}] min/max "
                                        f"in {params.source}")
        lo, hi = box.lower, box.upper
        for a in rule.axes:               # a premise that IS the input: its range is the input's box
            if a.premise == s:
                lo, hi = max(lo, a.lower), min(hi, a.upper)
        boxes[str(s)] = (float(lo), float(hi))
    return SwitchedModel(model, params, rule, np.array(A), np.array(B), np.array(F), C, L, tuple(points), boxes)


def _dummy_box(name: str):
    from ...model import SchedulingBox
    return SchedulingBox(name, 0.0, 1.0, 0.0, 0.0)
