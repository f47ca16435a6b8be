"""Probes of the reliability suite (make check) for the five kinds of issue 39, each broader than the
unit test that pinned its fix:

* a model that reads a file, by every route a model file can take (open, pathlib, json, numpy, csv,
  tomllib, pickle, sqlite3, os.open, a helper beside it that reads a file, a module of another folder
  by sys.path, importlib or runpy, a child process): refused at the first verb, one line naming the file;
* a name from every C and Python namespace: every object-like macro the compiler defines for the headers
  the generated C includes (C99, GNU C17, C2x and C++ modes, read from the compiler itself), every C/C++
  keyword, every Python keyword and every module of ``sys.stdlib_module_names``, as an observer name
  (``uiogen new``) and as a state name (the model's import); refused in one line with nothing written, or
  accepted, and then the generated C compiles in every mode and the extension loads beside the standard
  module of that name without shadowing it;
* a singular parameter in several forms (a division by zero, 0**-1, sqrt/log/asin/acosh of a negative
  number, log(0), an overflowing exp, a singular output equation), through ``uiogen design``;
* a campaign sized past memory under a cgroup limit (v1 as on this machine, v2 at the process's cgroup or
  its parent, v2 at the mount's root), read from fake cgroup files by the guard's own reader: refused
  before anything is written, and the duration it advises is accepted; under RLIMIT_AS the advised
  campaign runs;
* a forged design lock (gamma x 1000 or / 1000, a gain, the certificate, with the checksums recomputed;
  alone, and with the generated folder's stamp recomputed too) read by every verb that reads a lock: each
  refuses or re-derives, and none reports the forged number.

Sizes: the macro and keyword lists are read whole; ``sys.stdlib_module_names`` is tried whole as an
observer name and by a sample of 24 (fixed seed) as a state name; two accepted names of each kind are
built (fixed seed).
"""
import hashlib
import json
import os
import pickle
import random
import re
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen import cli
from codegen.campaign import memory, spec as campaign_spec
from codegen.design import lock as design_lock
from codegen.emit import generate as emit
from codegen.errors import ConfigurationError, ModelDefinitionError
from codegen.model import load_parameters
from codegen.model.definition import parameter_substitution
from codegen.project import observer_file as observers
from conftest import new_starter

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
SEED = 39
pytestmark = pytest.mark.reliability


