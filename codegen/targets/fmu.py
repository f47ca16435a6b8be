"""``uiogen export NAME --format fmu``: an FMI 2.0 co-simulation FMU of a generated observer.

The FMU holds ``modelDescription.xml`` (inputs, outputs and the status as FMI variables, with the
units and descriptions of the observer's C API, the sample time as the default communication
step), ``sources/`` (the generated C, the FMI wrapper rendered from
``codegen/emit/templates/fmu.c.j2`` and the FMI 2.0 headers of ``codegen/targets/fmi2/``) and
``binaries/linux64/NAME.so``, compiled from those sources with the host compiler and the
project's strict flags (no fast-math, no FMA contraction: the same bits as the Python
extension). One ``fmi2DoStep`` of ``k`` sample times takes ``k`` samples with the inputs held.
"""
from __future__ import annotations

import hashlib
import io
import platform
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

from .. import __version__ as UIOGEN_VERSION
from ..project import observer_file as observers
from ..project import outputs
from .. import pipeline
from ..errors import ConfigurationError, UnknownObserverError, UnsupportedError
from ..emit.header import unit_of
from ..emit.toolchain import STRICT_CFLAGS, compile_and_link, render_template

FMI2_HEADERS = Path(__file__).resolve().parent / "fmi2"
# Fixed entry time of every file in the archive: the same sources give the same zip entries.
ZIP_TIME = (1980, 1, 1, 0, 0, 0)


def variables(b) -> list:
    """The FMI variables: (name, value reference, causality, type, unit, description)."""
    _, inputs, outputs = b.signal_docs()
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


def model_description(b, guid: str, source_files: list) -> str:
    rows = variables(b)
    units = sorted({r[4] for r in rows if r[4]})
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(b.name)} guid="{guid}"',
           f'  description={quoteattr(b.config.doc)}',
           f'  generationTool="uiogen {UIOGEN_VERSION}" variableNamingConvention="flat" numberOfEventIndicators="0">',
           f'  <CoSimulation modelIdentifier={quoteattr(b.name)} canHandleVariableCommunicationStepSize="false"',
           '    canInterpolateInputs="false" canBeInstantiatedOnlyOncePerProcess="false"',
           '    canGetAndSetFMUstate="false" canSerializeFMUstate="false" providesDirectionalDerivative="false">',
           '    <SourceFiles>']
    out += [f'      <File name={quoteattr(f)}/>' for f in source_files]
    out += ['    </SourceFiles>', '  </CoSimulation>']
    if units:
        out.append('  <UnitDefinitions>')
        out += [f'    <Unit name={quoteattr(u)}/>' for u in units]
        out.append('  </UnitDefinitions>')
    out.append(f'  <DefaultExperiment startTime="0.0" stepSize="{b.config.sample_time!r}"/>')
    out.append('  <ModelVariables>')
    for name, vr, causality, typ, unit, doc in rows:
        unit_attr = f" unit={quoteattr(unit)}" if unit else ""
        if causality == "input":
            out.append(f'    <ScalarVariable name={quoteattr(name)} valueReference="{vr}" description={quoteattr(doc)} '
                       f'causality="input" variability="discrete">')
            out.append(f'      <Real{unit_attr} start="0.0"/>')
        else:
            start = "0.0" if typ == "Real" else "0"
            out.append(f'    <ScalarVariable name={quoteattr(name)} valueReference="{vr}" description={quoteattr(doc)} '
                       f'causality="output" variability="discrete" initial="exact">')
            out.append(f'      <{typ}{unit_attr} start="{start}"/>')
        out.append('    </ScalarVariable>')
    out.append('  </ModelVariables>')
    out.append('  <ModelStructure>')
    out.append('    <Outputs>')
    out += [f'      <Unknown index="{i + 1}"/>' for i, r in enumerate(rows) if r[2] == "output"]
    out += ['    </Outputs>', '  </ModelStructure>', '</fmiModelDescription>', '']
    return "\n".join(out)


def _zip(out: Path, files: dict) -> None:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for arcname in sorted(files):
            info = zipfile.ZipInfo(arcname, date_time=ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, files[arcname])
    outputs.write_atomic(out, buf.getvalue())


def export_fmu(observer, out, log=print) -> Path:
    """Write the FMU of ``observer`` (a built-in name, an observer file or a config) to ``out``."""
    from ..extension.build import check_generated, generated_dir, require_current
    config = observer if isinstance(observer, observers.ObserverConfig) else observers.get(str(observer))
    out = Path(out)
    if out.suffix != ".fmu":
        raise ConfigurationError(f"uiogen export --format fmu: --out must name a .fmu file, got {out}")
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise UnsupportedError(f"the FMU carries a linux64 binary built by the host compiler; this host is "
                               f"{platform.system()} {platform.machine()}")
    name = config.name
    src_dir = generated_dir(config)
    c_files = [f"{name}_kernel.c", f"{name}.c", f"{name}_kernel.h", f"{name}.h"]
    missing = [f for f in c_files if not (src_dir / f).is_file()]
    if missing:
        raise UnknownObserverError(f"observer {name!r} has not been generated (no {src_dir / missing[0]}); "
                                   f"run `uiogen generate {name if config.builtin else config.source}`")
    require_current(config)        # the committed design is the current one,
    check_generated(config)        # and the C is what generate wrote from it (its stamp), never as found
    b = pipeline.build(config)
    sources = {f: (src_dir / f).read_text() for f in c_files}
    digest = hashlib.sha256("".join(f + sources[f] for f in c_files).encode())
    guid = "{" + str(uuid.UUID(hex=digest.hexdigest()[:32])) + "}"
    sources[f"{name}_fmu.c"] = render_template("fmu.c.j2", name=name, NAME=name.upper(), ts=repr(config.sample_time),
                                               guid=guid, vr_status=len(variables(b)) - 1)
    for h in sorted(FMI2_HEADERS.glob("fmi2*.h")):
        sources[h.name] = h.read_text()
    c_sources = [f"{name}_kernel.c", f"{name}.c", f"{name}_fmu.c"]
    md = model_description(b, guid, c_sources)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for f, text in sources.items():
            (tmp / f).write_text(text)
        (tmp / "bin").mkdir()
        so = compile_and_link([tmp / f for f in c_sources], tmp / "bin" / f"{name}.so", include=[tmp],
                              flags=STRICT_CFLAGS, shared=True, object_dir=tmp / "obj")
        files = {"modelDescription.xml": md.encode(), f"binaries/linux64/{name}.so": so.read_bytes(),
                 **{f"sources/{f}": text.encode() for f, text in sources.items()}}
    out.parent.mkdir(parents=True, exist_ok=True)
    _zip(out, files)
    log(f"{name}: wrote {out} (FMI 2.0 co-simulation, {len(variables(b))} variables, step {config.sample_time:g} s, "
        f"binaries/linux64/{name}.so and sources/)")
    return out


def run_fmu(path, inputs, input_names, output_names):
    """Simulate the FMU with FMPy over an (n, n_input) input sequence, one sample per
    communication step (inputs at t_k = k Ts); returns (outputs (n, n_output), status (n,)),
    row k the result of the doStep from t_k, as :meth:`CompiledObserver.run` returns them."""
    try:
        import fmpy
    except ImportError:
        raise UnsupportedError("FMPy is not installed: pip install -c constraints.txt '.[fmu]'") from None
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
