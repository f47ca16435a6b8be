"""The car's sensor noise as declared: the parameter file's ``[sensor_noise]`` table, read and
checked against the model, for every verb that needs it.

A parameter file's ``[sensor_noise]`` table gives the standard deviation of the white noise on
each measured signal, by the model's name of the signal and in its unit::

    [sensor_noise]                          # the car's sensors (datasheets, or a still-stand log)
    r = 8.7e-4                              # rad/s: the model's unit of output r
    a_y = { std = 0.05, unit = "m/s^2" }    # with its unit: converted to the model's (deg/s, km/h, ...)
    v_x = { std = 0.18, unit = "km/h" }     # a measured scheduling signal
    delta = 3.5e-4                          # a measured known input (rad)

A measured signal is an output of the model (``r`` is what the observer reads as ``y_r``), a known
input, or a scheduling signal the observer reads (not one derived from the outputs). Who reads it:

* ``uiogen validate NAME --scenario excitation`` adds seeded white noise at these levels to what the
  observer reads (:mod:`codegen.validation.noise` draws it; ``--noise-free``: without; no table:
  noise free, and the header says so);
* ``uiogen build --float32`` takes them as the sensor noise its tolerance is a fraction of
  (:func:`codegen.project.precision.input_noise`; the observer file's ``[precision] noise``, the
  former place, must agree with them);
* ``uiogen new`` writes a starter's table (:mod:`codegen.project.starter`).

No design derives from the table: :func:`python_bindings.integrity.parameters_sha256` leaves it out,
so declaring or editing it re-solves nothing and keeps every extension current.
"""
from __future__ import annotations

import numpy as np

from ..errors import UnitError
from ..settings import config_error, suggest

SENSOR_NOISE = {"r": np.deg2rad(0.05), "delta": np.deg2rad(0.02), "delta_dot": np.deg2rad(0.2), "a_y": 0.05}
"""The library's own validation runs: the standard deviation they add per measured signal (a family's own
levels where it has them, :func:`sensor_noise`). Here, beside the car's
declared noise, not with the validation: the float32 build reads it, and a design's stamp stays off the
validation's modules."""


def sensor_noise(family) -> dict:
    """Standard deviation per measured signal of ``family``'s validation runs: its own
    (:class:`~codegen.contract.capabilities.Campaigns`), else the common one of the library's validations."""
    from ..contract.capabilities import Campaigns
    if isinstance(family, Campaigns):
        return family.sensor_noise()
    return dict(SENSOR_NOISE)


def measured_signals(model) -> dict:
    """{name: kind} of the signals of ``model`` a sensor measures: outputs, known inputs, scheduling
    signals that are not derived from the outputs."""
    out = {name: "output" for name, _ in model.outputs}
    for u in model.known_inputs:
        out.setdefault(str(u), "known input")
    for g in model.scheduling:
        if g.derived is None:
            out.setdefault(str(g.symbol), "scheduling signal")
    return out


def _convert(std: float, given: str, unit: str | None, source: str, key: str) -> float:
    """``std`` in ``given`` expressed in the model's ``unit`` (UnitError naming the file and key when
    the two are not of one dimension, or the model declares none)."""
    from ..model.dimensions import DimensionError, unit as parse
    where = f"{source}: [sensor_noise.{key}] unit = {given!r}"
    if unit is None:
        raise UnitError(f"{where}: the model declares no unit for {key}, so none can be converted to; drop the unit "
                        f"(std is then in the model's own unit of {key}) or declare {key}'s unit in the model "
                        f"(units={{\"{key}\": \"...\"}})")
    try:
        have, to_si = parse(given)
    except DimensionError as exc:
        raise UnitError(f"{where}: {exc}") from None
    want, from_si = parse(unit)
    if have != want:
        raise UnitError(f"{where}: not a unit of {key}, which the model declares in {unit!r}; allowed: {unit!r} or "
                        f"a unit of the same dimension (e.g. deg/s for rad/s, km/h for m/s)")
    return std * to_si / from_si


def declared(model, params) -> dict:
    """{measured signal: standard deviation in the model's unit} of ``params``' ``[sensor_noise]``.

    Raises
    ------
    ConfigurationError
        a key that is no measured signal of the model (with a did-you-mean: ``y_r`` is ``r``).
    UnitError
        a ``unit`` of another dimension than the signal's.
    """
    signals = measured_signals(model)
    units = dict(model.units or {})
    out = {}
    for key, spec in (getattr(params, "sensor_noise", None) or {}).items():
        if key not in signals:
            near = (key[2:] if key.startswith("y_") and key[2:] in signals else suggest(key, list(signals)))
            listed = ", ".join(f"{n} ({k})" for n, k in signals.items()) or "none"
            raise config_error(params.source, "sensor_noise", key, spec["std"],
                               f"not a measured signal of model {model.name!r}; its measured signals: {listed}", near)
        std = spec["std"]
        if spec.get("unit") is not None and spec["unit"] != units.get(key):
            std = _convert(std, spec["unit"], units.get(key), params.source, key)
        out[key] = float(std)
    return out


def column_signal(column: str, signals) -> str | None:
    """The measured signal an observer input column reads (``y_r`` -> ``r``, ``v_x`` -> ``v_x``), or None."""
    if column.startswith("y_") and column[2:] in signals:
        return column[2:]
    return column if column in signals else None


def observer_levels(input_names, model, params) -> dict:
    """{observer input column: standard deviation} of the declared noise of the signals it reads."""
    levels = declared(model, params)
    out = {}
    for col in input_names:
        sig = column_signal(col, levels)
        if sig is not None:
            out[col] = levels[sig]
    return out
