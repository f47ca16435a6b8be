"""One typed certificate for every observer family: what is certified, under which conditions,
by which independent checks, with which bound in which unit.

Every family's build produces a :class:`Certificate` (``ObserverBuild.certificate``); the design
lock records it as ``certificate`` (:meth:`Certificate.to_json`: the same keys for every family,
the family's own figures under ``extras``), and ``uiogen design``, ``uiogen demo``, the C header,
``uiogen check-gains`` and the export targets read it back (:meth:`Certificate.from_json`) instead
of a family's own keys. Its text is rendered in one place, :mod:`codegen.certificate.text`.

Numbers are kept to six significant digits (:func:`~codegen.certificate.artifact.significant`)
when a certificate is made, so the one built by a design and the one read back from its lock are
equal, and the lock's bytes do not depend on last-bit noise.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from ..errors import DesignLockError
from ..design.lmi import worst_block
from .artifact import significant

#: norms a :class:`Bound` may be stated in
NORMS = {
    "peak": "sup_t |error| <= value sup_t |input| (L-infinity, peak to peak)",
    "l2": "||error||_2 <= value ||input||_2 over any horizon (l2 / H-infinity gain), plus the initial error's decay",
    "rms": "RMS error <= value when every input channel is at its stated level (the claim says how: an l2 gain, or "
           "a contraction with white noise)",
}


@dataclass(frozen=True)
class Bound:
    """A certified bound on an estimation error against an input, in the signal's unit.

    ``error`` names what is bounded (a signal or a performance output), ``input`` what drives it,
    ``norm`` one of :data:`NORMS`, ``unit`` the unit of ``value`` (error unit per input unit, or the
    error's unit when the input is normalized)."""

    quantity: str
    value: float
    unit: str
    norm: str
    error: str
    input: str

    def __post_init__(self):
        if self.norm not in NORMS:
            raise ValueError(f"bound {self.quantity!r}: norm {self.norm!r} is not one of {sorted(NORMS)}")
        object.__setattr__(self, "value", significant(float(self.value)))

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Recheck:
    """The independent numpy re-check of the LMI blocks: how many, and the one with the least margin."""

    blocks: int
    worst_block: str
    worst_min_eig: float
    worst_relative_margin: float

    def __post_init__(self):
        object.__setattr__(self, "worst_min_eig", significant(float(self.worst_min_eig)))
        object.__setattr__(self, "worst_relative_margin", significant(float(self.worst_relative_margin)))

    @classmethod
    def of(cls, checks) -> "Recheck":
        """From :class:`~codegen.design.lmi.BlockCheck` s (the worst by relative margin)."""
        checks = list(checks)
        worst = worst_block(checks)
        return cls(len(checks), worst.label, worst.min_eig, worst.relative_margin)


@dataclass(frozen=True)
class Step:
    """The discrete step's certificate: sqrt(V) of the estimation error contracts by at most
    ``contraction`` per step (the slowest over everything the step can meet), at ``sample_time``.

    ``contraction`` is proven; 1 means V decreases strictly at every step with no rate proven (the
    paper's strict inequality). ``sampled``, when given, is evidence beside it (the largest ratio
    met on random samples), never in its place."""

    sample_time: float
    method: str
    contraction: float
    sampled: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "contraction", significant(float(self.contraction)))
        if self.sampled is not None:
            object.__setattr__(self, "sampled", significant(float(self.sampled)))
        if not 0.0 <= self.contraction <= 1.0:
            raise ValueError(f"a certified step contracts by at most 1 per step, got {self.contraction}")

    @property
    def rate_proven(self) -> bool:
        return self.contraction < 1.0

    @property
    def time_constant_s(self) -> float:
        """The time in which the certified bound on the error shrinks by e: -T_s / ln(contraction)
        (inf without a proven rate)."""
        import math
        if not self.rate_proven:
            return math.inf
        return significant(-self.sample_time / math.log(self.contraction)) if self.contraction > 0 else 0.0


