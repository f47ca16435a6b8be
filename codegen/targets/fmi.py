"""What the FMI targets share (:mod:`codegen.targets.fmu`, FMI 2.0; :mod:`codegen.targets.fmu3`,
FMI 3.0): the FMU's description, its variables and their start values, the checks made before
anything is written, the compile-and-zip tail, and :func:`run_fmu` (FMPy's simulation of either).

An FMU holds ``modelDescription.xml`` (inputs, outputs and the status as FMI variables, with the
units and descriptions of the observer's C API, the sample time as the default communication
step), ``sources/`` (the generated C, the target's FMI wrapper and the FMI headers) and the binary
compiled from those sources with the host compiler and the project's strict flags (no fast-math,
no FMA contraction: the same bits as the Python extension). One step of ``k`` sample times takes
``k`` samples with the inputs held.
"""
from __future__ import annotations

import hashlib
import io
import platform
import re
import tempfile
import uuid
import zipfile
from pathlib import Path

from ..project import observer_file as observers
from ..project import outputs
from .. import pipeline
from ..errors import ConfigurationError, UnsupportedError, install_hint
from ..emit.header import unit_of
from ..emit.toolchain import STRICT_CFLAGS, compile_and_link
from .base import generated_c

# Fixed entry time of every file in the archive: the same sources give the same zip entries.
ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def description(b) -> str:
    """The FMU's ``description``: the first paragraph of the observer file's header comment without
    its commands and notes (a ``next: uiogen design ...`` line, ``note:`` lines, the starter's ``then:`` and
    its command lines); when nothing is left, the family and the observer's name."""
    from .. import families
    lines = []
    try:
        with open(b.config.source, encoding="utf-8") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                text = line.lstrip("#").strip()
                if not text:
                    if lines:
                        break           # the first paragraph only
                    continue
                if not observers.HINT_LINE.match(text):
                    lines.append(text)
    except OSError:
        lines = [b.config.doc] if b.config.doc else []
    sentences = re.split(r"(?<=\.)\s+", " ".join(lines))
    text = " ".join(s for s in sentences if s and not re.search(r"\b(then|next):\s*$", s)).strip()
    if text:
        return text
    family = families.get(b.config.family)
    return f"observer {b.name}: {family.title} ({family.short_citation or family.citation})".strip()


def input_starts(b) -> dict:
    """{input: start value} of the FMU's inputs: 0.0, except for an input with a box that excludes 0
    (a scheduling signal's ``[scheduling.NAME]``, a measured state's ``[state_bounds] NAME`` for an
    input ``y_NAME`` of an output that is the state NAME): the midpoint of its box, so an FMU whose
    importer has not set it yet starts inside the box (at 0.0, outside a speed's [5, 25], the step
    clamps it and flags SCHEDULING_CLAMPED)."""
    from ..model import load_parameters
    params = load_parameters(b.config.parameter_path)
    boxes = {k: (box.lower, box.upper) for k, box in params.scheduling.items()}
    model = b.config.load_model()
    states = {str(s) for s in getattr(model, "states", ())}
    for name, expr in getattr(model, "outputs", ()):
        sym = str(expr)
        if sym in states and sym in params.state_bounds:
            boxes.setdefault(f"y_{name}", tuple(params.state_bounds[sym]))
    out = {}
    for n in b.input_names:
        lo, hi = (float(v) for v in boxes.get(n, (0.0, 0.0)))
        out[n] = 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi)
    return out


def c_starts(b) -> str:
    """The C initializer of the wrapper's INPUT_START (the same values as the XML's start)."""
    starts = input_starts(b)
    return ", ".join(repr(float(starts[n])) for n in b.input_names)


def variables(b) -> list:
    """The FMI variables: (name, value reference, causality, type, unit, description)."""
    from ..emit.generate import signal_fields
    _, inputs, outputs = signal_fields(b, b.step_function())      # every signal documented, as in the C header
    rows = [(s["name"], k, "input", "Real", unit_of(s["doc"]), s["doc"]) for k, s in enumerate(inputs)]
    rows += [(s["name"], len(inputs) + k, "output", "Real", unit_of(s["doc"]), s["doc"])
             for k, s in enumerate(outputs)]
    rows.append(("status", len(inputs) + len(outputs), "output", "Integer", "",
                 "status bits of the step (OR over the samples of the communication step): 1 scheduling "
                 "clamped, 2 non-finite input, 4 numerical failure, 8 warming up; 0 nominal"))
    names = [r[0] for r in rows]
    if len(set(names)) != len(names):
        raise UnsupportedError(f"{b.name}: an input or output is called 'status' (or two share a name); "
                               f"the FMU's variable names must be unique")
    return rows


