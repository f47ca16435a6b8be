"""``uiogen export NAME --format fmu3``: an FMI 3.0 co-simulation FMU of a generated observer.

``modelDescription.xml`` (time as value reference 0, ``Float64`` inputs and outputs, an ``Int32``
status), ``sources/`` (the generated C, the wrapper rendered from ``templates/fmu3.c.j2`` here,
the FMI 3.0 headers of ``fmi3/`` here and ``buildDescription.xml``) and
``binaries/x86_64-linux/NAME.so``, compiled with the strict flags like the FMI 2.0 FMU
(:mod:`codegen.targets.fmi`). The wrapper implements co-simulation; every other function of
``fmi3Functions.h`` answers ``fmi3Error`` (:func:`fmi3_stubs`).
"""
from __future__ import annotations

import re
from pathlib import Path
from xml.sax.saxutils import quoteattr

from ... import __version__ as UIOGEN_VERSION
from ...emit.toolchain import render_template
from ...errors import UnsupportedError
from .. import fmi
from ..base import Target

HERE = Path(__file__).resolve().parent
FMI3_HEADERS = HERE / "fmi3"
TEMPLATES = HERE / "templates"
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
    rows = fmi.variables(b)
    units = sorted({r[4] for r in rows if r[4]})
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<fmiModelDescription fmiVersion="3.0" modelName={quoteattr(b.name)} instantiationToken="{token}"',
           f'  description={quoteattr(fmi.description(b))}',
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
    starts = fmi.input_starts(b)
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
    config, b, name, c_files, sources = fmi.current_sources(observer, out, "fmu3", f"an {FMI3_PLATFORM} binary")
    token = fmi.guid("fmi3" + "".join(f + sources[f] for f in c_files))
    sources[f"{name}_fmu3.c"] = render_template("fmu3.c.j2", TEMPLATES, name=name, NAME=name.upper(),
                                                ts=repr(config.sample_time), input_start=fmi.c_starts(b),
                                                guid=token, stubs=fmi3_stubs())
    for h in sorted(FMI3_HEADERS.glob("fmi3*.h")):
        sources[h.name] = h.read_text()
    c_sources = [f"{name}_kernel.c", f"{name}.c", f"{name}_fmu3.c"]
    sources["buildDescription.xml"] = build_description3(name, c_sources)
    fmi.compile_and_zip(out, name, sources, c_sources, model_description3(b, token), FMI3_PLATFORM)
    log(f"{name}: wrote {out} (FMI 3.0 co-simulation, {len(fmi.variables(b)) + 1} variables, step "
        f"{config.sample_time:g} s, binaries/{FMI3_PLATFORM}/{name}.so and sources/)")
    return Path(out)


class FMU3(Target):
    name = "fmu3"
    title = "FMI 3.0 co-simulation FMU (sources/ and binaries/x86_64-linux/NAME.so)"
    out = "FILE.fmu"
    suffix = ".fmu"
    fmi_version = "3.0"

    def export(self, config, out, log=print):
        return export_fmu3(config, out, log)


TARGET = FMU3()
