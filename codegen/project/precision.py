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
table (:mod:`codegen.project.sensor_noise`: by the model's signal name, in its unit); ``noise`` here is
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

from ..settings import Rule, parse_settings, setting, suggest

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


def input_noise(config, inputs) -> dict:
    """{input name: standard deviation} of the sensor noise of an observer's ``inputs``: its observer
    file's ``[precision] noise`` table (which must agree with the parameter file's ``[sensor_noise]``),
    else ``[sensor_noise]`` (:mod:`codegen.project.sensor_noise`), else the family's validation noise of a
    measured ``y_NAME`` or a raw input ``NAME`` (:func:`codegen.project.sensor_noise.sensor_noise`);
    an input with none is left out. The float32 build's tolerance and ``validate --data``'s log checks
    use it.

    Raises
    ------
    ConfigurationError
        a ``[precision] noise`` key that is no input of the observer, or whose level disagrees with
        ``[sensor_noise]``.
    """
    import math
    from ..errors import ConfigurationError
    from ..model import load_parameters
    from . import sensor_noise as sensor
    spec = config.precision
    inputs = list(inputs)
    source = config.source or f"{config.name}.toml"
    for key in spec.noise:
        if key not in inputs:
            near = suggest(key, inputs) or suggest(f"y_{key}", inputs)     # the measured yawr is the input y_yawr
            raise ConfigurationError(f"{source}: [precision.noise] {key}: not an input of {config.name}; its inputs: "
                                     f"{', '.join(inputs)}" + (f" (did you mean {near!r}?)" if near else ""),
                                     source=source, section="precision.noise", key=key, allowed=", ".join(inputs))
    params = load_parameters(config.parameter_path)
    declared = sensor.observer_levels(inputs, config.load_model(), params)     # [sensor_noise]: the one place
    for key, value in spec.noise.items():
        if key in declared and not math.isclose(float(value), declared[key], rel_tol=1e-9, abs_tol=0.0):
            raise ConfigurationError(
                f"{source}: [precision.noise] {key} = {float(value):g} disagrees with the sensor noise {declared[key]:g} "
                f"that [sensor_noise] of {params.source} declares for it (in the model's unit): declare a sensor's noise "
                f"once, in [sensor_noise] (read by validate and the float32 build); remove {key} from [precision] noise",
                source=source, section="precision.noise", key=key,
                allowed=f"{declared[key]:g} (the [sensor_noise] level), or no entry")
    family = sensor.sensor_noise(config.observer_family)
    out = {}
    for name in inputs:
        if name in spec.noise:
            out[name] = float(spec.noise[name])
        elif name in declared:
            out[name] = declared[name]
        elif name.startswith("y_") and name[2:] in family:
            out[name] = float(family[name[2:]])
        elif name in family:
            out[name] = float(family[name])
    return out
