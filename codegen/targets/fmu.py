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
import re
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

from .. import __version__ as UIOGEN_VERSION
from ..project import observer_file as observers
from ..project import outputs
from .. import pipeline
from ..errors import ConfigurationError, UnknownObserverError, UnsupportedError, install_hint
from ..emit.header import unit_of
from ..emit.toolchain import STRICT_CFLAGS, compile_and_link, render_template

FMI2_HEADERS = Path(__file__).resolve().parent / "fmi2"
FMI3_HEADERS = Path(__file__).resolve().parent / "fmi3"
FORMATS = {"fmu": "2.0", "fmu3": "3.0"}
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


def _c_starts(b) -> str:
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


def model_description(b, guid: str, source_files: list) -> str:
    rows = variables(b)
    units = sorted({r[4] for r in rows if r[4]})
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(b.name)} guid="{guid}"',
           f'  description={quoteattr(description(b))}',
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
    starts = input_starts(b)
    for name, vr, causality, typ, unit, doc in rows:
        unit_attr = f" unit={quoteattr(unit)}" if unit else ""
        if causality == "input":
            out.append(f'    <ScalarVariable name={quoteattr(name)} valueReference="{vr}" description={quoteattr(doc)} '
                       f'causality="input" variability="discrete">')
            out.append(f'      <Real{unit_attr} start="{starts[name]!r}"/>')
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


