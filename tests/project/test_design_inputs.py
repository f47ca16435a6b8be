"""What a design depends on is in its stamp, or refused (issue: nothing stale, round two).

A helper module beside a user's model is a design input (the lock's hash and the extension's source
record see it); a model that reads a file no stamp covers is refused at its import, naming the file;
a user's observer file names its own parameter file and never falls back to a built-in of that name.
"""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from codegen.design import lock
from codegen.design.sources import helper_modules
from codegen.errors import ConfigurationError, ModelDefinitionError
from codegen.extension.build import source_record
from codegen.project import observer_file as observers
from python_bindings import integrity
from conftest import new_starter

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def project(tmp_path) -> Path:
    """A starter project (``uiogen new``): obs1.toml, model.py, parameters.toml."""
    return new_starter(tmp_path / "p")


def _fresh(path) -> observers.ObserverConfig:
    """The observer file read again, its model imported again (as a new process would)."""
    for name in [m for m in sys.modules if m.startswith("uiogen_user_model") or m in ("tyre_data", "tyre_pkg",
                                                                                       "tyre_pkg.data")]:
        del sys.modules[name]
    return observers.get(str(path))


def _with_helper(project: Path, scale: str) -> None:
    (project / "tyre_data.py").write_text(f"C_SCALE = {scale}\n")
    model = project / "model.py"
    text = model.read_text()
    if "tyre_data" not in text:
        text = text.replace("import sympy as sp\n", "import sympy as sp\nfrom tyre_data import C_SCALE\n", 1)
        text = text.replace("F_yf = 2 * C_f * alpha_f", "F_yf = 2 * C_f * C_SCALE * alpha_f")
    model.write_text(text)


def test_a_helper_module_beside_the_model_is_a_design_input(project):
    _with_helper(project, "1.0")
    config = _fresh(project / "obs1.toml")
    assert config.load_definition() is not None          # imports from any current directory
    assert helper_modules(config.model_path) == [(project / "tyre_data.py").resolve()]
    before, record = lock.design_inputs(config), source_record(config)
    assert record[integrity.HELPERS] == [["tyre_data.py", integrity.file_sha256(project / "tyre_data.py")]]
    _with_helper(project, "1.05")
    config = _fresh(project / "obs1.toml")
    assert lock.design_inputs(config) != before            # generate re-solves, load refuses the old extension
    changed = integrity.changed_sources(json.loads(json.dumps(record)), project / "obs1.toml")
    assert changed == [("model helper", project / "tyre_data.py")]


def test_a_helper_package_beside_the_model_is_followed(project):
    pkg = project / "tyre_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "data.py").write_text("C_SCALE = 1.0\n")
    model = project / "model.py"
    model.write_text(model.read_text().replace("import sympy as sp\n",
                                               "import sympy as sp\nfrom tyre_pkg.data import C_SCALE\n", 1))
    config = _fresh(project / "obs1.toml")
    config.load_definition()
    assert set(helper_modules(config.model_path)) == {(pkg / "__init__.py").resolve(), (pkg / "data.py").resolve()}


@pytest.mark.parametrize("reader", [
    "import json, pathlib\nC_SCALE = json.loads((pathlib.Path(__file__).parent / 'tyre.json').read_text())['s']\n",
    "import numpy as np, pathlib\nC_SCALE = float(np.loadtxt(pathlib.Path(__file__).parent / 'tyre.csv'))\n",
    "import sqlite3, pathlib\nC_SCALE = sqlite3.connect(pathlib.Path(__file__).parent / 'tyre.db')"
    ".execute('select 1.0').fetchone()[0]\n",
])
def test_a_model_that_reads_a_data_file_is_refused_naming_it(project, reader):
    (project / "tyre.json").write_text('{"s": 1.0}')
    (project / "tyre.csv").write_text("1.0\n")
    model = project / "model.py"
    model.write_text(reader + model.read_text())
    config = _fresh(project / "obs1.toml")
    with pytest.raises(ModelDefinitionError) as exc:
        config.load_definition()
    msg = str(exc.value)
    assert str(model.resolve()) in msg and "reads the file" in msg and "tyre." in msg and "parameter file" in msg


def test_a_model_that_starts_a_process_is_refused_naming_the_command(project):
    """What a child process reads no audit hook of this process sees (``cat tyre.txt``)."""
    (project / "tyre.txt").write_text("1.0\n")
    model = project / "model.py"
    model.write_text("import pathlib, subprocess\nC_SCALE = float(subprocess.run(['cat', str(pathlib.Path(__file__)"
                     ".parent / 'tyre.txt')], capture_output=True, check=True).stdout)\n" + model.read_text())
    config = _fresh(project / "obs1.toml")
    with pytest.raises(ModelDefinitionError, match=r"the model starts a process \(cat .*tyre.txt\) while it is imported"):
        config.load_definition()


