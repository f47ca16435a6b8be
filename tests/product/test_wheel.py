"""The product as a user gets it: the wheel, installed in a fresh venv with no checkout in sight,
runs the tutorial from an empty folder (new -> design --update -> generate -> build -> validate).

The wheel is built from a copy of the source tree (no .git, venv, build or generated files),
installed with its pinned dependencies (constraints.txt, through pip's configured index) into a
venv made from the base interpreter; every command runs from an empty folder with a clean
environment, so neither the checkout nor its venv is importable.
"""
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from codegen.design import lock as design_lock
from conftest import HANG_GUARD

pytestmark = pytest.mark.slow          # builds the wheel and installs it into a fresh venv

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
SOURCE_IGNORE = shutil.ignore_patterns(".git", ".venv*", "build", "generated_c", "__pycache__", "*.egg-info",
                                       ".pytest_cache", "site", "*.so", "*.o")


def _run(cmd, cwd, env, timeout=HANG_GUARD):
    proc = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"$ {' '.join(map(str, cmd))}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv folder, wheel path, clean environment) of the wheel installed in a fresh venv."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    shutil.copytree(ROOT, src, ignore=SOURCE_IGNORE)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep)
                                  if not p.startswith(str(ROOT)))
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--quiet", "-w", tmp / "dist",
          src], tmp, env)
    wheel, = (tmp / "dist").glob("uiogen-*.whl")
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", venv], tmp, env)
    _run([venv / "bin" / "python", "-m", "pip", "install", "--quiet", "-c", ROOT / "constraints.txt", wheel], tmp, env)
    return venv, wheel, env


def test_the_wheel_holds_every_package_and_data_file(installed):
    _, wheel, _ = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    sources = {str(p.relative_to(ROOT)) for pkg in ("codegen", "model_defs", "python_bindings")
               for p in (ROOT / pkg).rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    missing = sorted(sources - names)
    assert not missing, f"files of the packages missing from the wheel: {missing}"
    assert not [n for n in names if n.startswith(("generated_c/", "build/", "tests/"))]


def test_the_tutorial_runs_from_an_empty_folder_with_the_installed_wheel(installed, tmp_path):
    venv, _, env = installed
    uiogen = venv / "bin" / "uiogen"
    work = tmp_path / "empty"
    work.mkdir()
    where = _run([venv / "bin" / "python", "-c", "import codegen, python_bindings, sys; "
                  "print(codegen.__file__); print(python_bindings.__file__); print(sys.path)"], work, env)
    site = str(venv)
    assert all(line.startswith(site) for line in where.splitlines()[:2]), where
    assert str(ROOT) not in where, where
    name = "my_observer"
    out = _run([uiogen, "new", "proj", "--family", "linf_uio", "--name", name], work, env)
    toml = Path("proj") / f"{name}.toml"            # relative, as a user types it
    assert "next:" in out and (work / toml).is_file()
    _run([uiogen, "design", toml, "--update"], work, env)
    lock = work / "proj" / "generated_c" / name / f"{name}_design.json"
    data = json.loads(lock.read_text())
    assert data["lock"]["format"] == design_lock.FORMAT and design_lock.verify(data, str(lock))
    out = _run([uiogen, "generate", toml], work, env)
    assert "committed design" in out and (lock.parent / f"{name}.h").is_file()
    _run([uiogen, "build", toml], work, env)
    assert list((work / "proj" / "build" / "extensions").glob(f"_{name}.*"))
    result = json.loads(_run([uiogen, "validate", toml, "--scenario", "excitation", "--json"], work, env))
    assert result["samples"] == 3001 and result["status_flags"] == 0, result
    # like for like: the same project through the checkout gives the same lock, byte for byte (the
    # hash labels package files by their path inside the package), and the same validation figures
    twin = tmp_path / "twin"
    shutil.copytree(work / "proj", twin, ignore=shutil.ignore_patterns("generated_c", "build", "__pycache__"))
    here = [sys.executable, "-m", "codegen.cli"]
    for cmd in (["design", "--update"], ["generate"], ["build"]):
        _run([*here, cmd[0], twin / toml.name, *cmd[1:]], ROOT, os.environ.copy())
    assert (twin / "generated_c" / name / lock.name).read_text() == lock.read_text()
    ours = _run([*here, "validate", twin / toml.name, "--scenario", "excitation", "--json"], ROOT, os.environ.copy())
    assert json.loads(ours) == result
    assert not list(venv.rglob("generated_c")), "generated files inside the installed package"
    assert not [p for p in (work / "proj").iterdir() if p.name not in
                ("generated_c", "build", "model.py", "parameters.toml", toml.name, "__pycache__")]
    assert not (work / "generated_c").exists() and not (work / "build").exists()
