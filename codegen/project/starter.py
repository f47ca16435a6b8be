"""``uiogen new DIR --family F [--name NAME]``: a starter project that works as written.

A starter is the family's example observer (``Family.example``, a built-in observer) with its
model and parameter file copied beside it and wired to them by path: ``DIR/model.py``,
``DIR/parameters.toml``, ``DIR/NAME.toml``. The example's parameter file declares the ranges the
generic excitation scenario needs (``[inputs.NAME]``), so a starter designs, generates, builds and
validates (``uiogen validate DIR/NAME.toml --scenario excitation``) before the user edits a line;
``tests/product/test_families_and_verbs.py`` holds that, and every other verb, for every family.

The observer's name is the file's stem. It must not be a built-in observer's: a command given a
name resolves built-ins first, so ``uiogen generate NAME`` would regenerate the built-in, and both
extensions would be ``_NAME``. Every hint printed names the file by its path.
"""
from __future__ import annotations

import math
import re
import shlex
from pathlib import Path

from ..errors import ConfigurationError
from ..model.names import RULE as NAME_RULE, c_name_problem
from . import observer_file as observers, outputs


def default_name(family) -> str:
    return f"my_{family.name}"


def check_name(name: str) -> None:
    """An observer name for a new project: a C identifier, not a built-in observer's name."""
    why = c_name_problem(name)
    if why is None and len(name) > observers.MAX_NAME_LENGTH:
        why = f"has {len(name)} characters (at most {observers.MAX_NAME_LENGTH})"
    if why is not None:
        raise ConfigurationError(f"uiogen new --name {name!r}: {why}; an observer name is a C identifier "
                                 f"({NAME_RULE}): it names the C API NAME_step, its CasADi functions and the "
                                 f"extension _NAME",
                                 key="--name", value=name, allowed=f"a C identifier ({NAME_RULE})")
    if name in observers.names():
        raise ConfigurationError(f"uiogen new --name {name}: {name!r} is a built-in observer (uiogen list); a project "
                                 f"observer of that name would be shadowed by it wherever a name is given "
                                 f"(uiogen generate {name} regenerates the built-in): choose another name",
                                 key="--name", value=name, allowed="a name that is not a built-in observer's")


def write(folder: Path, family, name: str | None = None) -> Path:
    """Write the starter of ``family`` into ``folder``; the observer file's path.

    Raises
    ------
    ConfigurationError
        a name that collides with a built-in or is not a C identifier, a family without an
        example, or a file the starter would overwrite.
    """
    if not family.example:
        raise ConfigurationError(f"family {family.name!r} has no example observer to start from", key="--family",
                                 value=family.name)
    name = name or default_name(family)
    check_name(name)
    folder = Path(folder)
    example = observers.get(family.example)
    files = {folder / "model.py": example.model_path, folder / "parameters.toml": example.parameter_path}
    target = folder / f"{name}.toml"
    existing = [str(p) for p in [*files, target] if p.exists()]
    if existing:
        raise ConfigurationError(f"uiogen new {folder}: would overwrite {', '.join(existing)}; choose an empty folder",
                                 key="dir", value=str(folder))
    outputs.make_folder(folder)
    for dst, src in files.items():
        outputs.write_atomic(dst, src.read_text())
    params_text = files[folder / "parameters.toml"].read_text()
    if "sensor_noise" not in _tables(params_text):
        outputs.write_atomic(folder / "parameters.toml", params_text.rstrip("\n") + "\n\n" + sensor_table(example, family))
    text = Path(example.source).read_text()
    text = re.sub(r'^model = "[^"]*"', 'model = "model.py"', text, count=1, flags=re.M)
    text = re.sub(r'^parameters = "[^"]*"', 'parameters = "parameters.toml"', text, count=1, flags=re.M)
    head = (f"# Observer {name}: a starter for your own {family.title} ({family.citation}), copied from the\n"
            f"# built-in observer {family.example}. Edit model.py (your equations, sympy) and parameters.toml\n"
            f"# (your car; [inputs.NAME] ranges for the excitation scenario), then:\n"
            + "".join(f"#   {line}\n" for line in next_steps(target)) + "#\n")
    outputs.write_atomic(target, head + text)
    return target


def _tables(text: str) -> dict:
    import tomllib
    return tomllib.loads(text)


def sensor_table(example, family) -> str:
    """The starter's ``[sensor_noise]`` table (:mod:`codegen.project.sensor_noise`): a level for each measured
    signal of the example's model that has one (the example observer file's ``[precision] noise``,
    else the family's validation noise: the float32 build's levels until now, so it stays as it was),
    the others as a commented line to fill in from the sensor's datasheet."""
    from .sensor_noise import column_signal, measured_signals, sensor_noise
    model = example.load_model()
    signals = measured_signals(model)
    units = dict(model.units or {})
    levels = {}
    for col, std in example.precision.noise.items():
        sig = column_signal(col, signals)
        if sig is not None:
            levels[sig] = float(std)
    for sig, std in sensor_noise(family).items():
        if sig in signals:
            levels.setdefault(sig, float(std))
    lines = ["[sensor_noise]   # standard deviation of each measured signal's sensor noise, in its unit (a number) or",
             "                 # { std = ..., unit = \"deg/s\" }: `uiogen validate --scenario excitation` adds it (seeded);",
             "                 # the starter's levels are the family's validation noise: put your sensors' figures here"]
    for sig, kind in signals.items():
        unit = units.get(sig)
        note = f"# {unit + ', ' if unit else ''}{kind}"
        if sig in levels:       # repr: the very level the float32 build took (its tolerance stays as it was)
            deg = f" ({math.degrees(levels[sig]):.3g} {unit.replace('rad', 'deg')})" if unit in ("rad", "rad/s") else ""
            lines.append(f"{sig} = {levels[sig]!r}".ljust(31) + " " + note + deg)
        else:
            lines.append(f"# {sig} = ...".ljust(31) + " " + note + ": no level declared, read noise free")
    return "\n".join(lines) + "\n"


def next_steps(target: Path) -> list:
    """The commands that take a starter from its files to a validated compiled step."""
    t = shlex.quote(str(target))            # a folder named "my car" pastes back into a shell as one word
    return [f"uiogen design {t} --update", f"uiogen generate {t}", f"uiogen build {t}",
            f"uiogen validate {t} --scenario excitation"]
