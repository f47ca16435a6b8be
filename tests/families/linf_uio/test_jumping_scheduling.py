"""A scheduling signal that jumps (a gear ratio): ``[scheduling.NAME]`` without rate_min and rate_max (issue 42,
also weak). A design that bounds the membership rates by them is refused by one line naming the file, the signal
and both fixes; the quadratic design over any rate (rate_bounds = "none", lyapunov = "quadratic") designs,
generates, builds and validates on an excitation that sweeps the signal as a staircase; one rate bound alone is
refused."""
import json
import re

import numpy as np
import pytest

from codegen import cli
from codegen.model import load_parameters
from codegen.project import observer_file as observers
from codegen.validation import excitation

from conftest import new_starter


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_a_signal_without_rate_bounds_designs_at_any_rate_and_is_swept_as_steps(tmp_path, capsys):
    folder = new_starter(tmp_path / "p")
    obs, params = folder / "obs1.toml", folder / "parameters.toml"
    text = params.read_text()
    assert re.search(r"(?m)^rate_min = ", text) and re.search(r"(?m)^rate_max = ", text)
    params.write_text(re.sub(r"(?m)^rate_max = .*\n", "", text))
    assert cli.main(["design", str(obs), "--update"]) == 2
    err = _one_line(capsys)
    assert "SchedulingBoundsError" in err and str(params) in err and "gives rate_min without rate_max" in err
    params.write_text(re.sub(r"(?m)^rate_(min|max) = .*\n", "", text))
    box = load_parameters(params).scheduling["v_x"]
    assert box.rate_lower is None and box.rate_upper is None and not box.rate_bounded
    assert cli.main(["design", str(obs), "--update"]) == 2
    err = _one_line(capsys)
    assert str(params) in err and "[scheduling.v_x] gives no rate_min, rate_max" in err
    assert 'rate_bounds = "none" and lyapunov = "quadratic"' in err
    # the fix, applied: the quadratic design holds at any rate
    said = obs.read_text()
    said = re.sub(r'(?m)^rate_bounds = "[a-z_]+"', 'rate_bounds = "none"', said)
    said = re.sub(r'(?m)^lyapunov = "[a-z]+"', 'lyapunov = "quadratic"', said)
    obs.write_text(said)
    for verb in (["design", str(obs), "--update"], ["generate", str(obs)], ["build", str(obs)]):
        assert cli.main(verb) == 0, capsys.readouterr().err
    capsys.readouterr()
    assert cli.main(["validate", str(obs), "--scenario", "excitation", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["status_flags"] == 0 and r["observer"]["beta"]["rms_percent"] < 5.0     # measured 2.7 %
    # the excitation holds each level of a staircase across 90 % of the box
    t, signals = excitation.signal_functions(observers.get(str(obs)))
    v = signals["v_x"](t)
    levels = np.unique(v)
    assert 4 <= len(levels) <= 5 and levels.min() >= box.lower and levels.max() <= box.upper
    jumps = np.flatnonzero(np.diff(v))
    assert len(jumps) >= 3 and np.all(np.diff(jumps) >= round(excitation.STEP_S / observers.get(str(obs)).sample_time) - 1)
