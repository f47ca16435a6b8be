"""Statistics of a logged run gathered chunk by chunk, so a log of any size is validated in
bounded memory (:mod:`codegen.validation.csvlog` reads it in chunks).

:class:`ErrorStats` gives what :func:`codegen.validation.common.signal_stats` gives on whole
arrays (the row of :func:`codegen.validation.metrics.signal_report`; the same numbers on a log
of one chunk, merged by the parallel formulas of Chan et al. 1979 otherwise); :class:`Summary`
the mean, std, min and max of an estimate without reference, in the same unit;
:class:`Decimated` keeps a signal for plots: every sample up to :data:`KEEP_SAMPLES`, then every
2nd, 4th, ... so that at most that many are held.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import MetricInputError
from . import metrics

KEEP_SAMPLES = 1_000_000
"""Samples of each signal kept for plots and the result's ``signals`` (more: every k-th)."""


class _Moments:
    """Count, mean and sum of squared deviations of a 1-D stream."""

    def __init__(self):
        self.n, self.mean, self.m2 = 0, 0.0, 0.0

    def add(self, x: np.ndarray) -> None:
        m = x.size
        if not m:
            return
        mean = float(np.mean(x))
        d = x - mean
        m2 = float(np.sum(d * d))
        if not self.n:
            self.n, self.mean, self.m2 = m, mean, m2
            return
        n = self.n + m
        delta = mean - self.mean
        self.m2 += m2 + delta * delta * self.n * m / n
        self.mean += delta * m / n
        self.n = n


class ErrorStats:
    """Error statistics of an estimate against its reference, fed chunk by chunk: the row of
    :func:`codegen.validation.metrics.signal_report` (the one definition of every validation).

    ``unit``: the model's declared unit of the signal (a plane angle in rad is reported in deg,
    marked so); ``settle``: samples at t < settle (t from the log's start) are left out, as
    :func:`~codegen.validation.common.signal_stats` does with its ``t`` (the row's ``after_s``).
    """

    def __init__(self, unit: str | None, settle: float | None = None):
        self.unit, self.settle = unit, settle
        self.abs_sum, self.max_abs, self.sq_sum, self.truth_sq_sum = 0.0, 0.0, 0.0, 0.0
        self.est_sq_sum = 0.0
        self.err, self.ref = _Moments(), _Moments()
        self.nonfinite, self.first_nonfinite, self.seen = 0, None, 0

    def add(self, truth, est, t=None) -> None:
        y, yh = np.asarray(truth, dtype=float), np.asarray(est, dtype=float)
        offset = self.seen
        self.seen += y.size
        if self.settle is not None and t is not None:
            keep = np.asarray(t) >= self.settle
            y, yh = y[keep], yh[keep]
            offset += int(np.argmax(keep)) if keep.any() else 0
        bad = ~(np.isfinite(y) & np.isfinite(yh))
        if bad.any():
            if self.first_nonfinite is None:
                self.first_nonfinite = offset + int(np.flatnonzero(bad)[0])
            self.nonfinite += int(bad.sum())
            return
        e = yh - y
        a = np.abs(e)
        if a.size:
            self.abs_sum += float(a.sum())
            self.max_abs = max(self.max_abs, float(a.max()))
            self.sq_sum += float(np.sum(e * e))
            self.truth_sq_sum += float(np.sum(y * y))
            self.est_sq_sum += float(np.sum(yh * yh))
        self.err.add(e)
        self.ref.add(y)

    def scale_ratio(self) -> float | None:
        """RMS of the estimate / RMS of the reference over the compared samples (None: a reference
        of RMS 0 or no sample): about 1 for any observer worth its table, a unit factor (57.3 for
        deg/rad) when the reference column is in another unit than the one declared."""
        if not self.err.n or self.truth_sq_sum <= 0 or not math.isfinite(self.est_sq_sum):
            return None
        return math.sqrt(self.est_sq_sum / self.truth_sq_sum)

    def result(self) -> dict:
        """The :func:`~codegen.validation.metrics.signal_report` row (and ``after_s``), as
        :func:`~codegen.validation.common.signal_stats` gives it on the whole arrays.

        Raises
        ------
        MetricInputError
            no sample, or a non-finite one.
        """
        if self.nonfinite:
            raise MetricInputError(f"metric input holds {self.nonfinite} non-finite sample(s), first at index "
                                   f"{self.first_nonfinite}")
        row = metrics.report_from_sums(self.unit, n=self.err.n, abs_sum=self.abs_sum, abs_max=self.max_abs,
                                       sq_sum=self.sq_sum, mean=self.err.mean, m2=self.err.m2,
                                       truth_sq_sum=self.truth_sq_sum, truth_m2=self.ref.m2)
        row["after_s"] = self.settle
        return row


class Summary:
    """Mean, std, min and max of a stream, in the reported unit of its declared ``unit``
    (:func:`codegen.validation.metrics.reported_unit`: a plane angle in deg, marked so)."""

    def __init__(self, unit: str | None):
        self.unit, self.factor, self.converted = metrics.reported_unit(unit)
        self.m = _Moments()
        self.lo, self.hi = math.inf, -math.inf

    def add(self, x) -> None:
        x = np.asarray(x, dtype=float) * self.factor
        if x.size:
            self.lo, self.hi = min(self.lo, float(x.min())), max(self.hi, float(x.max()))
        self.m.add(x)

    def result(self) -> dict:
        row = {"unit": self.unit, "mean": self.m.mean, "std": math.sqrt(self.m.m2 / self.m.n) if self.m.n else math.nan,
               "min": self.lo, "max": self.hi}
        if self.converted is not None:
            row["converted_from"] = self.converted
        return row


class Decimated:
    """Signals kept for plots: all samples up to ``limit``, then every ``stride``-th (a power of 2)."""

    def __init__(self, limit: int | None = None):
        self.limit, self.stride, self.seen = int(KEEP_SAMPLES if limit is None else limit), 1, 0
        self.parts: dict = {}

    def add(self, cols: dict) -> None:
        n = len(next(iter(cols.values())))
        first = (-self.seen) % self.stride              # first index of this chunk on the grid
        for k, v in cols.items():
            self.parts.setdefault(k, []).append(np.asarray(v)[first::self.stride].copy())
        self.seen += n
        if sum(p.size for p in self.parts[next(iter(self.parts))]) > self.limit:
            self.parts = {k: [np.concatenate(v)[::2]] for k, v in self.parts.items()}
            self.stride *= 2

    def signals(self) -> dict:
        return {k: np.concatenate(v) if v else np.empty(0) for k, v in self.parts.items()}
