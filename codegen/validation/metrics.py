"""Per-signal estimation-error metrics: one definition of each, and the papers' formats.

**One definition** (:func:`signal_report`, the rows of every ``uiogen validate`` table and
``--json`` report, every family): with ``e = estimate - truth`` over the samples compared,

====================  ==========================================================================
``unit``              the unit of every figure of the row: the model's declared unit, except a
                      plane angle declared in ``rad``, reported in ``deg`` (``converted_from``
                      then says ``"rad"``); angular rates (``rad/s``: yaw rates, wheel speeds)
                      stay as declared
``rms``               ``sqrt(mean(e²))``
``mae``               ``mean(|e|)``
``max``               ``max(|e|)``
``std``               standard deviation of ``e`` (ddof = 0)
``bias``              ``mean(e)``
``truth_rms``         ``sqrt(mean(truth²))``, the scale the error is set against
``truth_std``         ``sqrt(mean((truth - mean(truth))²))``: the error of estimating the truth's
                      mean all along
``no_information``    ``rms >= truth_std`` (NMSE <= 0): the estimate says nothing a constant would
                      not (None for a constant truth); ``uiogen validate`` names such estimates
``rms_percent``       ``100 rms / truth_rms`` (None for an all-zero truth)
``nmse_percent``      ``100 - 100 Σe² / Σ(truth - mean(truth))²`` (Sentouh et al. 2023 eq. (32):
                      100 is perfect, 0 no better than the truth's mean, negative worse; None
                      for a constant truth)
``samples``           how many samples were compared
====================  ==========================================================================

**The papers' formats** (the extra tables of each family, :func:`error_stats` and the functions
below it):

* Nguyen et al. 2019, Tables II-IV: ``E_mean`` (mean *absolute* error), ``E_max``
  (maximal absolute error), ``Std`` (standard deviation of the error), ``RMS`` (root mean square
  of the error); angles reported in degrees.
* Nguyen et al. 2021, Table II: ``MAE`` (mean absolute error) and ``RMSD`` (root-mean-square deviation).
* Sentouh et al. 2023, eq. (32)::

      NMSE_% = 100 - 100 ||y - ŷ||² / ||y - mean(y)||²
      RMSE_% = 100 sqrt( (1/N) Σ (y - ŷ)² )

  taken literally: ``RMSE_%`` is 100 times the RMS error in the signal's own units (the paper
  does not normalize it), ``NMSE_%`` is 100 times the coefficient of determination (100 is a
  perfect fit, it can be negative). ``NMSE_%`` is undefined for a constant reference signal.
  The interconnected family's Table 1 reads ``RMSE_%`` normalized by ``max |y|`` instead
  (its ``rmse_percent_of_max``); neither is the ``rms_percent`` above.

Errors are ``estimate - reference``. Every function rejects empty, mismatched or non-finite input
with :class:`MetricInputError` (a :class:`codegen.errors.SampleError`); Sentouh et al. 2023 states the same
precondition ("the errors must not contain any NaN or Inf values").
"""
from __future__ import annotations

from dataclasses import dataclass, asdict

import math

import numpy as np

from ..errors import MetricInputError

#: what each key of a :func:`signal_report` row means (``uiogen validate --json`` carries it)
DEFINITIONS = {
    "unit": "unit of every figure of the row: the model's declared unit, except a plane angle declared in rad, "
            "reported in deg (converted_from: rad); angular rates (rad/s) stay as declared",
    "converted_from": "the declared unit, present only where the figures were converted from it",
    "rms": "sqrt(mean(e^2)), e = estimate - truth over the samples compared",
    "mae": "mean(|e|)",
    "max": "max(|e|)",
    "std": "standard deviation of e (ddof 0)",
    "bias": "mean(e)",
    "truth_rms": "sqrt(mean(truth^2)) over the same samples",
    "truth_std": "the truth's RMS about its mean, sqrt(mean((truth - mean(truth))^2)), over the same samples: the "
                 "error of estimating the truth's mean (a constant) all along",
    "no_information": "true when rms >= truth_std (NMSE <= 0): the estimate carries no information about the signal's "
                      "variation, its mean would do as well (null for a constant truth)",
    "rms_percent": "100 rms / truth_rms (null for an all-zero truth)",
    "nmse_percent": "100 - 100 sum(e^2) / sum((truth - mean(truth))^2), Sentouh et al. 2023 eq. (32): 100 perfect, "
                    "0 no better than the truth's mean (null for a constant truth)",
    "samples": "samples compared",
    "after_s": "the samples compared are those at t >= after_s [s] (the settle time); null: every sample",
    "uninformative": "(top level) the estimates whose no_information is true, by name",
    "noise": "(top level) the sensor noise of the run; the excitation scenario's: mode (declared: the parameter file's "
             "[sensor_noise]; none declared; off: --noise-free), levels {observer input: standard deviation in the "
             "model's unit, units}, noise_free (inputs read without noise), source (the parameter file), seed; a family's "
             "scenario: {signal: standard deviation} of its paper's noise",
    "max_abs_ay": "(top level) max |a_y| [m/s^2] of the simulated truth's lateral acceleration, the model's output "
                  "named a_y; null when the model has no output of that name (no value is made up)",
}