def _cli(*args, cwd=ROOT, timeout=600, code=None) -> subprocess.CompletedProcess:
    head = [sys.executable, "-c", code] if code else [sys.executable, "-m", "codegen.cli"]
    return subprocess.run([*head, *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=timeout)


def _one_line(proc) -> str:
    assert proc.returncode == 2, (proc.stdout[-800:], proc.stderr[-2000:])
    err = proc.stderr.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def _tree(folder: Path) -> dict:
    """{relative path: SHA-256} of every file under ``folder`` but byte-code caches."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*"))
            if p.is_file() and "__pycache__" not in p.parts}


@pytest.fixture(scope="module")
def starter(tmp_path_factory) -> Path:
    """A starter project (``uiogen new``, the default family of the tests' starters), never modified."""
    return new_starter(tmp_path_factory.mktemp("starter") / "p")


@pytest.fixture(scope="module")
def family(starter) -> str:
    """The starter's family (from its observer file, not a literal)."""
    return observers.get(str(starter / "obs1.toml")).family


def _copy(starter: Path, where: Path) -> Path:
    shutil.copytree(starter, where)
    return where


def _forget_user_models():
    for m in [m for m in sys.modules if m.startswith("uiogen_user_model")]:
        del sys.modules[m]


# --- 1. a model that reads a file ------------------------------------------------------------------------

ROUTES = {
    "open": ("S = float(open(HERE / 'tyre.txt').read())", "tyre.txt"),
    "pathlib.read_text": ("S = float((HERE / 'tyre.txt').read_text())", "tyre.txt"),
    "pathlib.read_bytes": ("S = float((HERE / 'tyre.txt').read_bytes())", "tyre.txt"),
    "json.load": ("import json\nS = json.load(open(HERE / 'tyre.json'))['s']", "tyre.json"),
    "numpy.loadtxt": ("import numpy\nS = float(numpy.loadtxt(HERE / 'tyre.csv'))", "tyre.csv"),
    "numpy.fromfile": ("import numpy\nS = float(numpy.fromfile(HERE / 'tyre.bin')[0])", "tyre.bin"),
    "numpy.load": ("import numpy\nS = float(numpy.load(HERE / 'tyre.npy')[0])", "tyre.npy"),
    "csv": ("import csv\nS = float(next(csv.reader(open(HERE / 'tyre.csv')))[0])", "tyre.csv"),
    "tomllib": ("import tomllib\nS = tomllib.load(open(HERE / 'tyre.toml', 'rb'))['s']", "tyre.toml"),
    "configparser": ("import configparser\n_c = configparser.ConfigParser()\n_c.read(HERE / 'tyre.ini')\n"
                     "S = float(_c['t']['s'])", "tyre.ini"),
    "pickle": ("import pickle\nS = pickle.load(open(HERE / 'tyre.pkl', 'rb'))", "tyre.pkl"),
    "os.open": ("import os\n_fd = os.open(HERE / 'tyre.txt', os.O_RDONLY)\nS = float(os.read(_fd, 64))\n"
                "os.close(_fd)", "tyre.txt"),
    "io.FileIO": ("import io\nS = float(io.FileIO(HERE / 'tyre.txt').read())", "tyre.txt"),
    "linecache": ("import linecache\nS = float(linecache.getline(str(HERE / 'tyre.txt'), 1))", "tyre.txt"),
    "sqlite3": ("import sqlite3\nS = sqlite3.connect(HERE / 'tyre.db').execute('select s from t').fetchone()[0]",
                "tyre.db"),
    "a helper beside it that reads a file": ("from tyre_helper import S", "tyre.json"),
    "sys.path of another folder": ("import sys\nsys.path.insert(0, FAR)\nfrom far_data import S", "far_data.py"),
    "importlib by path": ("import importlib.util\n_s = importlib.util.spec_from_file_location('far_data', "
                          "FAR + '/far_data.py')\n_m = importlib.util.module_from_spec(_s)\n"
                          "_s.loader.exec_module(_m)\nS = _m.S", "far_data.py"),
    "runpy": ("import runpy\nS = runpy.run_path(FAR + '/far_data.py')['S']", "far_data.py"),
    "a child process": ("import subprocess\nS = float(subprocess.run(['cat', str(HERE / 'tyre.txt')], "
                        "capture_output=True, check=True).stdout)", "tyre.txt"),
}


def _data_files(folder: Path, far: Path) -> None:
    (folder / "tyre.txt").write_text("1.0\n")
    (folder / "tyre.json").write_text('{"s": 1.0}')
    (folder / "tyre.csv").write_text("1.0\n")
    np.array([1.0]).tofile(folder / "tyre.bin")
    np.save(folder / "tyre.npy", np.array([1.0]))
    (folder / "tyre.toml").write_text("s = 1.0\n")
    (folder / "tyre.ini").write_text("[t]\ns = 1.0\n")
    (folder / "tyre.pkl").write_bytes(pickle.dumps(1.0))
    with sqlite3.connect(folder / "tyre.db") as db:
        db.execute("create table t (s real)")
        db.execute("insert into t values (1.0)")
    db.close()
    (folder / "tyre_helper.py").write_text("import json, pathlib\n"
                                           "S = json.loads((pathlib.Path(__file__).parent / 'tyre.json').read_text())"
                                           "['s']\n")
    far.mkdir()
    (far / "far_data.py").write_text("S = 1.0\n")


@pytest.mark.parametrize("route", ROUTES)
def test_probe_a_model_reading_a_file_by_any_route_is_refused_at_the_first_verb(starter, tmp_path, route):
    project = _copy(starter, tmp_path / "p")
    _data_files(project, tmp_path / "elsewhere")
    code, read = ROUTES[route]
    model = project / "model.py"
    text = model.read_text()
    model.write_text(f"import pathlib\nHERE = pathlib.Path(__file__).resolve().parent\n"
                     f"FAR = {str(tmp_path / 'elsewhere')!r}\n{code}\n"
                     + text.replace("F_yf = 2 * C_f * alpha_f", "F_yf = 2 * C_f * S * alpha_f"))
    before = _tree(project)
    err = _one_line(_cli("design", project / "obs1.toml", "--update"))
    assert "ModelDefinitionError" in err and read in err and str(model.resolve()) in err, err
    assert _tree(project) == before, "written although refused"


# --- 2. a name from every C and Python namespace --------------------------------------------------------

SHAPE = re.compile(r"[A-Za-z](?:_?[A-Za-z0-9])*")      # what can be a C identifier of the generated code
# keywords of C89 to C23 (C23's and GNU C's own spelled out) and of C++ up to C++20, written here, not
# read from the product
C_KEYWORDS = ("auto break case char const continue default do double else enum extern float for goto if inline "
              "int long register restrict return short signed sizeof static struct switch typedef union unsigned "
              "void volatile while alignas alignof bool constexpr false nullptr static_assert thread_local true "
              "typeof typeof_unqual asm").split()
CXX_KEYWORDS = ("and and_eq bitand bitor catch char8_t char16_t char32_t class compl concept consteval constinit "
                "const_cast co_await co_return co_yield decltype delete dynamic_cast explicit export friend mutable "
                "namespace new noexcept not not_eq operator or or_eq private protected public reinterpret_cast "
                "requires static_cast template this throw try typeid typename using virtual wchar_t xor "
                "xor_eq").split()
GNU_MODES = ["-std=c99", "-std=c99 -D_DEFAULT_SOURCE", "-std=gnu11", "-std=gnu17", "-std=gnu2x"]


def _cc(*args, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([os.environ.get("CC", "cc"), *args], capture_output=True, text=True, **kw)


def _included_headers() -> list:
    """The system headers the committed generated C includes (read from the files)."""
    found = set()
    for f in (ROOT / "generated_c").glob("*/*.[ch]"):
        found.update(re.findall(r"#include <([^>]+)>", f.read_text()))
    assert found, "no generated C"
    return sorted(found)


def _supported(flags: str, lang: str = "c") -> bool:
    return _cc(*flags.split(), "-x", lang, "-fsyntax-only", "-", input="int x;\n").returncode == 0


def _compiler_macros(tmp_path) -> set:
    """Every object-like macro the compiler defines after the generated C's system headers, in the C modes
    a user may compile them in (C99; with _DEFAULT_SOURCE; GNU C11, C17, C2x; GNU C++17)."""
    if shutil.which(os.environ.get("CC", "cc")) is None:
        pytest.skip("no C compiler")
    src = tmp_path / "h.c"
    src.write_text("".join(f"#include <{h}>\n" for h in _included_headers()))
    names = set()
    modes = [(m, "c") for m in GNU_MODES] + [("-std=gnu++17", "c++")]
    for flags, lang in modes:
        if not _supported(flags, lang):
            continue
        proc = _cc(*flags.split(), "-x", lang, "-dM", "-E", str(src))
        assert proc.returncode == 0, proc.stderr
        for line in proc.stdout.splitlines():
            m = re.match(r"#define ([A-Za-z_][A-Za-z0-9_]*)(\s|$)", line)      # object-like: no '(' after
            if m and SHAPE.fullmatch(m.group(1)):
                names.add(m.group(1))
    assert len(names) > 100, sorted(names)
    return names


def _new(tmp_path, name, capsys, family) -> tuple:
    """``uiogen new DIR --family F --name NAME`` in this process: (exit status, stderr, whether DIR exists)."""
    folder = tmp_path / f"n_{hashlib.sha256(name.encode()).hexdigest()[:12]}"
    code = cli.main(["new", str(folder), "--family", family, "--name", name])
    err = capsys.readouterr().err
    return code, err, folder.exists()


def test_probe_every_macro_and_keyword_is_refused_as_an_observer_name(tmp_path, capsys, family):
    """uiogen new: one typed line, exit 2, nothing written -- for every macro the compiler defines after the
    generated C's headers (in any mode) and every C/C++ keyword of the right shape."""
    names = sorted((_compiler_macros(tmp_path) | set(C_KEYWORDS) | set(CXX_KEYWORDS)))
    accepted = []
    for name in names:
        code, err, written = _new(tmp_path, name, capsys, family)
        if code == 0:
            accepted.append(name)
            continue
        assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (name, err)
        assert "ConfigurationError" in err and "an observer name is a C identifier" in err and name in err, (name, err)
        assert not written, name
    assert not accepted, f"{len(accepted)} of {len(names)} macros/keywords accepted as observer names: {accepted}"


def _rename_state(project: Path, name: str) -> Path:
    """The starter's model with its state beta renamed ``name`` (the symbol's name and its unit)."""
    model = project / "model.py"
    text = model.read_text()
    assert 'sp.symbols("beta r delta delta_dot")' in text and '"beta": "rad"' in text
    model.write_text(text.replace('sp.symbols("beta r delta delta_dot")',
                                  f'(sp.Symbol({name!r}), *sp.symbols("r delta delta_dot"))')
                     .replace('"beta": "rad"', f'{name!r}: "rad"'))
    return model


def test_probe_every_macro_keyword_and_a_sample_of_python_names_as_a_state_name(starter, tmp_path):
    """The model's import (every verb's first step): a macro or keyword refused as ModelDefinitionError naming
    the state; a Python keyword or standard module name (a sample) either refused or accepted -- the builds
    below compile the accepted ones."""
    import keyword
    rng = random.Random(SEED)
    macros = sorted(_compiler_macros(tmp_path))
    refuse = sorted(set(C_KEYWORDS) | set(CXX_KEYWORDS)) + macros
    python = sorted(keyword.kwlist + keyword.softkwlist) + rng.sample(sorted(sys.stdlib_module_names), 24)
    project = _copy(starter, tmp_path / "p")
    wrong = []
    for name in refuse + python:
        shutil.copy2(starter / "model.py", project / "model.py")
        _rename_state(project, name)
        _forget_user_models()
        try:
            observers.get(str(project / "obs1.toml")).load_definition()
        except ModelDefinitionError as exc:
            assert f"the state {name!r}" in str(exc), (name, str(exc))
            continue
        if name in refuse:
            wrong.append(name)
    _forget_user_models()
    assert not wrong, f"{len(wrong)} macros/keywords accepted as state names: {wrong}"
    # and at the command line: one line, before any C (two of them, chosen with the seed)
    for name in rng.sample(refuse, 2):
        shutil.copy2(starter / "model.py", project / "model.py")
        _rename_state(project, name)
        err = _one_line(_cli("design", project / "obs1.toml"))
        assert "ModelDefinitionError" in err and f"the state {name!r}" in err, err
        assert not (project / "generated_c").exists()


def test_probe_every_standard_module_name_as_an_observer_name(tmp_path, capsys, family):
    """Every name of sys.stdlib_module_names through uiogen new: refused in one line with nothing written, or
    accepted (then its extension must not shadow the standard module: built below)."""
    accepted = []
    for name in sorted(sys.stdlib_module_names):
        code, err, written = _new(tmp_path, name, capsys, family)
        if code == 0:
            accepted.append(name)
            assert written
        else:
            assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (name, err)
            assert "an observer name is a C identifier" in err and name in err, (name, err)
            assert not written, name
    assert accepted, "no standard module name accepted: the builds below have nothing to build"


def _accepted_pairs() -> list:
    """Two (observer name, state name) pairs the rule accepts (fixed seed): an observer named like a standard
    module that has a C accelerator ``_NAME``, a state named like a Python keyword or a C library function."""
    from codegen.model.names import c_name_problem
    import keyword
    rng = random.Random(SEED)
    modules = sorted(n for n in sys.stdlib_module_names if f"_{n}" in sys.stdlib_module_names
                     and c_name_problem(n) is None)
    states = sorted(n for n in keyword.kwlist + ["sin", "exp", "main", "exit", "printf", "malloc", "arg", "res",
                                                 "w", "iw", "mem", "state", "status", "inputs", "out"]
                    if c_name_problem(n) is None)
    return list(zip(rng.sample(modules, 2), rng.sample(states, 2)))


@pytest.mark.parametrize("observer, state", _accepted_pairs())
def test_probe_an_accepted_name_compiles_in_every_mode_and_shadows_nothing(tmp_path, family, observer, state):
    project = tmp_path / "p"
    assert _cli("new", project, "--family", family, "--name", observer).returncode == 0
    _rename_state(project, state)
    for verb in ("generate", "build"):
        proc = _cli(verb, project / f"{observer}.toml")
        assert proc.returncode == 0, (verb, proc.stdout[-1000:], proc.stderr[-2000:])
    folder = project / "generated_c" / observer
    sources = [str(p) for p in sorted(folder.glob("*.c"))]
    for flags in [m for m in GNU_MODES if _supported(m)]:
        proc = _cc(*flags.split(), "-pedantic", "-Wall", "-Werror", "-fsyntax-only", f"-I{folder}", *sources)
        assert proc.returncode == 0, (flags, proc.stderr[-2000:])
    if _supported("-std=gnu++17", "c++"):
        proc = _cc("-x", "c++", "-std=gnu++17", "-fsyntax-only", f"-I{folder}", "-", input=f'#include "{observer}.h"\n'
                   "int main() { return 0; }\n")
        assert proc.returncode == 0, proc.stderr[-2000:]
    probe = ("import importlib, sys\nimport python_bindings as pb\nobs = pb.load(sys.argv[1])\n"
             "name = sys.argv[2]\nmod = importlib.import_module(name)\n"
             "for m in (name, '_' + name):\n"
             "    f = getattr(sys.modules.get(m), '__file__', '') or ''\n"
             "    assert 'build' not in f.split('/') and 'extensions' not in f, (m, f)\n"
             "assert sys.argv[3] in obs.output_names or sys.argv[3] in getattr(obs, 'state_names', obs.output_names), "
             "obs.output_names\n"
             "import numpy as np\nout, status, _ = obs.run(np.zeros((20, obs.n_input)))\n"
             "assert np.isfinite(out).all()\nprint('ok')\n")
    proc = subprocess.run([sys.executable, "-c", probe, str(project / f"{observer}.toml"), observer, state],
                          capture_output=True, text=True, cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr[-2000:]


# --- 3. a singular parameter ---------------------------------------------------------------------------

SINGULAR = {   # the starter's lateral force line rewritten, the singular values, the parameters named, good values
    "division by zero": ("F_yf = 2 * C_f * alpha_f / (l_f - l_r)", {"l_f": 1.3, "l_r": 1.3}, "l_f, l_r",
                         {"l_f": 1.2, "l_r": 1.4}),
    "0**-1": ("F_yf = 2 * C_f * alpha_f * (l_f / l_r - 1)**-1", {"l_f": 1.3, "l_r": 1.3}, "l_f, l_r",
              {"l_f": 1.2, "l_r": 1.6}),
    "sqrt of a negative": ("F_yf = 2 * C_f * alpha_f * sp.sqrt(l_f - l_r)", {"l_f": 1.0, "l_r": 1.5}, "l_f, l_r",
                           {"l_f": 1.5, "l_r": 1.0}),
    "log of a negative": ("F_yf = 2 * C_f * alpha_f * sp.log(l_f / l_r - 1)", {"l_f": 1.2, "l_r": 1.6}, "l_f, l_r",
                          {"l_f": 1.6, "l_r": 1.2}),
    "log of zero": ("F_yf = 2 * C_f * alpha_f * sp.log(l_f / l_r - 1)", {"l_f": 1.3, "l_r": 1.3}, "l_f, l_r",
                    {"l_f": 1.6, "l_r": 1.2}),
    "asin beyond 1": ("F_yf = 2 * C_f * alpha_f * sp.asin(l_f / l_r)", {"l_f": 1.5, "l_r": 1.0}, "l_f, l_r",
                      {"l_f": 1.0, "l_r": 1.5}),
    "acosh below 1": ("F_yf = 2 * C_f * alpha_f * sp.acosh(l_f / l_r)", {"l_f": 1.0, "l_r": 1.5}, "l_f, l_r",
                      {"l_f": 1.5, "l_r": 1.0}),
    "exp overflowing": ("F_yf = 2 * C_f * alpha_f * sp.exp(800 * l_f / l_r)", {"l_f": 1.3, "l_r": 1.3}, "l_f, l_r",
                        {"l_f": 0.8, "l_r": 1.6}),
    "in an output equation": ("OUTPUT", {"l_f": 1.3, "l_r": 1.3}, "l_f, l_r", {"l_f": 1.2, "l_r": 1.6}),
}


def _set(path: Path, values: dict) -> None:
    lines = path.read_text().splitlines()
    for k, v in values.items():
        i = next(i for i, line in enumerate(lines) if line.split("=")[0].strip() == k)
        lines[i] = f"{k} = {v}"
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("form", SINGULAR)
def test_probe_a_singular_parameter_is_one_line_at_design(starter, tmp_path, form):
    line, values, named, good = SINGULAR[form]
    project = _copy(starter, tmp_path / "p")
    model = project / "model.py"
    text = model.read_text().replace('"l_f l_r eta_t R_s B_s K_p M I_z I_s C_f C_r", positive=True)',
                                     '"l_f l_r eta_t R_s B_s K_p M I_z I_s C_f C_r")')
    if line == "OUTPUT":
        assert text.count('outputs=(("r", r),') == 2
        text = text.replace('outputs=(("r", r),', 'outputs=(("r", r / (l_f / l_r - 1)),', 1)
    else:
        assert "F_yf = 2 * C_f * alpha_f\n" in text
        text = text.replace("F_yf = 2 * C_f * alpha_f\n", line + "\n", 1)
    model.write_text(text)
    _set(project / "parameters.toml", values)
    before = _tree(project)
    err = _one_line(_cli("design", project / "obs1.toml", "--update"))
    assert "ConfigurationError" in err and "parameters.toml" in err and named in err, err
    assert all(f"{v}" in err for v in values.values()), err
    assert _tree(project) == before
    # the advice (values that keep every part finite and real) works: other values pass the check
    _set(project / "parameters.toml", good)
    _forget_user_models()
    config = observers.get(str(project / "obs1.toml"))
    assert parameter_substitution(config.load_model(), load_parameters(config.parameter_path))
    _forget_user_models()


# --- 4. a campaign sized past memory under a cgroup limit ------------------------------------------------

CAMPAIGN_OBSERVER = "lpv_linf_driver_torque"            # a built-in observer (built by `uiogen build`)
LIMIT = 3 * memory.GiB


def _fake_cgroup(root: Path, layout: str) -> Path:
    """A fake file system root (proc/self/cgroup, proc/meminfo and the cgroup files) whose only limit below
    the machine's is LIMIT, set where ``layout`` says (with some of it in use by other processes)."""
    files = {"proc/meminfo": "MemTotal:       67108864 kB\nMemAvailable:   67108864 kB\n"}
    used = 256 * 2 ** 20
    if layout == "v1 (this machine's layout: a parent's limit)":
        files.update({"proc/self/cgroup": "4:memory:/process_api/job\n0::/\n",
                      "sys/fs/cgroup/memory/process_api/job/memory.limit_in_bytes": "9223372036854771712\n",
                      "sys/fs/cgroup/memory/process_api/memory.limit_in_bytes": f"{LIMIT + used}\n",
                      "sys/fs/cgroup/memory/process_api/memory.usage_in_bytes": f"{used}\n"})
    elif layout == "v2 at the process's cgroup":
        files.update({"proc/self/cgroup": "0::/user.slice/job.scope\n",
                      "sys/fs/cgroup/user.slice/job.scope/memory.max": f"{LIMIT + used}\n",
                      "sys/fs/cgroup/user.slice/job.scope/memory.current": f"{used}\n",
                      "sys/fs/cgroup/user.slice/memory.max": "max\n"})
    else:                                   # a container without a cgroup namespace: its limit at the mount's root
        files.update({"proc/self/cgroup": "0::/docker/abc123\n", "sys/fs/cgroup/memory.max": f"{LIMIT + used}\n",
                      "sys/fs/cgroup/memory.current": f"{used}\n"})
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


_UNDER_FAKE_ROOT = ("import functools, sys\nfrom codegen.campaign import memory\n"
                    "memory.memory_limit = functools.partial(memory.memory_limit, sys.argv[1])\n"
                    "from codegen.cli import main\nsys.exit(main(sys.argv[2:]))\n")
_UNDER_RLIMIT_AS = ("import resource, sys\nlim = int(sys.argv[1])\n"
                    "resource.setrlimit(resource.RLIMIT_AS, (lim, resource.RLIM_INFINITY))\n"
                    "from codegen.cli import main\nsys.exit(main(sys.argv[2:]))\n")


def _campaign_file(path: Path, duration: float, runs: int = 4) -> Path:
    path.write_text(f'observer = "{CAMPAIGN_OBSERVER}"\nscenarios = ["excitation"]\nruns = {runs}\n'
                    f'scenario_seed = "per_run"\nduration = {duration}\n')
    return path


def _advised(err: str) -> float:
    return float(re.search(r"a run of at most ([0-9.e+]+) s fits", err).group(1))


@pytest.mark.parametrize("layout", ["v1 (this machine's layout: a parent's limit)", "v2 at the process's cgroup",
                                    "v2 at the mount's root"])
def test_probe_a_campaign_past_a_cgroup_limit_is_refused_and_its_advice_fits(tmp_path, layout):
    root = _fake_cgroup(tmp_path / "root", layout)
    limit = memory.memory_limit(root)
    assert limit.bytes == LIMIT and limit.source.startswith("cgroup v") and "less the" in limit.source, limit
    out = tmp_path / "out"
    for duration, workers in ((30000.0, 2), (300000.0, 1), (3000.0, 16)):
        spec = _campaign_file(tmp_path / "big.toml", duration)
        err = _one_line(_cli(root, "campaign", spec, "--workers", workers, "--out", out, code=_UNDER_FAKE_ROOT))
        assert "ConfigurationError" in err and str(root) in err and "more than the limit of" in err, err
        assert not out.exists()
        parsed = campaign_spec.load(spec)
        if "--workers" in err:                   # too many workers: the number it names fits, one more does not
            fit = int(re.search(r"`--workers (\d+)`", err).group(1))
            assert memory.check(parsed, fit, limit)
            with pytest.raises(ConfigurationError):
                memory.check(parsed, fit + 1, limit)
            continue
        fit = _advised(err)                      # the duration it names fits, with one worker; 1 % more does not
        assert memory.check(campaign_spec.parse({**_toml(spec), "duration": fit}, str(spec)), 1, limit)
        with pytest.raises(ConfigurationError):
            memory.check(campaign_spec.parse({**_toml(spec), "duration": fit * 1.01}, str(spec)), 1, limit)


def _toml(path: Path) -> dict:
    import tomllib
    return tomllib.loads(path.read_text())


def test_probe_the_campaign_the_guard_advises_under_rlimit_as_runs(tmp_path):
    """RLIMIT_AS (which the guard reads) of 2 GiB: a 30,000 s campaign is refused naming the longest run that
    fits; that campaign (one run, one worker) then runs under the same limit (no MemoryError, no kill)."""
    out = tmp_path / "out"
    spec = _campaign_file(tmp_path / "big.toml", 30000.0, runs=1)
    err = _one_line(_cli(2 * memory.GiB, "campaign", spec, "--workers", 1, "--out", out, code=_UNDER_RLIMIT_AS))
    assert "(RLIMIT_AS)" in err and not out.exists(), err
    fit = _advised(err)
    spec = _campaign_file(tmp_path / "fits.toml", fit, runs=1)
    proc = _cli(2 * memory.GiB, "campaign", spec, "--workers", 1, "--out", out, code=_UNDER_RLIMIT_AS, timeout=900)
    assert proc.returncode == 0, (proc.stdout[-1500:], proc.stderr[-3000:])
    rows = (out / "runs.csv").read_text().splitlines()
    assert len(rows) == 2 and "worker_lost" not in rows[1] and "error" not in rows[1].lower(), rows


# --- 5. a forged lock read by every verb ------------------------------------------------------------------

def _numbers(text: str) -> list:
    return [float(t) for t in re.findall(r"[-+]?\d+\.?\d*(?:[eE][-+]?\d+)?", text)]


def _reports(text: str, forged: float, true: float) -> bool:
    """Whether ``text`` shows the forged figure (to the digits it prints, 4 at least) rather than the true one."""
    return any(math_close(x, forged) and not math_close(x, true) for x in _numbers(text))


def math_close(a: float, b: float) -> bool:
    return b != 0 and abs(a - b) <= 5e-4 * abs(b)


FORGERIES = {   # entry: (edit of the parsed lock, the forged figure, the true figure)
    "gamma x 1000": lambda d: ("gamma", 1000.0),
    "gamma / 1000": lambda d: ("gamma", 1e-3),
    "certificate bound x 1000": lambda d: ("certificate", 1000.0),
    "a gain x 1.5": lambda d: ("gains_at_vertices", 1.5),
}


def _forge(data: dict, what: str) -> tuple:
    """``data`` forged as ``what`` says (in place): (forged figure, true figure)."""
    entry, factor = FORGERIES[what](data)
    if entry == "gamma":
        true = data["gamma"]
        data["gamma"] = true * factor
    elif entry == "certificate":
        bound = data["certificate"]["bounds"][0]
        true = bound["value"]
        bound["value"] = true * factor
    else:
        key = sorted(data["gains_at_vertices"])[0]
        row = data["gains_at_vertices"][key][0]
        true = row[0]
        row[0] = true * factor
    return true * factor, true


def _verbs(project: Path, obs: Path, lock_copy: Path, every: bool) -> dict:
    """The verbs that read a lock, as command lines (all of them, or the ones that re-derive or build)."""
    camp = _campaign_file(project / "camp.toml", 4.0, runs=2)
    camp.write_text(camp.read_text().replace(f'"{CAMPAIGN_OBSERVER}"', json.dumps(str(obs))))
    load = ("import sys\nimport python_bindings as pb\nfrom codegen.errors import UiogenError\n"
            "try:\n    obs = pb.load(sys.argv[1])\nexcept UiogenError as exc:\n"
            "    sys.exit(f'refused: {type(exc).__name__}: {exc}')\n"
            "print(obs.name, getattr(obs, 'gamma', ''), getattr(obs, 'certificate', ''))\n")
    verbs = {
        "generate --force": ("generate", obs, "--force"), "build": ("build", obs),
        "export fmu": ("export", obs, "--format", "fmu", "--out", project / "o.fmu"),
        "check-gains (the forged lock as gains)": ("check-gains", obs, "--gains", lock_copy),
    }
    if every:
        verbs.update({
            "generate": ("generate", obs), "build --float32": ("build", obs, "--float32"),
            "validate": ("validate", obs, "--scenario", "excitation", "--duration", "3", "--json"),
            "export fmu3": ("export", obs, "--format", "fmu3", "--out", project / "o3.fmu"),
            "campaign": ("campaign", camp, "--workers", "1", "--out", project / "camp"),
            "campaign --only": ("campaign", camp, "--only", "0"),
            "design": ("design", obs), "design --json": ("design", obs, "--json"),
            "analyze": ("analyze", obs, "--no-design", "--json"),
            "python load()": ("-c", load, obs),
        })
    return verbs


@pytest.mark.parametrize("stamp", ["lock only", "lock and the generated folder's stamp"])
def test_probe_a_forged_lock_is_refused_or_re_derived_by_every_verb(starter, tmp_path, stamp):
    """Every verb on a lock forged with its checksums recomputed (gamma x 1000 and / 1000 through every verb;
    the certificate's bound and a gain through the verbs that re-derive, build or check): it refuses (a
    non-zero exit, one line, which may quote the forged figure as the lock's), or goes on without reporting the
    forged figure and without writing anything built from it. check-gains refuses a gains file whose gamma is not
    the one its gains certify (a ConfigurationError naming the file and the key: the forged lock is a gains file
    there); a file's ``gamma_stated`` (its source's claim) is echoed with what the gains certify beside it."""
    project = _copy(starter, tmp_path / "p")
    obs = project / "obs1.toml"
    for verb in ("generate", "build"):
        assert _cli(verb, obs).returncode == 0
    config = observers.get(str(obs))
    lock = design_lock.path(config)
    folder = lock.parent
    good = {p: p.read_bytes() for p in folder.iterdir()}
    findings = []
    for what in FORGERIES:
        for p in folder.iterdir():
            if p not in good:
                findings.append(f"{what}: {p.name} left in the generated folder")
                p.unlink()
        for p, b in good.items():
            p.write_bytes(b)
        data = json.loads(lock.read_text())
        forged, true = _forge(data, what)
        text = design_lock.dumps(design_lock.seal(data))
        lock.write_text(text)
        design_lock.verify(json.loads(text), str(lock))                 # the checksums alone do not see it
        if stamp != "lock only":
            files = {f.name: f.read_text() for f in folder.iterdir() if f.name != emit.STAMP}
            (folder / emit.STAMP).write_text(emit.stamp_text(emit.emission_inputs(config, text), files))
        lock_copy = tmp_path / "forged_lock.json"
        lock_copy.write_text(text)
        for verb, args in _verbs(project, obs, lock_copy, every=what.startswith("gamma")).items():
            proc = subprocess.run([sys.executable, *map(str, args)] if args[0] == "-c" else
                                  [sys.executable, "-m", "codegen.cli", *map(str, args)],
                                  capture_output=True, text=True, cwd=ROOT, timeout=600)
            said = proc.stdout + proc.stderr
            shown = "\n".join(line for line in said.splitlines() if "_in_file" not in line)
            if "Traceback" in said:
                findings.append(f"{what}, {verb}: a traceback: {proc.stderr[-300:]}")
            elif proc.returncode != 0:
                typed = (r"DesignLock|StaleExtension|Generation" if not verb.startswith("check-gains") else
                         r"DesignLock|ConfigurationError: gains file \S+: (gamma = |the design lock's)")
                if len(proc.stderr.strip().splitlines()) != 1 or not re.search(typed, proc.stderr):
                    findings.append(f"{what}, {verb}: exit {proc.returncode}: {proc.stderr.strip()[-300:]}")
            elif _reports(shown, forged, true):
                findings.append(f"{what}, {verb}: exit 0, reports the forged {forged:.6g} (true {true:.6g}): "
                                f"{said.strip().splitlines()[-1][:200]}")
            elif verb.startswith("check-gains") and what.startswith("gamma") and not _reports(said, true, forged):
                findings.append(f"{what}, {verb}: exit 0 without the re-derived gamma {true:.6g}")
            for p in (project / "o.fmu", project / "o3.fmu"):        # never an FMU of a forged lock
                if p.exists():
                    findings.append(f"{what}, {verb}: exit {proc.returncode}, wrote {p.name}")
                    p.unlink()
    assert not findings, "\n".join(findings)