def test_a_model_importing_a_module_from_another_folder_is_refused(project, tmp_path):
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "far_data.py").write_text("C_SCALE = 1.0\n")
    model = project / "model.py"
    model.write_text(f"import sys\nsys.path.insert(0, {str(other)!r})\nfrom far_data import C_SCALE\n"
                     + model.read_text())
    config = _fresh(project / "obs1.toml")
    try:
        with pytest.raises(ModelDefinitionError, match="imports the module .*far_data.py"):
            config.load_definition()
    finally:
        sys.path[:] = [p for p in sys.path if p != str(other)]
        sys.modules.pop("far_data", None)


def test_the_cli_refuses_a_model_reading_a_file_in_one_line(project):
    (project / "tyre.json").write_text('{"s": 1.0}')
    model = project / "model.py"
    model.write_text("import json, pathlib\nS = json.loads((pathlib.Path(__file__).parent / 'tyre.json')"
                     ".read_text())\n" + model.read_text())
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "design", str(project / "obs1.toml")],
                          capture_output=True, text=True, cwd=ROOT)
    err = proc.stderr.strip()
    assert proc.returncode == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert "tyre.json" in err and "ModelDefinitionError" in err


def test_a_missing_parameter_file_is_not_replaced_by_a_builtin(project):
    """The project's own commonroad_bmw320i.toml deleted: an error naming it, never the built-in file."""
    builtin = observers.PARAMS_DIR / "commonroad_bmw320i.toml"
    assert builtin.is_file()
    obs = project / "obs1.toml"
    obs.write_text(obs.read_text().replace('parameters = "parameters.toml"', 'parameters = "commonroad_bmw320i.toml"'))
    (project / "commonroad_bmw320i.toml").write_text((project / "parameters.toml").read_text())
    assert observers.get(str(obs)).parameter_path == (project / "commonroad_bmw320i.toml").resolve()
    (project / "commonroad_bmw320i.toml").unlink()
    with pytest.raises(ConfigurationError) as exc:
        observers.get(str(obs))
    msg = str(exc.value)
    assert str((project / "commonroad_bmw320i.toml").resolve()) in msg and f"cp {builtin}" in msg
    assert exc.value.key == "parameters"


def test_a_byte_order_mark_is_read_past_alike_by_design_and_load(project):
    """Windows editors write a UTF-8 BOM: the observer and parameter files read as without it, and the
    hashes that decide staleness (design lock, extension record) are those of the file without it."""
    config = _fresh(project / "obs1.toml")
    before = (lock.design_inputs(config), integrity.observer_file_sha256(project / "obs1.toml"),
              integrity.parameters_sha256(project / "parameters.toml"))
    for f in ("obs1.toml", "parameters.toml"):
        (project / f).write_bytes(b"\xef\xbb\xbf" + (project / f).read_bytes())
    config = _fresh(project / "obs1.toml")
    assert config.doc and not config.doc.startswith("\ufeff")
    after = (lock.design_inputs(config), integrity.observer_file_sha256(project / "obs1.toml"),
             integrity.parameters_sha256(project / "parameters.toml"))
    assert after == before


def test_a_folder_where_a_file_is_named_is_said_so(project):
    obs = project / "obs1.toml"
    (project / "params_dir").mkdir()
    obs.write_text(obs.read_text().replace('parameters = "parameters.toml"', 'parameters = "params_dir"'))
    with pytest.raises(ConfigurationError, match="params_dir is a folder; name a parameter .toml file"):
        observers.get(str(obs))
    (project / "as_dir.toml").mkdir()
    with pytest.raises(Exception, match="is a folder, not an observer file"):
        observers.get(str(project / "as_dir.toml"))


def test_a_symbol_named_like_an_outputs_measurement_is_refused(project):
    """A known input y_r beside the output r: both would be the step's input y_r."""
    model = project / "model.py"
    text = model.read_text()
    model.write_text(text.replace('T_a, T_d = sp.symbols("T_a T_d")', 'T_a, T_d = sp.symbols("y_r T_d")'))
    config = _fresh(project / "obs1.toml")
    with pytest.raises(ModelDefinitionError, match=r"y_r is the name of the measurement of output r"):
        config.load_definition()
