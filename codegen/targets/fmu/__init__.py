"""``uiogen export NAME --format fmu``: an FMI 2.0 co-simulation FMU of a generated observer.

The FMU holds ``modelDescription.xml`` (inputs, outputs and the status as FMI variables, with the
units and descriptions of the observer's C API, the sample time as the default communication
step), ``sources/`` (the generated C, the FMI wrapper rendered from ``templates/fmu.c.j2`` here
and the FMI 2.0 headers of ``fmi2/`` here) and ``binaries/linux64/NAME.so``, compiled from those
sources with the host compiler and the project's strict flags (:mod:`codegen.targets.fmi`, shared
with FMI 3.0). One ``fmi2DoStep`` of ``k`` sample times takes ``k`` samples with the inputs held.
"""
from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

from ... import __version__ as UIOGEN_VERSION
from ...emit.toolchain import render_template
from .. import fmi
from ..base import Target

HERE = Path(__file__).resolve().parent
FMI2_HEADERS = HERE / "fmi2"
TEMPLATES = HERE / "templates"
PLATFORM = "linux64"


def export_fmu(observer, out, log=print) -> Path:
    """Write the FMI 2.0 co-simulation FMU of ``observer`` (a built-in name, an observer file or a
    config) to ``out``."""
    config, b, name, c_files, sources = fmi.current_sources(observer, out, "fmu", f"a {PLATFORM} binary")
    guid = fmi.guid("".join(f + sources[f] for f in c_files))
    sources[f"{name}_fmu.c"] = render_template("fmu.c.j2", TEMPLATES, name=name, NAME=name.upper(),
                                               ts=repr(config.sample_time), input_start=fmi.c_starts(b),
                                               guid=guid, vr_status=len(fmi.variables(b)) - 1)
    for h in sorted(FMI2_HEADERS.glob("fmi2*.h")):
        sources[h.name] = h.read_text()
    c_sources = [f"{name}_kernel.c", f"{name}.c", f"{name}_fmu.c"]
    fmi.compile_and_zip(out, name, sources, c_sources, model_description(b, guid, c_sources), PLATFORM)
    log(f"{name}: wrote {out} (FMI 2.0 co-simulation, {len(fmi.variables(b))} variables, step {config.sample_time:g} s, "
        f"binaries/{PLATFORM}/{name}.so and sources/)")
    return Path(out)


def model_description(b, guid: str, source_files: list) -> str:
    rows = fmi.variables(b)
    units = sorted({r[4] for r in rows if r[4]})
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(b.name)} guid="{guid}"',
           f'  description={quoteattr(fmi.description(b))}',
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
    starts = fmi.input_starts(b)
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


class FMU2(Target):
    name = "fmu"
    title = "FMI 2.0 co-simulation FMU (sources/ and binaries/linux64/NAME.so)"
    out = "FILE.fmu"
    suffix = ".fmu"
    fmi_version = "2.0"

    def export(self, config, out, log=print):
        return export_fmu(config, out, log)


TARGET = FMU2()