def _current_sources(observer, out, fmt: str, binary: str) -> tuple:
    """(config, build, name, C file names, {file: text}) of an observer whose generated C is current:
    the checks both FMI versions make before anything is written (the .fmu suffix, the host the
    binary is built for, the generated files, the committed design and the C's stamp)."""
    from ..extension.build import check_generated, generated_dir, require_current
    config = observer if isinstance(observer, observers.ObserverConfig) else observers.get(str(observer))
    out = Path(out)
    if out.suffix != ".fmu":
        raise ConfigurationError(f"uiogen export --format {fmt}: --out must name a .fmu file, got {out}")
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise UnsupportedError(f"the FMU carries {binary} built by the host compiler; this host is "
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
    return config, pipeline.build(config), name, c_files, {f: (src_dir / f).read_text() for f in c_files}

def export_fmu(observer, out, log=print, fmi_version: str = "2.0") -> Path:
    """Write the FMU of ``observer`` (a built-in name, an observer file or a config) to ``out``:
    FMI 2.0 co-simulation, or FMI 3.0 with ``fmi_version="3.0"`` (:func:`export_fmu3`)."""
    if fmi_version == "3.0":
        return export_fmu3(observer, out, log)
    if fmi_version != "2.0":
        raise UnsupportedError(f"FMI version {fmi_version!r}: uiogen exports 2.0 and 3.0 co-simulation FMUs")
    config, b, name, c_files, sources = _current_sources(observer, out, "fmu", "a linux64 binary")
    out = Path(out)
    digest = hashlib.sha256("".join(f + sources[f] for f in c_files).encode())
    guid = "{" + str(uuid.UUID(hex=digest.hexdigest()[:32])) + "}"
    sources[f"{name}_fmu.c"] = render_template("fmu.c.j2", name=name, NAME=name.upper(), ts=repr(config.sample_time),
                                               input_start=_c_starts(b),
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
    outputs.make_folder(out.parent)
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


# ---- FMI 3.0 ---------------------------------------------------------------------------------------

FMI3_PLATFORM = "x86_64-linux"
# the functions fmu3.c.j2 implements; every other function of fmi3Functions.h gets a stub (fmi3Error)
FMI3_IMPLEMENTED = {"fmi3GetVersion", "fmi3SetDebugLogging", "fmi3InstantiateCoSimulation", "fmi3FreeInstance",
                    "fmi3EnterInitializationMode", "fmi3ExitInitializationMode", "fmi3EnterStepMode",
                    "fmi3Terminate", "fmi3Reset", "fmi3GetFloat64", "fmi3SetFloat64", "fmi3GetInt32", "fmi3DoStep"}


def _fmi3_signatures() -> dict:
    """{function: (return type, [(declaration, parameter name)])} of every function fmi3Functions.h
    exports, from the typedefs of fmi3FunctionTypes.h."""
    types = (FMI3_HEADERS / "fmi3FunctionTypes.h").read_text()
    exported = re.findall(r"FMI3_Export\s+fmi3(\w+)TYPE\s+fmi3\1\s*;", (FMI3_HEADERS / "fmi3Functions.h").read_text())
    out = {}
    for fn in exported:
        m = re.search(rf"typedef\s+([\w\s*]+?)\s*\(?\s*fmi3{fn}TYPE\s*\)?\s*\(([^;]*?)\)\s*;", types, re.S)
        if m is None:
            raise UnsupportedError(f"fmi3FunctionTypes.h: no typedef of fmi3{fn}TYPE")
        params = []
        for decl in (p.strip() for p in m.group(2).split(",")):
            if decl in ("", "void"):
                continue
            name = re.search(r"(\w+)\s*(\[\s*\])?$", decl).group(1)
            params.append((decl, name))
        out[f"fmi3{fn}"] = (" ".join(m.group(1).split()), params)
    return out


def fmi3_stubs() -> str:
    """C of every fmi3Functions.h function the wrapper does not implement: fmi3Error (NULL for an
    instantiation), the instance's logger told which function was called."""
    blocks = []
    for fn, (ret, params) in sorted(_fmi3_signatures().items()):
        if fn in FMI3_IMPLEMENTED:
            continue
        # "instance" is a parameter name of the standard and the wrapper's type name: renamed
        decls = [re.sub(r"\binstance\b", "inst", d) for d, _ in params] or ["void"]
        names = ["inst" if n == "instance" else n for _, n in params]
        body = [f"    (void){n};" for n in names if n != "inst"]
        if ret == "fmi3Status":
            body.append(f'    return unsupported({"inst" if "inst" in names else "NULL"}, "{fn}: not offered by this FMU");')
        elif ret == "fmi3Instance":
            body.append("    return NULL;")
        else:
            raise UnsupportedError(f"fmi3Functions.h: {fn} returns {ret}, which the stub generator does not know")
        if "inst" in names and ret != "fmi3Status":
            body.insert(0, "    (void)inst;")
        blocks.append(f"{ret} {fn}({', '.join(decls)})\n{{\n" + "\n".join(body) + "\n}")
    return "\n\n".join(blocks)


def model_description3(b, token: str) -> str:
    """modelDescription.xml of the FMI 3.0 FMU: time (value reference 0), the inputs, the outputs
    and the Int32 status, with the units and descriptions of the C API."""
    rows = variables(b)
    units = sorted({r[4] for r in rows if r[4]})
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<fmiModelDescription fmiVersion="3.0" modelName={quoteattr(b.name)} instantiationToken="{token}"',
           f'  description={quoteattr(description(b))}',
           f'  generationTool="uiogen {UIOGEN_VERSION}" variableNamingConvention="flat">',
           f'  <CoSimulation modelIdentifier={quoteattr(b.name)} canHandleVariableCommunicationStepSize="false"',
           '    canGetAndSetFMUState="false" canSerializeFMUState="false" providesDirectionalDerivatives="false"',
           '    providesAdjointDerivatives="false" providesIntermediateUpdate="false" canReturnEarlyAfterIntermediateUpdate="false"',
           '    hasEventMode="false" fixedInternalStepSize=' + f'"{b.config.sample_time!r}"/>']
    if units:
        out.append('  <UnitDefinitions>')
        out += [f'    <Unit name={quoteattr(u)}/>' for u in units]
        out.append('  </UnitDefinitions>')
    out.append(f'  <DefaultExperiment startTime="0.0" stepSize="{b.config.sample_time!r}"/>')
    out.append('  <ModelVariables>')
    out.append('    <Float64 name="time" valueReference="0" causality="independent" variability="continuous" '
               'description="simulation time"/>')
    starts = input_starts(b)
    for name, vr, causality, typ, unit, doc in rows:
        unit_attr = f" unit={quoteattr(unit)}" if unit else ""
        kind = "Float64" if typ == "Real" else "Int32"
        start = repr(starts[name]) if causality == "input" else "0.0" if typ == "Real" else "0"
        extra = ' initial="exact"' if causality == "output" else ""
        out.append(f'    <{kind} name={quoteattr(name)} valueReference="{vr + 1}" description={quoteattr(doc)} '
                   f'causality="{causality}" variability="discrete"{extra}{unit_attr} start="{start}"/>')
    out.append('  </ModelVariables>')
    out.append('  <ModelStructure>')
    out += [f'    <Output valueReference="{r[1] + 1}"/>' for r in rows if r[2] == "output"]
    out += ['  </ModelStructure>', '</fmiModelDescription>', '']
    return "\n".join(out)


def build_description3(name: str, c_sources: list) -> str:
    """sources/buildDescription.xml: how to compile the FMU from its sources (FMI 3.0)."""
    files = "\n".join(f'      <SourceFile name={quoteattr(f)}/>' for f in c_sources)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier={quoteattr(name)}>\n    <SourceFileSet language="C99">\n'
            f'{files}\n    </SourceFileSet>\n  </BuildConfiguration>\n</fmiBuildDescription>\n')


