"""docs/tutorial.md, executed as written in a temporary folder outside the repository: every block
starting with ``# file: NAME`` is written to NAME, every ``sh`` block runs there (``uiogen`` and
``python`` from this interpreter). Then the tutorial's claims are checked: the force estimate within
5 % of the force's RMS, and the same observer in kN as in N up to the unit."""
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"```(\w+)\n(.*?)```", re.S)


def _run_page(folder: Path) -> None:
    for lang, body in BLOCK.findall((ROOT / "docs" / "tutorial.md").read_text()):
        first = body.splitlines()[0] if body.strip() else ""
        if first.startswith("# file: "):
            (folder / first[len("# file: "):].strip()).write_text(body)
        elif lang == "sh":
            for line in body.strip().splitlines():
                cmd = shlex.split(line)
                cmd = ([sys.executable, "-m", "codegen.cli", *cmd[1:]] if cmd[0] == "uiogen"
                       else [sys.executable, *cmd[1:]] if cmd[0] == "python" else cmd)
                proc = subprocess.run(cmd, cwd=folder, capture_output=True, text=True,
                                      env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
                assert proc.returncode == 0, f"$ {line}\n{proc.stdout}\n{proc.stderr}"


@pytest.fixture(scope="module")
def tutorial(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tutorial")
    _run_page(folder)
    return folder


def test_the_tutorial_runs_from_an_empty_folder(tutorial):
    for name in ("disturbance", "saturating"):
        assert (tutorial / "generated_c" / name / f"{name}_design.json").is_file()
        assert (tutorial / "generated_c" / name / f"{name}.h").is_file()


def test_the_force_estimate_is_within_five_percent_and_unit_free(tutorial):
    from codegen import emit, extension, validate
    res = validate.run_scenario(str(tutorial / "disturbance.toml"), "excitation")
    truth = res["signals"]["truth"]["F"]
    keep = res["signals"]["t"] >= 2.0
    force_rms = float(np.sqrt(np.mean(truth[keep] ** 2)))
    assert res["observer"]["F"]["rms"] <= 0.05 * force_rms, (res["observer"]["F"]["rms"], force_rms)
    # the same model with the force in kN
    (tutorial / "lateral_kn.py").write_text((tutorial / "lateral.py").read_text()
                                            .replace("(F_yf + F_yr + F) / M", "(F_yf + F_yr + 1000.0 * F) / M"))
    (tutorial / "car_kn.toml").write_text((tutorial / "car.toml").read_text()
                                          .replace("F = { min = -1500.0, max = 1500.0", "F = { min = -1.5, max = 1.5"))
    (tutorial / "disturbance_kn.toml").write_text((tutorial / "disturbance.toml").read_text()
                                                  .replace('"lateral.py"', '"lateral_kn.py"')
                                                  .replace('"car.toml"', '"car_kn.toml"'))
    kn = str(tutorial / "disturbance_kn.toml")
    emit.generate([kn], log=lambda *_: None)
    extension.build_extension(kn)
    res_kn = validate.run_scenario(kn, "excitation")
    f_n = res["signals"]["estimate"]["F"][keep]
    f_kn = 1000.0 * res_kn["signals"]["estimate"]["F"][keep]
    assert np.abs(f_kn - f_n).max() <= 0.01 * np.abs(f_n).max()


def test_the_saturating_tyre_observer_tracks_its_model(tutorial):
    from codegen import validate
    res = validate.run_scenario(str(tutorial / "saturating.toml"), "excitation")
    obs = res["observer"]
    assert obs["v_y"]["rms"] < 0.01 and obs["T_eng"]["nmse_percent"] > 95 and obs["delta"]["nmse_percent"] > 95