#: declared unit -> (reported unit, factor): plane angles in degrees, as the field and the papers' tables
#: give them; nothing else is converted (a wheel speed in rad/s is no angle)
_REPORTED = {"rad": ("deg", 180.0 / math.pi)}
_CONVERSIONS = {("deg", "rad"): math.pi / 180.0, ("rad", "deg"): 180.0 / math.pi,
                ("deg/s", "rad/s"): math.pi / 180.0, ("rad/s", "deg/s"): 180.0 / math.pi}
_SCALED = ("rms", "mae", "max", "std", "bias", "truth_rms", "truth_std")

__all__ = [
    "MetricInputError", "DEFINITIONS", "reported_unit", "signal_report", "report_from_sums", "convert", "ErrorStats", "error_stats", "mean_abs_error", "max_abs_error",
    "std_error", "rms_error", "mae", "rmsd", "rmse_percent", "nmse_percent",
]


@dataclass(frozen=True)
class ErrorStats:
    """Error statistics of one signal (all in the reported unit, degrees when ``degrees=True``).

    Attributes
    ----------
    e_mean : float
        Mean absolute error (Nguyen et al. 2019 ``E_mean``; Nguyen et al. 2021 ``MAE``).
    e_max : float
        Maximal absolute error (Nguyen et al. 2019 ``E_max``).
    std : float
        Standard deviation of the signed error, population form (ddof = 0).
    rms : float
        Root mean square of the error (Nguyen et al. 2019 ``RMS``; Nguyen et al. 2021 ``RMSD``).
    n : int
        Number of samples.
    unit : str
        ``"deg"`` when converted from radians, else the caller's unit label.
    """

    e_mean: float
    e_max: float
    std: float
    rms: float
    n: int
    unit: str

    def as_dict(self) -> dict:
        """Return the statistics as a plain dictionary (for JSON reports)."""
        return asdict(self)


def _errors(reference, estimate, degrees: bool = False) -> np.ndarray:
    """Validated signed error ``estimate - reference`` (converted to degrees on request)."""
    try:
        y = np.asarray(reference, dtype=float)
        yh = np.asarray(estimate, dtype=float)
    except (TypeError, ValueError) as exc:
        raise MetricInputError(f"metric input is not numeric: {exc}") from None
    if y.ndim != 1 or yh.ndim != 1:
        raise MetricInputError(
            f"metric inputs must be 1-D arrays, got shapes {y.shape} and {yh.shape}")
    if y.shape != yh.shape:
        raise MetricInputError(f"reference has {y.size} samples, estimate has {yh.size}")
    if y.size == 0:
        raise MetricInputError("metric input is empty")
    bad = ~(np.isfinite(y) & np.isfinite(yh))
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise MetricInputError(
            f"metric input holds {int(bad.sum())} non-finite sample(s), first at index {first}")
    e = yh - y
    return np.degrees(e) if degrees else e


def mean_abs_error(reference, estimate, *, degrees: bool = False) -> float:
    """Mean absolute error, ``mean(|ŷ - y|)`` (Nguyen et al. 2019 ``E_mean``).

    Parameters
    ----------
    reference, estimate : array_like, 1-D, same length
        True and estimated signal.
    degrees : bool, optional
        Inputs are in radians; report the result in degrees.

    Returns
    -------
    float

    Raises
    ------
    MetricInputError
        Empty, mismatched or non-finite input.
    """
    return float(np.mean(np.abs(_errors(reference, estimate, degrees))))


def max_abs_error(reference, estimate, *, degrees: bool = False) -> float:
    """Maximal absolute error, ``max |ŷ - y|`` (Nguyen et al. 2019 ``E_max``). See :func:`mean_abs_error`."""
    return float(np.max(np.abs(_errors(reference, estimate, degrees))))


def std_error(reference, estimate, *, degrees: bool = False) -> float:
    """Standard deviation of the signed error (ddof = 0) (Nguyen et al. 2019 ``Std``)."""
    return float(np.std(_errors(reference, estimate, degrees)))


def rms_error(reference, estimate, *, degrees: bool = False) -> float:
    """Root mean square error, ``sqrt(mean((ŷ - y)²))`` (Nguyen et al. 2019 ``RMS``)."""
    e = _errors(reference, estimate, degrees)
    return float(np.sqrt(np.mean(e * e)))


