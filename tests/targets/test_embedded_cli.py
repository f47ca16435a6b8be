"""The command lines of the embedded tools (``python -m codegen.targets.cortexm``, ``codegen.tools.m4cycles``,
``codegen.tools.qemu`` [NAME ...], docs/embedding.md): ``--help``, NAME resolved as the ``uiogen`` verbs
resolve it (a built-in name or an observer file of the user's project), every mistake one typed line
on stderr with exit status 2. They read ``--help`` as an observer name, looked for
``obs.toml_kernel.c`` given an observer file, and ended in tracebacks. The runs that need the
cross compiler and QEMU are slow and skip without them (under CI they fail, as in test_cortexm.py)."""
from __future__ import annotations

import re

import pytest

from codegen import families
from codegen.project import starter
from codegen.targets import cortexm
from codegen.tools import m4cycles, qemu
from conftest import require_embedded_tool as require

TOOLS = {"cortexm": cortexm, "m4cycles": m4cycles, "qemu": qemu}


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err.strip()


@pytest.mark.parametrize("tool", TOOLS)
def test_help_says_what_it_does_and_what_NAME_may_be(tool, capsys):
    with pytest.raises(SystemExit) as exit_:
        TOOLS[tool].main(["--help"])
    assert exit_.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert out.startswith(f"usage: python -m {TOOLS[tool].__name__} [-h] [--project DIR] [NAME ...]")
    assert "a built-in observer (uiogen list) or the path of an observer file (.toml)" in out
    assert "make embedded-tools" in out and "Cortex-M4F" in out


@pytest.mark.parametrize("tool", TOOLS)
def test_a_misspelt_name_is_one_typed_line_with_did_you_mean(tool, capsys):
    assert TOOLS[tool].main(["lpv_linf_driver_torqe"]) == 2
    line = one_error_line(capsys)
    assert line.startswith("uiogen: error: UnknownObserverError: no observer named 'lpv_linf_driver_torqe' "
                           "(did you mean 'lpv_linf_driver_torque'?); known: ")


@pytest.mark.parametrize("tool", TOOLS)
def test_an_unknown_option_is_argparse_usage_with_status_2(tool, capsys):
    with pytest.raises(SystemExit) as exit_:
        TOOLS[tool].main(["--bogus"])
    assert exit_.value.code == 2
    assert "unrecognized arguments: --bogus" in capsys.readouterr().err


@pytest.fixture
def starter_project(tmp_path, monkeypatch):
    """A user's project as `uiogen new DIR --family linf_uio` writes it (not generated), the working
    directory."""
    path = starter.write(tmp_path, families.get("linf_uio"), "obs")
    monkeypatch.chdir(tmp_path)
    return path


@pytest.mark.parametrize("tool", TOOLS)
def test_the_bare_name_of_an_observer_file_here_suggests_the_file(tool, starter_project, capsys):
    assert TOOLS[tool].main(["obs"]) == 2
    assert re.match(r"uiogen: error: UnknownObserverError: no observer named 'obs' \(did you mean 'obs.toml'\?\)",
                    one_error_line(capsys))


@pytest.mark.parametrize("tool", TOOLS)
def test_an_observer_file_not_generated_says_how_to_generate_it(tool, starter_project, capsys):
    require(TOOLS[tool].available(), "the embedded tools")
    assert TOOLS[tool].main(["obs.toml"]) == 2
    line = one_error_line(capsys)
    assert line.startswith("uiogen: error: UnknownObserverError: observer 'obs' has not been generated")
    assert "run `uiogen generate obs.toml`" in line


@pytest.mark.parametrize("tool", TOOLS)
def test_a_missing_cross_tool_is_one_line_saying_how_to_install_it(tool, starter_project, tmp_path, monkeypatch,
                                                                    capsys):
    """The observer file resolves (its config read), then the tools are looked for: none on PATH."""
    monkeypatch.setenv("PATH", str(tmp_path / "no-tools"))
    assert TOOLS[tool].main([str(starter_project)]) == 2
    line = one_error_line(capsys)
    assert line.startswith("uiogen: error: UnsupportedError: arm-none-eabi-gcc")
    assert "not installed: sudo apt-get install gcc-arm-none-eabi" in line and "make embedded-tools" in line


# --- a user's observer, generated and built, through the three tools (slow) ---------------------------

@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """A project made by ``uiogen new`` (linf_uio), generated and built once for the module."""
    from codegen import workflow
    from codegen.extension.build import build_extension
    require(qemu.available() and m4cycles.available(), qemu.missing() or m4cycles.OBJDUMP)
    root = tmp_path_factory.mktemp("embedded")
    path = starter.write(root, families.get("linf_uio"), "obs")
    workflow.generate([str(path)], log=lambda *_: None)
    build_extension(str(path))
    return path


def rows(out: str) -> dict:
    lines = out.strip().splitlines()
    return {tuple(line.split()[:2]): line.split()[2:] for line in lines[1:]}


@pytest.mark.slow          # generates, builds, cross-compiles and runs QEMU
def test_cortexm_sizes_a_users_observer_from_its_generated_c(project, capsys):
    assert cortexm.main([str(project)]) == 0
    table = rows(capsys.readouterr().out)
    assert set(table) == {("obs", "double"), ("obs", "float32")}
    for code, rodata, stack in table.values():
        assert 0 < int(code) <= 16384 and 0 < int(stack) <= 2048
    assert int(table["obs", "float32"][0]) < int(table["obs", "double"][0])


@pytest.mark.slow
def test_qemu_runs_a_users_observer_bit_identical_to_its_host_build(project, capsys):
    assert qemu.main([str(project)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[:2] for line in lines] == [["obs", "double"], ["obs", "float32"]]
    assert all(line.endswith("samples: bit-identical") for line in lines), lines


@pytest.mark.slow
def test_m4cycles_counts_a_users_observer(project, capsys):
    assert m4cycles.main([str(project), "--project", str(project.parent)]) == 0
    table = rows(capsys.readouterr().out)
    assert set(table) == {("obs", "float32"), ("obs", "double")}
    instr, lo, hi, flops, _ = map(float, table["obs", "float32"])
    assert flops > 0 and flops <= instr <= lo < hi < 10 * flops
    assert float(table["obs", "double"][1]) > 10 * lo           # soft-float double on the M4F
