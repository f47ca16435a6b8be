"""Parameter values that make the model singular are one typed line naming the file and the values,
never a numeric traceback deep in a design (issue: nothing stale, round two, item 7)."""
import subprocess
import sys
from pathlib import Path

import pytest

from codegen.errors import ConfigurationError
from codegen.model import load_parameters
from codegen.model.definition import parameter_substitution
from codegen.project import observer_file as observers
from conftest import new_starter

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def project(tmp_path) -> Path:
    """A starter (linf_uio) whose parameters carry no sympy sign assumption (a user's model)."""
    model = new_starter(tmp_path / "p") / "model.py"
    text = model.read_text()
    assert '"l_f l_r eta_t R_s B_s K_p M I_z I_s C_f C_r", positive=True)' in text
    model.write_text(text.replace('"l_f l_r eta_t R_s B_s K_p M I_z I_s C_f C_r", positive=True)',
                                  '"l_f l_r eta_t R_s B_s K_p M I_z I_s C_f C_r")'))
    return tmp_path / "p"


def _set(project: Path, **values) -> None:
    path = project / "parameters.toml"
    lines = path.read_text().splitlines()
    for k, v in values.items():
        i = next(i for i, line in enumerate(lines) if line.split("=")[0].strip() == k)
        lines[i] = f"{k} = {v}"
    path.write_text("\n".join(lines) + "\n")


def _substitute(project: Path):
    for m in [m for m in sys.modules if m.startswith("uiogen_user_model")]:
        del sys.modules[m]
    config = observers.get(str(project / "obs1.toml"))
    return parameter_substitution(config.load_model(), load_parameters(config.parameter_path))


def test_the_starter_without_assumptions_is_accepted(project):
    assert _substitute(project)


@pytest.mark.parametrize("values, names", [({"I_z": 0.0}, "I_z"), ({"M": 0.0}, "M"), ({"R_s": 0.0}, "R_s")])
def test_a_division_by_zero_names_the_parameter(project, values, names):
    _set(project, **values)
    with pytest.raises(ConfigurationError) as exc:
        _substitute(project)
    msg = str(exc.value)
    assert names in msg and "which is" in msg and "parameters.toml" in msg


def test_a_root_of_a_negative_number_names_the_parameters(project):
    model = project / "model.py"
    model.write_text(model.read_text().replace("F_yf = 2 * C_f * alpha_f",
                                               "F_yf = 2 * C_f * sp.sqrt(l_f - l_r) * alpha_f"))
    _set(project, l_f=1.0, l_r=1.5)
    with pytest.raises(ConfigurationError, match=r"l_f, l_r = \[1\.0, 1\.5\].*sqrt.*complex") as exc:
        _substitute(project)
    assert exc.value.key == "l_f, l_r"


@pytest.mark.parametrize("name, value", [("M", -1500.0), ("I_z", -2000.0)])
def test_a_negative_mass_or_inertia_is_refused_unless_accepted(project, name, value):
    _set(project, **{name: value})
    with pytest.raises(ConfigurationError, match=f"{name} = {value}: a (mass|moment of inertia) is > 0"):
        _substitute(project)
    path = project / "parameters.toml"
    path.write_text(path.read_text() + f'\n[plausibility]\naccept = ["{name}"]\n')
    _substitute(project)


def test_the_command_line_says_it_in_one_line(project):
    _set(project, M=0.0)
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "design", str(project / "obs1.toml")],
                          capture_output=True, text=True, cwd=ROOT)
    err = proc.stderr.strip()
    assert proc.returncode == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert "ConfigurationError" in err and "M = 0.0" in err