def mae(reference, estimate, *, degrees: bool = False) -> float:
    """Mean absolute error (Nguyen et al. 2021 ``MAE``); identical to :func:`mean_abs_error`."""
    return mean_abs_error(reference, estimate, degrees=degrees)


def rmsd(reference, estimate, *, degrees: bool = False) -> float:
    """Root-mean-square deviation (Nguyen et al. 2021 ``RMSD``); identical to :func:`rms_error`."""
    return rms_error(reference, estimate, degrees=degrees)


def rms_difference_interval(error_a, error_b, *, block: int, draws: int = 4000, level: float = 0.95,
                            seed: int = 0) -> dict:
    """How sure is ``RMS(error_a) < RMS(error_b)``? A paired moving-block bootstrap of the difference.

    Two estimators' errors on the same samples are correlated in time and with each other (both
    miss the same manoeuvre), so neither samples nor estimators are resampled alone: each draw
    takes ``n // block`` blocks of ``block`` consecutive samples at uniform random starts, the
    same blocks for both errors, and computes ``RMS(a) - RMS(b)`` over them (Künsch 1989). The
    block should outlast the errors' correlation (seconds of a manoeuvre, not one sample).

    Parameters
    ----------
    error_a, error_b : array_like
        The two estimators' errors on the same samples (any unit; the result is in it).
    block : int
        Samples per block, 1 <= block <= n.
    draws, level, seed : int, float, int
        Bootstrap draws, the central interval's coverage, numpy's generator seed (deterministic).

    Returns
    -------
    dict
        ``difference`` (RMS(a) - RMS(b) on all samples), ``low``/``high`` (the central ``level``
        interval of the draws), ``share_below_zero`` (the share of draws where a is lower),
        ``block``, ``draws``, ``level``, ``samples``.
    """
    a, b = np.asarray(error_a, float), np.asarray(error_b, float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"the two errors must be 1-D and of one length (got {a.shape} and {b.shape})")
    n = a.size
    if not 1 <= block <= n:
        raise ValueError(f"block = {block}: must lie in [1, {n}] (the samples compared)")
    # sums of squares of every block by cumulative sums: a draw is k block starts
    sq = np.stack([np.concatenate([[0.0], np.cumsum(a * a)]), np.concatenate([[0.0], np.cumsum(b * b)])])
    sums = sq[:, block:] - sq[:, :-block]                       # (2, n - block + 1)
    k = n // block
    starts = np.random.default_rng(seed).integers(0, n - block + 1, size=(draws, k))
    rms = np.sqrt(sums[:, starts].sum(axis=2) / (k * block))   # (2, draws)
    d = rms[0] - rms[1]
    tail = 50.0 * (1.0 - level)
    return {"difference": float(np.sqrt(np.mean(a * a)) - np.sqrt(np.mean(b * b))),
            "low": float(np.percentile(d, tail)), "high": float(np.percentile(d, 100.0 - tail)),
            "share_below_zero": float(np.mean(d < 0)), "block": int(block), "draws": int(draws),
            "level": float(level), "samples": int(n)}


def rmse_percent(reference, estimate, *, degrees: bool = False) -> float:
    """``RMSE_%`` of Sentouh et al. 2023 eq. (32): ``100 * sqrt(mean((y - ŷ)²))``.

    Literal reading of (32): no normalization by the signal's range or RMS, so the value carries
    the signal's unit times 100 (degrees when ``degrees=True``).
    """
    return 100.0 * rms_error(reference, estimate, degrees=degrees)


def nmse_percent(reference, estimate) -> float:
    """``NMSE_%`` of Sentouh et al. 2023 eq. (32): ``100 - 100 ||y - ŷ||² / ||y - mean(y)||²``.

    Dimensionless (unit conversion cancels). 100 means a perfect estimate, 0 means no better
    than the reference's mean, negative means worse.

    Raises
    ------
    MetricInputError
        Empty, mismatched or non-finite input, or a constant reference (zero denominator).
    """
    e = _errors(reference, estimate)
    y = np.asarray(reference, dtype=float)
    den = float(np.sum((y - y.mean()) ** 2))
    if den == 0.0:
        raise MetricInputError("NMSE_% is undefined for a constant reference signal")
    return 100.0 - 100.0 * float(np.sum(e * e)) / den


