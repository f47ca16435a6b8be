"""The FMU's modelDescription.xml text, without compiling one (tests/targets/test_fmu.py builds and
simulates the FMUs): its description and the inputs' start values."""
from __future__ import annotations

import types
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from codegen.emit.toolchain import render_template
from codegen.project import observer_file as observers
from codegen.targets import fmi, fmu, fmu3

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
HEADER = """# roll_bank: linf_uio, chosen by uiogen analyze roll.py
# (the best-ranked family that applies to these sensors: r, ay, p;
# unknown inputs phir).
# next: uiogen design obs.toml --update && uiogen generate obs.toml && uiogen build obs.toml
# note: something the user should know

family = "linf_uio"
model = "roll.py"
parameters = "roll_params.toml"
sample_time = 0.01
polytope = "sector"
"""


def _build(tmp_path, header=HEADER):
    case = ROOT / "tests" / "analysis" / "models" / "roll_bank"
    for f in ("roll.py", "roll_params.toml"):
        (tmp_path / f).write_text((case / f).read_text())
    (tmp_path / "obs.toml").write_text(header)
    config = observers.get(str(tmp_path / "obs.toml"))
    return types.SimpleNamespace(name="obs", config=config, input_names=["dw", "y_r", "y_ay", "y_p", "vx"])


def _rows(b):
    rows = [(n, k, "input", "Real", "", n) for k, n in enumerate(b.input_names)]
    return rows + [("phir", len(rows), "output", "Real", "rad", "phir"),
                   ("status", len(rows) + 1, "output", "Integer", "", "status")]


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_fmu_description_is_the_header_without_commands_and_a_scheduling_input_starts_in_its_box(
        tmp_path, monkeypatch, version):
    """The description held the whole header comment, 'next: uiogen design ... &&' included, and the
    scheduling input vx (box [8, 35]) started at 0.0, outside its box: now the header's first
    paragraph without its commands, and vx starts at its box's midpoint (other inputs at 0.0)."""
    b = _build(tmp_path)
    monkeypatch.setattr(fmi, "variables", _rows)
    xml = fmu.model_description(b, "{0}", []) if version == "2.0" else fmu3.model_description3(b, "{0}")
    md = ET.fromstring(xml)
    assert md.get("description") == ("roll_bank: linf_uio, chosen by uiogen analyze roll.py (the best-ranked family "
                                      "that applies to these sensors: r, ay, p; unknown inputs phir).")
    if version == "2.0":
        starts = {v.get("name"): v.find("Real").get("start") for v in md.iter("ScalarVariable")
                  if v.get("causality") == "input"}
    else:
        starts = {v.get("name"): v.get("start") for v in md.find("ModelVariables") if v.get("causality") == "input"}
    assert starts == {"dw": "0.0", "y_r": "0.0", "y_ay": "0.0", "y_p": "0.0", "vx": "21.5"}
    # the C wrapper starts its inputs at the same values
    template, folder = ("fmu.c.j2", fmu.TEMPLATES) if version == "2.0" else ("fmu3.c.j2", fmu3.TEMPLATES)
    c = render_template(template, folder, name="obs", NAME="OBS", ts="0.01", guid="{0}", vr_status=6, stubs="",
                        input_start=fmi.c_starts(b))
    assert "static const double INPUT_START[N_IN] = { 0.0, 0.0, 0.0, 0.0, 21.5 };" in c
    assert "m->input[i] = INPUT_START[i];" in c


def test_a_starter_header_gives_its_first_sentence_and_no_header_the_family(tmp_path):
    head = ("# Observer obs: a starter for your own L-infinity UIO (Nguyen et al. 2019), copied from the\n"
            "# built-in observer lpv_linf_driver_torque. Edit model.py (your equations, sympy) and parameters.toml\n"
            "# (your car; [inputs.NAME] ranges for the excitation scenario), then:\n"
            "#   uiogen design obs.toml --update\n#   uiogen build obs.toml\n#\n# The example's own text.\n")
    b = _build(tmp_path, head + HEADER.split("\n\n", 1)[1])
    assert fmi.description(b) == ("Observer obs: a starter for your own L-infinity UIO (Nguyen et al. 2019), copied "
                                  "from the built-in observer lpv_linf_driver_torque.")
    b = _build(tmp_path, HEADER.split("\n\n", 1)[1])
    assert fmi.description(b).startswith("observer obs: ") and "2019" in fmi.description(b)


def test_an_fmu_under_a_file_is_an_output_error_naming_it(tmp_path, capsys):
    """`uiogen export NAME --out afile/x.fmu` with afile a file: one typed line (was a FileExistsError
    traceback from mkdir, after the FMU's sources were compiled)."""
    from codegen import cli
    (tmp_path / "afile").write_text("")
    out = tmp_path / "afile" / "x.fmu"
    assert cli.main(["export", "algebraic_uio_example1", "--format", "fmu", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("uiogen: error: OutputError: ") and f"{tmp_path / 'afile'} is a file, not a folder" in err
