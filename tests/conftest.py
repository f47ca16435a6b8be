import json
from pathlib import Path

import pytest

from codegen import observers, pipeline

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
PUBLISHED = SHARED / "reference" / "seed000_published_design.json"
NAME = "lpv_linf_driver_torque"


@pytest.fixture(scope="session")
def config():
    return observers.get(NAME)


@pytest.fixture(scope="session")
def build(config):
    return pipeline.build(config)


@pytest.fixture(scope="session")
def lpv(config):
    return pipeline.representation(config)[0]


@pytest.fixture(scope="session")
def compiled():
    from python_bindings import load
    return load(NAME)


@pytest.fixture(scope="session")
def published():
    if not PUBLISHED.is_file():
        pytest.skip(f"shared reference file missing: {PUBLISHED}")
    return json.loads(PUBLISHED.read_text())