def error_stats(reference, estimate, *, degrees: bool = False, unit: str = "") -> ErrorStats:
    """All Nguyen et al. 2019 statistics of one signal at once.

    Parameters
    ----------
    reference, estimate : array_like, 1-D, same length
    degrees : bool, optional
        Inputs in radians, statistics in degrees (``unit`` is then ``"deg"``).
    unit : str, optional
        Unit label stored with the statistics when ``degrees`` is False.

    Returns
    -------
    ErrorStats
    """
    e = _errors(reference, estimate, degrees)
    a = np.abs(e)
    return ErrorStats(e_mean=float(a.mean()), e_max=float(a.max()), std=float(e.std()),
                      rms=float(np.sqrt(np.mean(e * e))), n=int(e.size),
                      unit="deg" if degrees else unit)


def reported_unit(declared: str | None) -> tuple:
    """(unit of the reported figures, factor from the declared unit, the declared unit where it was
    converted else None): ``"rad"`` -> ``("deg", 180/pi, "rad")``; any other unit as declared (an
    undeclared one is None)."""
    from ..project.columns import normalize_unit
    if not declared:
        return None, 1.0, None
    unit = normalize_unit(declared)
    shown, factor = _REPORTED.get(unit, (unit, 1.0))
    return shown, factor, (unit if shown != unit else None)


def signal_report(reference, estimate, *, unit: str | None) -> dict:
    """Every figure of the one definition (module docstring, :data:`DEFINITIONS`) of one signal.

    Parameters
    ----------
    reference, estimate : array_like, 1-D, same length
        Truth and estimate, in the model's declared unit ``unit``.
    unit : str or None
        The model's declared unit of the signal (None: undeclared; figures as given).

    Returns
    -------
    dict
        ``unit`` (and ``converted_from``), ``rms``, ``mae``, ``max``, ``std``, ``bias``,
        ``truth_rms``, ``truth_std``, ``no_information``, ``rms_percent``, ``nmse_percent``, ``samples``.

    Raises
    ------
    MetricInputError
        Empty, mismatched or non-finite input.
    """
    e = _errors(reference, estimate)
    y = np.asarray(reference, dtype=float)
    a = np.abs(e)
    return report_from_sums(unit, n=e.size, abs_sum=float(a.sum()), abs_max=float(a.max()),
                            sq_sum=float(np.sum(e * e)), mean=float(e.mean()),
                            m2=float(np.sum((e - e.mean()) ** 2)), truth_sq_sum=float(np.sum(y * y)),
                            truth_m2=float(np.sum((y - y.mean()) ** 2)))


def report_from_sums(unit: str | None, *, n: int, abs_sum: float, abs_max: float, sq_sum: float, mean: float,
                     m2: float, truth_sq_sum: float, truth_m2: float) -> dict:
    """The :func:`signal_report` row from the sums of a stream (a log read in chunks gives the same
    row as the whole arrays), all in the declared ``unit``: error ``e`` = estimate - truth with
    ``abs_sum`` = Σ|e|, ``abs_max`` = max|e|, ``sq_sum`` = Σe², ``mean`` = mean(e), ``m2`` =
    Σ(e - mean(e))²; ``truth_sq_sum`` = Σy², ``truth_m2`` = Σ(y - mean(y))².

    Raises
    ------
    MetricInputError
        no sample.
    """
    if n <= 0:
        raise MetricInputError("metric input is empty")
    shown, k, converted = reported_unit(unit)
    rms = k * math.sqrt(sq_sum / n)
    truth_rms = k * math.sqrt(truth_sq_sum / n)
    row = {"unit": shown, "rms": rms, "mae": k * abs_sum / n, "max": k * abs_max, "std": k * math.sqrt(m2 / n),
           "bias": k * mean, "truth_rms": truth_rms, "truth_std": k * math.sqrt(truth_m2 / n),
           # Σe² >= Σ(y - mean y)²: the truth's mean, a constant, would estimate it as well (NMSE <= 0)
           "no_information": bool(sq_sum >= truth_m2) if truth_m2 > 0 else None,
           "rms_percent": 100.0 * rms / truth_rms if truth_rms > 0 else None,
           "nmse_percent": 100.0 - 100.0 * sq_sum / truth_m2 if truth_m2 > 0 else None,
           "samples": int(n)}
    if converted is not None:
        row["converted_from"] = converted
    return row


def convert(row: dict, unit: str) -> dict:
    """A :func:`signal_report` row with its dimensional figures in ``unit`` (deg <-> rad, deg/s <->
    rad/s), for a paper's table in the paper's units; the same row when it already is."""
    have = row.get("unit")
    if have == unit:
        return row
    factor = _CONVERSIONS.get((have, unit))
    if factor is None:
        raise MetricInputError(f"figures in {have!r} do not convert to {unit!r}")
    out = {**row, **{k: (None if row.get(k) is None else row[k] * factor) for k in _SCALED if k in row},
           "unit": unit}
    declared = row.get("converted_from", have)
    if declared == unit:
        out.pop("converted_from", None)
    else:
        out["converted_from"] = declared
    return out
