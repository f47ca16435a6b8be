"""``uiogen check-gains`` against hostile gains files: every mistake is one typed error (exit 2) naming
the file and the key, every unusable set of numbers a "not certified" verdict (exit 1), never a
traceback, a silently unused key or a silently converted entry."""
import json
from pathlib import Path

import numpy as np
import pytest

from codegen import cli

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())


def lock(name):
    return json.loads((ROOT / "generated_c" / name / f"{name}_design.json").read_text())


def check(tmp_path, capsys, name, content):
    path = tmp_path / "gains.json"
    if isinstance(content, (dict, list)):
        path.write_text(json.dumps(content))
    else:
        path = content
    rc = cli.main(["check-gains", name, "--gains", str(path)])
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    return rc, out.err.strip()


def test_a_folder_is_refused_typed(tmp_path, capsys):
    rc, err = check(tmp_path, capsys, "algebraic_uio_example2", tmp_path)
    assert rc == 2 and "ConfigurationError" in err and str(tmp_path) in err and len(err.splitlines()) == 1


def _records(name, edit):
    sols = lock(name)["lock"]["lmi_solutions"]
    edit(sols[0])
    return {"lmi_solutions": sols}


@pytest.mark.parametrize("edit, words", [
    (lambda r: r["variables"]["K1"][0].__setitem__(0, True), ["lmi_solutions[0].variables.K1", "True"]),
    (lambda r: r["variables"]["K1"][0].__setitem__(0, "1.5"), ["lmi_solutions[0].variables.K1", "'1.5'"]),
    (lambda r: r.__setitem__("variabels", {}), ["'variabels'", "did you mean 'variables'"]),
    (lambda r: r.pop("problem"), ["lmi_solutions[0] lacks problem"]),
    (lambda r: r.__setitem__("objective", "x"), ["lmi_solutions[0].objective"]),
])
def test_lock_form_entries_are_refused_by_key(tmp_path, capsys, edit, words):
    rc, err = check(tmp_path, capsys, "algebraic_uio_example2", _records("algebraic_uio_example2", edit))
    assert rc == 2 and err.startswith("uiogen: error: ConfigurationError: gains file"), err
    assert all(w in err for w in words), err


def test_lock_form_unread_keys_are_refused(tmp_path, capsys):
    sols = lock("algebraic_uio_example2")["lock"]["lmi_solutions"]
    rc, err = check(tmp_path, capsys, "algebraic_uio_example2", {"lmi_solutions": sols, "gamma": 0.5})
    assert rc == 2 and "key 'gamma' is not read" in err
    rc, err = check(tmp_path, capsys, "algebraic_uio_example2", {"lmi_solution": sols})
    assert rc == 2 and "did you mean 'lmi_solutions'" in err


def test_lock_form_zero_solution_is_not_certified(tmp_path, capsys):
    # X = 0 makes a block of the algebraic UIO's LMIs exactly singular: the numpy re-check refuses it
    # (a strict LMI), before L = X^-1 K would divide by zero
    def zero(r):
        for k, v in r["variables"].items():
            r["variables"][k] = (0 * np.array(v, float)).tolist()
    path = tmp_path / "gains.json"
    path.write_text(json.dumps(_records("algebraic_uio_example2", zero)))
    rc = cli.main(["check-gains", "algebraic_uio_example2", "--gains", str(path)])
    out = capsys.readouterr()
    assert rc == 1 and "Traceback" not in out.out + out.err
    assert "fails the numpy re-check" in out.out and "smallest eigenvalue 0.000e+00" in out.out, out.out


def _linf(edit):
    d = lock("lpv_linf_driver_torque")
    gains = {k: d[k] for k in d if k[0] in "PLX" and k[1:].isdigit() or k == "X"}
    edit(gains)
    return gains


@pytest.mark.parametrize("edit, words", [
    (lambda g: g.__setitem__("x", g.pop("X")), ["key 'x' is not read", "did you mean 'X'"]),
    (lambda g: g.__setitem__("alfa", 1.0), ["key 'alfa' is not read", "did you mean 'alpha'"]),
    (lambda g: g.__setitem__("l1", g.pop("L1")), ["key 'l1'", "did you mean 'L1'"]),
    (lambda g: g.__setitem__("alpha", True), ["alpha = True"]),
    (lambda g: g["L1"][0].__setitem__(0, "1.5"), ["L1", "'1.5' is not a number"]),
])
def test_linf_printed_form_mistakes_are_refused(tmp_path, capsys, edit, words):
    rc, err = check(tmp_path, capsys, "lpv_linf_driver_torque", _linf(edit))
    assert rc == 2 and "ConfigurationError: gains file" in err and len(err.splitlines()) == 1, err
    assert all(w in err for w in words), err