def _zip(out: Path, files: dict) -> None:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for arcname in sorted(files):
            info = zipfile.ZipInfo(arcname, date_time=ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, files[arcname])
    outputs.write_atomic(out, buf.getvalue())


def current_sources(observer, out, fmt: str, binary: str) -> tuple:
    """(config, build, name, C file names, {file: text}) of an observer whose generated C is current:
    the checks both FMI versions make before anything is written (the .fmu suffix, the host the
    binary is built for, the generated files, the committed design and the C's stamp)."""
    config = observer if isinstance(observer, observers.ObserverConfig) else observers.get(str(observer))
    out = Path(out)
    if out.suffix != ".fmu":
        raise ConfigurationError(f"uiogen export --format {fmt}: --out must name a .fmu file, got {out}")
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise UnsupportedError(f"the FMU carries {binary} built by the host compiler; this host is "
                               f"{platform.system()} {platform.machine()}")
    name = config.name
    c_files = [f"{name}_kernel.c", f"{name}.c", f"{name}_kernel.h", f"{name}.h"]
    _, generated = generated_c(config)
    return config, pipeline.build(config), name, c_files, {f: generated[f] for f in c_files}


def compile_and_zip(out, name: str, sources: dict, c_sources: list, model_description: str, platform_dir: str) -> None:
    """The tail both FMI versions share: ``sources`` ({file: text}) written to a temporary folder,
    ``c_sources`` compiled and linked with the strict flags into ``binaries/PLATFORM_DIR/NAME.so``,
    and the FMU (``modelDescription.xml``, the binary, ``sources/``) zipped to ``out``."""
    out = Path(out)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for f, text in sources.items():
            (tmp / f).write_text(text)
        (tmp / "bin").mkdir()
        so = compile_and_link([tmp / f for f in c_sources], tmp / "bin" / f"{name}.so", include=[tmp],
                              flags=STRICT_CFLAGS, shared=True, object_dir=tmp / "obj")
        files = {"modelDescription.xml": model_description.encode(), f"binaries/{platform_dir}/{name}.so": so.read_bytes(),
                 **{f"sources/{f}": text.encode() for f, text in sources.items()}}
    outputs.make_folder(out.parent)
    _zip(out, files)


def guid(text: str) -> str:
    """A GUID (FMI 2.0) or instantiation token (FMI 3.0) of the FMU's sources: the same sources,
    the same token."""
    digest = hashlib.sha256(text.encode())
    return "{" + str(uuid.UUID(hex=digest.hexdigest()[:32])) + "}"


def run_fmu(path, inputs, input_names, output_names):
    """Simulate the FMU with FMPy over an (n, n_input) input sequence, one sample per
    communication step (inputs at t_k = k Ts); returns (outputs (n, n_output), status (n,)),
    row k the result of the doStep from t_k, as :meth:`CompiledObserver.run` returns them."""
    try:
        import fmpy
    except ImportError:
        raise UnsupportedError(f"FMPy is not installed: {install_hint('fmu')}") from None
    import numpy as np
    md = fmpy.read_model_description(str(path))
    ts = float(md.defaultExperiment.stepSize)
    n = inputs.shape[0]
    signals = np.zeros(n, dtype=[("time", np.float64)] + [(c, np.float64) for c in input_names])
    signals["time"] = np.arange(n) * ts
    for j, c in enumerate(input_names):
        signals[c] = inputs[:, j]
    res = fmpy.simulate_fmu(str(path), start_time=0.0, stop_time=n * ts, step_size=ts, output_interval=ts,
                            input=signals, output=[*output_names, "status"], validate=True)
    if len(res) != n + 1:
        raise UnsupportedError(f"FMPy recorded {len(res)} rows for {n} communication steps")
    out = np.column_stack([res[c][1:] for c in output_names])
    return out, np.asarray(res["status"][1:], dtype=np.int32)