@dataclass(frozen=True)
class Certificate:
    """What a family's design certifies (one record for all families).

    Attributes
    ----------
    family : str
        The observer family.
    claim : str
        What is certified, in one sentence (the theorem and its conclusion).
    plant_class : str
        The models the claim holds for (the observer's model, its representation, parameter ranges).
    noise : str
        What disturbances and measurement errors the claim covers.
    region : dict
        ``{signal: (min, max)}``: the set the state and scheduling signals must stay in; outside it
        the step sets ``SCHEDULING_CLAMPED`` where the step can see it.
    region_note : str
        What else the set requires (derived signals, estimates, rate bounds), and what the status
        bit does not see.
    recheck : Recheck
        The numpy re-check of the LMI blocks.
    step : Step
        The discrete step's contraction at its sample time.
    bounds : tuple of Bound
        Certified input-to-error bounds (empty: the certificate is convergence only).
    extras : dict
        The family's own figures (JSON), e.g. per-mode H-infinity norms or per-subsystem margins.
    """

    family: str
    claim: str
    plant_class: str
    noise: str
    region: dict
    region_note: str
    recheck: Recheck
    step: Step
    bounds: tuple = ()
    extras: dict = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "region", {str(k): (significant(float(lo)), significant(float(hi)))
                                            for k, (lo, hi) in self.region.items()})
        object.__setattr__(self, "bounds", tuple(self.bounds))
        object.__setattr__(self, "extras", significant(dict(self.extras)))

    def bound(self, norm: str) -> Bound | None:
        """The first bound stated in ``norm``, or None."""
        return next((b for b in self.bounds if b.norm == norm), None)

    def to_json(self) -> dict:
        """The design lock's ``certificate`` (the same keys for every family)."""
        return {"family": self.family, "claim": self.claim, "plant_class": self.plant_class, "noise": self.noise,
                "region": {k: list(v) for k, v in self.region.items()}, "region_note": self.region_note,
                "recheck": dataclasses.asdict(self.recheck),
                "step": {"sample_time": self.step.sample_time, "method": self.step.method,
                         "contraction_per_step": self.step.contraction,
                         **({"sampled_contraction_per_step": self.step.sampled} if self.step.sampled is not None else {})},
                "bounds": [b.to_json() for b in self.bounds], "extras": self.extras}

    @classmethod
    def from_json(cls, data, source: str = "") -> "Certificate":
        """A certificate read back from a design lock's ``certificate``.

        Raises
        ------
        DesignLockError
            a lock written before the typed certificate, or a malformed record: re-generate it.
        """
        try:
            step = data["step"]
            return cls(str(data["family"]), str(data["claim"]), str(data["plant_class"]), str(data["noise"]),
                       {k: tuple(v) for k, v in data["region"].items()}, str(data["region_note"]),
                       Recheck(**data["recheck"]),
                       Step(float(step["sample_time"]), str(step["method"]), float(step["contraction_per_step"]),
                            step.get("sampled_contraction_per_step")),
                       tuple(Bound(**b) for b in data["bounds"]), dict(data.get("extras", {})))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise DesignLockError(f"{source}: the design lock's certificate is not the typed record of this toolchain "
                                  f"({type(exc).__name__}: {exc}); run `uiogen generate` to re-write it") from None


def of_lock(data: dict, source: str = "") -> Certificate:
    """The certificate of a parsed design lock (``NAME_design.json``)."""
    if not isinstance(data, dict) or "certificate" not in data:
        raise DesignLockError(f"{source}: the design lock has no certificate; run `uiogen generate` to re-write it")
    return Certificate.from_json(data["certificate"], source)


def unit_ratio(numerator: list, denominator: list) -> str:
    """The unit of a gain from signals in ``denominator`` units to signals in ``numerator`` units:
    'rad per N m' when each side's signals share one unit, else each signal's unit in the signals'
    order, repeats kept: '(rad, rad/s, rad, rad/s) per N m' for z = (beta, r, delta, delta_dot), so
    the k-th unit is the k-th signal's (merging the repeats to '(rad, rad/s)' paired them wrongly)."""
    def group(units):
        units = [u or "-" for u in units]
        return units[0] if len(set(units)) == 1 else f"({', '.join(units)})"
    return f"{group(numerator)} per {group(denominator)}"
