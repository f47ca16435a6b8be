import json
import os
import tempfile
from pathlib import Path

import pytest

# The derived-results cache (codegen.model.cache) of this test session only, for its subprocesses too:
# a run starts cold, and nothing a developer's own runs kept is read.
os.environ["UIOGEN_CACHE_DIR"] = tempfile.mkdtemp(prefix="uiogen-test-cache-")

from codegen.project import observer_file as observers
from codegen import pipeline
from codegen.families.linf_uio import build as linf_build

ROOT = Path(__file__).resolve().parent.parent

HANG_GUARD = 1800.0
"""[s] The one bound a test puts on a child process that finishes in seconds: it only keeps a hung child
from hanging the suite. No test asserts a time (issue 39): a correctness test waits for an event, and
this guard is far beyond what a slow or loaded machine takes."""
SHARED = ROOT.parent / "shared"
PUBLISHED = SHARED / "reference" / "seed000_published_design.json"
NAME = "lpv_linf_driver_torque"


def require_shared(path: Path, what: str = "shared file") -> Path:
    """``path`` under ../shared: a test without it is skipped on a developer's machine, and fails
    in CI (CI=true), where its absence means the checkout was set up wrong."""
    path = Path(path)
    if not path.exists():
        message = f"{what} missing: {path} (the checkout needs ../shared beside it)"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)
    return path


def new_starter(folder: Path, family: str = "linf_uio", name: str = "obs1") -> Path:
    """``uiogen new FOLDER --family FAMILY --name NAME`` in a fresh process (as a user types it); the folder."""
    import subprocess
    import sys
    proc = subprocess.run([sys.executable, "-m", "codegen.cli", "new", str(folder), "--family", family, "--name", name],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    return Path(folder)


def with_setting(toml: Path, key: str, value: str):
    """The observer file ``toml`` with its line ``key = ...`` set to ``value`` (the line must be there; a
    trailing comment stays), read back as the CLI reads it."""
    import re
    from codegen.project import observer_file as observers
    text = toml.read_text()
    assert re.search(rf"(?m)^{key} = ", text), key
    toml.write_text(re.sub(rf"(?m)^{key} = [^ #\n]*", f"{key} = {value}", text))
    return observers.get(str(toml))


def require_strace() -> str:
    """The path of strace (the kill-at-each-syscall tests): skipped where it is missing, a failure
    in CI (CI=true), where .ci/run installs it."""
    import shutil
    path = shutil.which("strace")
    if path is None:
        message = "strace is not installed (apt-get install strace): the crash-safety tests need it"
        if os.environ.get("CI") == "true":
            pytest.fail(message + "; .ci/run installs it")
        pytest.skip(message)
    return path


def require_embedded_tool(ok: bool, what: str) -> None:
    """A cross tool (arm-none-eabi-gcc, qemu-system-arm, cmake): skipped where it is missing, a failure in
    CI (CI=true), where .ci/run installs them (make embedded-tools)."""
    if not ok:
        message = f"{what} not installed (make embedded-tools / scripts/install_embedded_tools.sh)"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)


@pytest.fixture()
def fresh_cache(tmp_path, monkeypatch):
    """An empty derived-results cache of the test's own (``$UIOGEN_CACHE_DIR``), nothing held in memory: what a
    test reads back was kept by the test itself."""
    from codegen.model import cache
    monkeypatch.setenv("UIOGEN_CACHE_DIR", str(tmp_path / "cache"))
    cache.forget()
    yield
    cache.forget()


@pytest.fixture(scope="session")
def config():
    return observers.get(NAME)


@pytest.fixture(scope="session")
def built():
    """``built(NAME)``: the pipeline's build of a built-in observer (its committed design replayed and
    re-checked), made once per test session and shared by every test module that reads it. Tests
    read these builds; a test that changes a design makes its own (``dataclasses.replace``)."""
    cache = {}

    def get(name: str):
        if name not in cache:
            cache[name] = pipeline.build(observers.get(name))
        return cache[name]
    return get


@pytest.fixture(scope="session")
def build(built):
    return built(NAME)


@pytest.fixture(scope="session")
def lpv(config):
    return linf_build.representation(config)[0]


@pytest.fixture(scope="session")
def compiled():
    from python_bindings import load
    return load(NAME)


@pytest.fixture(scope="session")
def published():
    return json.loads(require_shared(PUBLISHED, "shared reference file").read_text())


# --- lanes -----------------------------------------------------------------------------------------
# `make test-fast` runs `pytest -m "not slow"`: no generate, no build, no compiler, QEMU, Dask, mkdocs
# or browser. A test that needs one of them (a compiled extension above all) carries
# @pytest.mark.slow, or its module `pytestmark = pytest.mark.slow`, with the reason beside it.
# The reliability suite and the long runs (make check) are slow by definition; `make test` leaves
# both out (`-m "not long and not reliability"`).

def pytest_collection_modifyitems(config, items):
    for item in items:
        if (item.get_closest_marker("reliability") is not None or item.get_closest_marker("long") is not None) \
                and item.get_closest_marker("slow") is None:
            item.add_marker(pytest.mark.slow)
    # the longest modules first (tests/durations.json, codegen/tools/durations.py): with a module per
    # xdist worker at a time, a long module started last runs alone at the end; the order within a
    # module is kept (a stable sort), a module without a record goes last
    record = json.loads((ROOT / "tests" / "durations.json").read_text())
    items.sort(key=lambda item: -record.get(item.nodeid.split("::")[0], 0.0))
