"""The ``[precision]`` table of an observer file: what the float32 build is held to.

``uiogen build --float32`` (:mod:`codegen.targets.float32`) bounds, per output signal and in its
unit, how far the single-precision step's estimate can drift from the double step's, and
accepts the float build when every bound is within that signal's tolerance. The tolerance is
physical: a declared fraction of what the sensors' noise already does to the estimate::

    [precision]
    fraction = 0.1                       # tolerance = 0.1 x the estimate's RMS response to the sensor noise
    noise = { y_r = 8.7e-4 }             # input -> std of its sensor noise [its unit]; better: [sensor_noise] r
                                         # of the parameter file (one place, read by validate too)
    tolerance = { T_d = 0.05 }           # output -> absolute tolerance [its unit], instead of the rule
    uncertified_states = "measured"      # or "refuse" (the default), see below
    accumulation = "compensated"         # or "plain" (the default), see below

The sensor noise is declared once, for every verb, in the parameter file's ``[sensor_noise]``
table (:mod:`codegen.validation.noise`: by the model's signal name, in its unit); ``noise`` here is
the former place, still read, and must agree with it (a ConfigurationError naming both files where
they differ). An input declared in neither takes the family's validation noise for that signal
(:meth:`Family.sensor_noise`, a measured ``y_NAME`` or a raw input ``NAME``); an input with none
of them is taken noise free. An output whose estimate no declared noise moves needs a
``tolerance``: the build says which.

State with dynamics of its own that no certificate covers (the sliding-mode differentiators:
they converge in finite time but do not contract, so no norm bounds how far two runs drift
apart) has no bound, only its measured deviation. By default such an observer's float build is
refused; ``uncertified_states = "measured"`` accepts it on the measured deviation of that state
(every output it reaches is still bounded from there, and the report says which are).

``accumulation = "compensated"`` changes the float32 C, not the design (and not the double C): the
kernel also returns the increment ``dz`` of the certified state as the step forms it (the
Gauss-Legendre step's ``h (b1 K1 + b2 K2)``, at its own scale: never a difference of state-sized
numbers), and the step adds ``dz + c`` to the state ``z`` by TwoSum, keeping the rounding error of
that addition in a compensation entry ``c`` (``NAME_comp``, the first entries of the float32 state
vector). The estimate the step carries is then ``z + c``, not ``z`` rounded to float: the half-ulp
storage rounding of every sample is no longer accumulated. The outputs are ``z`` (within ``|c|``
of it). What it costs: per certified entry, one more float of state and seven additions per
sample. Only a family whose step has such an increment form offers it
(:meth:`ObserverBuild.increment_function`); another is a ``ConfigurationError``.

Not part of the design: editing this table never re-solves.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .settings import Rule, parse_settings, setting

DEFAULT_FRACTION = 0.1

_POSITIVE = Rule(float, gt=0)


@dataclass(frozen=True)
class PrecisionSettings:
    """The float32 build's tolerances (see the module docstring)."""

    fraction: float = setting(DEFAULT_FRACTION, gt=0, le=1,
                              doc="tolerance as a fraction of the estimate's RMS response to the sensor noise")
    noise: dict = setting(default_factory=dict, items=_POSITIVE,
                          doc="input name -> standard deviation of its sensor noise, in its unit")
    tolerance: dict = setting(default_factory=dict, items=_POSITIVE,
                              doc="output name -> absolute tolerance of the float32 deviation, in its unit")
    uncertified_states: str = setting("refuse", choices=("refuse", "measured"),
                                      doc="state with own dynamics no certificate covers (a sliding-mode "
                                          "differentiator): refuse the float build, or take its measured deviation")
    accumulation: str = setting("plain", choices=("plain", "compensated"),
                                doc="the float32 update of the certified state: z + dz rounded (plain), or dz added "
                                    "by TwoSum with its rounding error carried in compensation entries of the state")


def parse(table, source: str) -> PrecisionSettings:
    """The ``[precision]`` table, every key and value checked (ConfigurationError naming the file)."""
    return parse_settings(PrecisionSettings, table or {}, source=source, section="precision")