@pytest.mark.parametrize("edit", [
    lambda g: [g.__setitem__(k, (0 * np.array(v)).tolist()) for k, v in list(g.items()) if k[0] in "PX"],
    lambda g: [g.__setitem__(k, (1e308 * np.ones_like(np.array(v))).tolist()) for k, v in list(g.items())
               if k[0] == "L"],
], ids=["singular P+X", "overflowing L"])
def test_linf_printed_form_unusable_numbers_are_not_certified(tmp_path, capsys, edit):
    rc, _ = check(tmp_path, capsys, "lpv_linf_driver_torque", _linf(edit))
    assert rc == 1


@pytest.mark.parametrize("gains, words", [
    ({"l": [[0, 1], [0, 1]]}, ["key 'l' is not read", "did you mean 'L'"]),
    ({"L": [[True, 1], [0, 1]]}, ["entry True is not a number"]),
    ({"L": [["1", 1], [0, 1]]}, ["entry '1' is not a number"]),
])
def test_nonlinear_printed_form_mistakes_are_refused(tmp_path, capsys, gains, words):
    rc, err = check(tmp_path, capsys, "stanford_sideslip_nonlinear_tyre", gains)
    assert rc == 2 and "ConfigurationError: gains file" in err and all(w in err for w in words), err


# --- a stated gamma is the one the gains certify (issue 39: a forged gamma_in_file was printed beside PASS) ---

def _observers_with_gamma(printed: bool) -> list:
    """Built-in observers whose committed lock reports a gamma: those whose family checks a printed form
    of its gains (the lock's own P_i, L_i are such a form) or those checked in the lock form."""
    from codegen import families
    from codegen.contract.capabilities import GainForms
    from codegen.project import observer_file as observers
    out = []
    for name in observers.names():
        family = families.get(observers.get(name).family)
        if isinstance(family, GainForms) == printed and "gamma" in lock(name):
            out.append(name)
    return out


@pytest.fixture(scope="module")
def printed_name():
    names = _observers_with_gamma(printed=True)
    assert names
    return names[0]


def test_the_locks_own_gamma_and_a_rounded_one_pass(tmp_path, capsys, printed_name):
    gains = lock(printed_name)
    rc, err = check(tmp_path, capsys, printed_name, gains)
    assert rc == 0, err
    gains["gamma"] = float(f"{gains['gamma']:.3g}")
    rc, err = check(tmp_path, capsys, printed_name, gains)
    assert rc == 0, err


@pytest.mark.parametrize("factor", [1000.0, 1e-3, 1.01])
def test_a_stated_gamma_the_gains_do_not_certify_is_refused_naming_the_key(tmp_path, capsys, printed_name, factor):
    gains = lock(printed_name)
    true = gains["gamma"]
    gains["gamma"] = true * factor
    rc, err = check(tmp_path, capsys, printed_name, gains)
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert err.startswith("uiogen: error: ConfigurationError: gains file") and "gamma = " in err, err
    import re
    named = re.search(r"these gains certify gamma = ([0-9.e+-]+)", err)
    assert named and float(named.group(1)) == pytest.approx(true, rel=1e-4), err      # the re-derived value
    from codegen.certificate import gains as gains_check
    with pytest.raises(cli.ConfigurationError) as info:
        gains_check._stated_gamma_checked(gains_check.GainsCheck("o", "printed", "f.json", True,
                                                                 cases={"c": {"gamma": true}}), gains, "f.json")
    assert info.value.key == "gamma" and info.value.source == "f.json"


def test_a_stated_claim_of_the_source_is_shown_with_what_the_gains_certify(tmp_path, capsys, printed_name):
    gains = lock(printed_name)
    true = gains.pop("gamma")
    gains["gamma_stated"] = true / 5
    rc = cli.main(["check-gains", printed_name, "--gains", str(_write(tmp_path, gains))])
    out = capsys.readouterr().out
    assert rc == 0
    assert "gamma_stated_in_file_checked" in out and "not certified by these gains" in out


def _write(tmp_path, content) -> Path:
    path = tmp_path / "gains.json"
    path.write_text(json.dumps(content))
    return path


def test_a_lock_file_forged_with_its_checksums_is_refused_naming_the_entry(tmp_path, capsys):
    from codegen.design import lock as design_lock
    names = _observers_with_gamma(printed=False)
    assert names
    name = names[0]
    rc, err = check(tmp_path, capsys, name, lock(name))           # the committed lock, as gains: it passes
    assert rc == 0, err
    data = lock(name)
    data["gamma"] *= 1000
    rc, err = check(tmp_path, capsys, name, design_lock.seal(data))
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert "ConfigurationError: gains file" in err and "the design lock's gamma is not what its own LMI solutions give" \
        in err, err
