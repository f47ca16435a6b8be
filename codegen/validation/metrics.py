"""Per-signal estimation-error metrics, exactly as the paper papers define them.

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

Errors are ``estimate - reference``. Every function rejects empty, mismatched or non-finite input
with :class:`MetricInputError` (a :class:`codegen.errors.SampleError`); Sentouh et al. 2023 states the same
precondition ("the errors must not contain any NaN or Inf values").
"""
from __future__ import annotations

from dataclasses import dataclass, asdict

import numpy as np

from ..errors import MetricInputError

__all__ = [
    "MetricInputError", "ErrorStats", "error_stats", "mean_abs_error", "max_abs_error",
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
