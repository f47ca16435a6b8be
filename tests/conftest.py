import json
import os
from pathlib import Path

import pytest

from codegen.project import observer_file as observers
from codegen import pipeline
from codegen.families.linf_uio import build as linf_build

ROOT = Path(__file__).resolve().parent.parent
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


@pytest.fixture(scope="session")
def config():
    return observers.get(NAME)


@pytest.fixture(scope="session")
def build(config):
    return pipeline.build(config)


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