def export_fmu3(observer, out, log=print) -> Path:
    """Write the FMI 3.0 co-simulation FMU of ``observer`` to ``out`` (``uiogen export --format
    fmu3``): ``modelDescription.xml``, ``sources/`` (the generated C, the wrapper rendered from
    ``fmu3.c.j2``, the FMI 3.0 headers and ``buildDescription.xml``) and
    ``binaries/x86_64-linux/NAME.so``, compiled with the strict flags like the FMI 2.0 FMU."""
    config, b, name, c_files, sources = _current_sources(observer, out, "fmu3", "an x86_64-linux binary")
    out = Path(out)
    digest = hashlib.sha256(("fmi3" + "".join(f + sources[f] for f in c_files)).encode())
    token = "{" + str(uuid.UUID(hex=digest.hexdigest()[:32])) + "}"
    sources[f"{name}_fmu3.c"] = render_template("fmu3.c.j2", name=name, NAME=name.upper(), ts=repr(config.sample_time),
                                                input_start=_c_starts(b),
                                                guid=token, stubs=fmi3_stubs())
    for h in sorted(FMI3_HEADERS.glob("fmi3*.h")):
        sources[h.name] = h.read_text()
    c_sources = [f"{name}_kernel.c", f"{name}.c", f"{name}_fmu3.c"]
    sources["buildDescription.xml"] = build_description3(name, c_sources)
    md = model_description3(b, token)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for f, text in sources.items():
            (tmp / f).write_text(text)
        (tmp / "bin").mkdir()
        so = compile_and_link([tmp / f for f in c_sources], tmp / "bin" / f"{name}.so", include=[tmp],
                              flags=STRICT_CFLAGS, shared=True, object_dir=tmp / "obj")
        files = {"modelDescription.xml": md.encode(), f"binaries/{FMI3_PLATFORM}/{name}.so": so.read_bytes(),
                 **{f"sources/{f}": text.encode() for f, text in sources.items()}}
    outputs.make_folder(out.parent)
    _zip(out, files)
    log(f"{name}: wrote {out} (FMI 3.0 co-simulation, {len(variables(b)) + 1} variables, step "
        f"{config.sample_time:g} s, binaries/{FMI3_PLATFORM}/{name}.so and sources/)")
    return out
