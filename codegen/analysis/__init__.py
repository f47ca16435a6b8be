"""``uiogen analyze``: what a model's equations allow with its sensors, and which family to use.

>>> from codegen import analysis
>>> a = analysis.analyze("ts_fuzzy_uio", design=False)          # doctest: +SKIP
>>> a.ranking.best.family                                         # doctest: +SKIP
'ts_fuzzy_uio'

* :mod:`.subject`: what is analyzed (a built-in observer, an observer file or a model file with
  its parameter file; the measured outputs and the unknown inputs chosen);
* :mod:`.structure`: the structural facts over the whole box (observability, matching, left
  invertibility, invariant zeros, strong detectability, relative degrees, what is estimable);
* :mod:`.ranking`: every registered family's answer (``Family.applicability``), trial designs
  where they are cheap, the families ranked; the observer file ``uiogen new --from-model`` writes;
* :mod:`.report`: the text;
* :mod:`.sweep`: ``uiogen sweep``, one observer designed over a grid of its settings.

Nothing here is imported by a family's pipeline: analyzing never makes a design lock stale.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

from . import ranking as _ranking
from . import structure as _structure
from ..emit.stepgen import check_functions
from ..model.dimensions import unranged_parameters
from .subject import Subject, load

__all__ = ["Analysis", "analyze", "load", "Subject"]


@dataclass
class Analysis:
    """The answer of ``uiogen analyze``: subject, structure, ranking and the seconds each took."""

    subject: Subject
    structure: object
    ranking: object
    seconds: dict

    def text(self) -> str:
        from .report import text
        return text(self)

    def to_json(self) -> dict:
        return _finite(self._json())

    def _json(self) -> dict:
        s = self.subject
        return {"target": s.target, "model": s.name, "model_file": str(s.model_path),
                "parameter_file": str(s.parameter_path),
                "observer_file": s.config.source if s.config is not None else None,
                "states": list(s.states), "outputs": list(s.outputs), "known_inputs": list(s.known_inputs),
                "unknown_inputs": list(s.unknown_inputs), "units": s.units,
                "unranged_parameters": list(unranged_parameters(s.model)), "sample_time": s.sample_time,
                "selected": s.selected,
                "substitutions": [{**sub.to_json(), "origin": s.substitution_origin,
                                   "estimated": f"{sub.symbol} = {sub.carrier}",
                                   "recovered": f"{sub.unknown} = {sub.inverse}, an output of the observer"}
                                  for sub in s.substitutions],
                "substitution_refusals": dict(s.substitution_refusals),
                "structure": self.structure.to_json(),
                "ranking": self.ranking.to_json() if self.ranking is not None else None,
                "seconds": self.seconds}


def _finite(obj):
    """JSON has no infinities or NaN: a non-finite number becomes null."""
    import math
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def analyze(target, parameters: str | None = None, outputs=None, unknown_inputs=None, design: bool = True,
            rank: bool = True, progress=None) -> Analysis:
    """Analyze ``target`` (an observer name or file, or a model file with ``parameters``).

    ``design``: run the trial designs of the applicable families whose design takes seconds;
    ``rank``: ask the families at all (False: the structure only).
    """
    t0 = time.perf_counter()
    subject = target if isinstance(target, Subject) else load(target, parameters, outputs, unknown_inputs)
    check_functions(subject.model, subject.model_path)      # a function without C (besselj): one line, no traceback
    structure = _structure.analyze(subject)
    t1 = time.perf_counter()
    ranking = _ranking.rank(subject, structure, design=design, progress=progress) if rank else None
    t2 = time.perf_counter()
    return Analysis(subject, structure, ranking, {"structure": t1 - t0, "families": t2 - t1, "total": t2 - t0})
