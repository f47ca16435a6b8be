"""make misra: cppcheck's MISRA C:2012 addon on the generated C: no finding in the code our
templates write, and the CasADi kernel's findings exactly those of misra/kernel_deviations.toml."""
from __future__ import annotations

import shutil

import pytest

from codegen.targets import misra
from python_bindings.workspace import Workspace, source_checkout

GENERATED_DIR = Workspace.of(source_checkout()).generated

pytestmark = [pytest.mark.slow,          # cppcheck over the generated C
              pytest.mark.skipif(shutil.which("cppcheck") is None,
                                 reason="cppcheck is not installed (make embedded-tools / "
                                        "scripts/install_embedded_tools.sh: apt-get install cppcheck)")]
NAME = "lpv_linf_driver_torque"


@pytest.fixture(scope="module")
def found():
    """cppcheck over every generated observer, once for the module (about a minute)."""
    return misra.findings(log=lambda *_: None)


def test_misra_zero_template_findings_and_kernel_findings_as_listed(found):
    r = misra.judge(found)
    assert len(r["observers"]) == len(list(GENERATED_DIR.glob("*/INPUTS.sha256")))
    assert r["template_findings"] == 0
    assert r["kernel_findings"] == r["deviations"]
    assert r["problems"] == []


def test_a_new_finding_in_template_code_is_reported(tmp_path):
    src = tmp_path / NAME
    shutil.copytree(GENERATED_DIR / NAME, src)
    c = src / f"{NAME}.c"
    c.write_text(c.read_text() + "\nint uiogen_extra(int x);\nint uiogen_extra(int x) { goto end; end: return x; }\n")
    found = misra.classify(NAME, misra.analyse(NAME, src))
    assert any(rule == "15.1" for _, _, rule in found["template"])


def test_a_kernel_count_above_the_deviations_file_fails(found, tmp_path):
    listed = misra.deviations()["8.4"][0]
    text = misra.DEVIATIONS.read_text().replace(f"count = {listed}", f"count = {listed - 1}")
    assert text != misra.DEVIATIONS.read_text()
    path = tmp_path / "dev.toml"
    path.write_text(text)
    r = misra.judge(found, deviations_path=path)
    assert any("rule 8.4" in p and "new finding" in p for p in r["problems"])
