"""A new export target is one folder and one registry line (codegen/targets/README.md): a toy
target, written as a package in a folder of its own and registered from the test, appears in
``uiogen export --format`` and exports through ``uiogen export`` without any other file touched;
the C it writes compiles."""
from __future__ import annotations

import importlib
import subprocess
import sys
import textwrap

import pytest

from codegen import cli, targets
from codegen.emit.toolchain import STRICT_CFLAGS, compiler

NAME = "lpv_linf_driver_torque"

TOY = '''
"""A toy target: the step's C with a SHA256SUMS file."""
import hashlib

from codegen.targets.base import Target, generated_c, write_folder


class Checksummed(Target):
    name = "toy_sums"
    title = "the step's C with its SHA256SUMS"
    out = "DIR"

    def export(self, config, out, log=print):
        _, files = generated_c(config)
        c = {f: t for f, t in files.items() if f.endswith((".c", ".h")) and not f.endswith("_example.c")}
        sums = "".join(f"{hashlib.sha256(t.encode()).hexdigest()}  {f}\\n" for f, t in sorted(c.items()))
        out = write_folder(out, {**c, "SHA256SUMS": sums})
        log(f"{config.name}: wrote {out}")
        return out


TARGET = Checksummed()
'''


@pytest.fixture
def toy(tmp_path, monkeypatch):
    folder = tmp_path / "pkgs" / "toy_sums"                     # one folder ...
    folder.mkdir(parents=True)
    (folder / "__init__.py").write_text(textwrap.dedent(TOY))
    monkeypatch.syspath_prepend(str(tmp_path / "pkgs"))
    target = targets.register(importlib.import_module("toy_sums").TARGET)     # ... and one line
    yield target
    targets.unregister(target.name)
    sys.modules.pop("toy_sums", None)


@pytest.mark.slow          # compiles what it wrote
def test_a_toy_target_is_listed_and_exports_through_the_cli(toy, tmp_path, capsys):
    assert cli.main(["export", "--format"]) == 0
    listed = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()}
    assert set(listed) == set(targets.names()) and "toy_sums" in listed
    assert toy.title in listed["toy_sums"]
    out = tmp_path / "out"
    assert cli.main(["export", NAME, "--format", "toy_sums", "--out", str(out)]) == 0
    sums = (out / "SHA256SUMS").read_text().splitlines()
    assert {line.split()[1] for line in sums} == {f"{NAME}.c", f"{NAME}.h", f"{NAME}_kernel.c", f"{NAME}_kernel.h"}
    # what it wrote builds with the strict flags
    for c in (f"{NAME}.c", f"{NAME}_kernel.c"):
        subprocess.run([compiler(), *STRICT_CFLAGS, "-I", str(out), "-c", str(out / c), "-o",
                        str(tmp_path / (c + ".o"))], check=True, capture_output=True)


def test_an_unregistered_target_is_refused_by_the_cli(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["export", NAME, "--format", "toy_sums", "--out", "x"])
    assert exc.value.code == 2
    assert "invalid choice: 'toy_sums'" in capsys.readouterr().err


def test_a_registered_target_needs_the_protocol():
    with pytest.raises(TypeError):
        targets.register(object())
