"""An alpha (27b) cannot meet under the gain bound ||K_i|| <= ell is refused naming the bound; a legal alpha
that does not solve names a lower one measured to work (issue 39 weak point: alpha = 1e9 was an
InfeasibleLMIError advising only 'lower alpha')."""
import re
from pathlib import Path

import pytest

from codegen import pipeline
from codegen.errors import ConfigurationError, InfeasibleLMIError
from codegen.families.interconnected_uio import design as du, representation as icm
from codegen.settings import parse_settings
from tests.conftest import new_starter, with_setting

FAMILY = "interconnected_uio"


@pytest.fixture(scope="module")
def toml(tmp_path_factory) -> Path:
    return new_starter(tmp_path_factory.mktemp("decay") / "p", FAMILY) / "obs1.toml"


def _bound(config) -> float:
    from codegen.families.interconnected_uio.build import STEP_KEYS
    settings = parse_settings(du.ICDesignSettings, dict(config.design), source=config.source, extra=STEP_KEYS)
    return du.decay_bound(icm.load(config), settings)[0]


@pytest.mark.parametrize("alpha", ["1e9", "1000.0"])
def test_an_alpha_past_the_gain_bound_is_refused_naming_the_key_and_the_bound(toml, alpha):
    config = with_setting(toml, "alpha", alpha)
    bound = _bound(config)
    assert 0 < bound < float(alpha)
    with pytest.raises(ConfigurationError) as info:
        pipeline.solve(config)
    exc = info.value
    assert exc.key == "alpha" and exc.section == "design" and exc.source == config.source
    assert exc.value == float(alpha)
    assert f"must be < {bound:.4g} 1/s with gain_bound = " in str(exc) and "\n" not in str(exc)


@pytest.mark.slow       # four designs (the failed one and its measured retries)
def test_a_legal_alpha_27_cannot_meet_names_a_lower_alpha_that_designs(toml):
    config = with_setting(toml, "alpha", "100.0")
    assert 100.0 < _bound(config)
    with pytest.raises(InfeasibleLMIError) as info:
        pipeline.solve(config)
    said = re.search(r"measured: with \[design\] alpha = ([0-9.e+-]+) the design is solved and certified",
                     str(info.value))
    assert said, str(info.value)
    b, _ = pipeline.solve(with_setting(toml, "alpha", said.group(1)))
    assert b.design.settings.alpha == float(said.group(1))
