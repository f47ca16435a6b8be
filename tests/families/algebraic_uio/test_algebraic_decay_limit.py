"""An alpha the Gauss step cannot certify at the sample time is refused naming the bound; a legal alpha that
LMI (39) cannot meet names a lower one measured to work (issue 39 weak point: the starter's alpha = 1e9
was an InfeasibleLMIError on 'X >= I' that named neither alpha nor the sample time)."""
import re
from pathlib import Path

import pytest

from codegen import pipeline
from codegen.errors import ConfigurationError, InfeasibleLMIError
from codegen.families.algebraic_uio import design as alg
from tests.conftest import new_starter, with_setting

FAMILY = "algebraic_uio"


@pytest.fixture(scope="module")
def toml(tmp_path_factory) -> Path:
    return new_starter(tmp_path_factory.mktemp("decay") / "p", FAMILY) / "obs1.toml"


def test_the_bound_follows_from_the_gauss_tableau():
    assert alg.GL_ROW_SUM == pytest.approx(0.5 + 3 ** 0.5 / 6)
    assert alg.decay_limit_of_step(0.001) == pytest.approx(1.0 / (0.001 * (0.5 + 3 ** 0.5 / 6)))


@pytest.mark.parametrize("alpha", ["1e9", "2000.0"])
def test_an_alpha_past_the_step_is_refused_naming_the_file_the_key_and_the_bound(toml, alpha):
    config = with_setting(toml, "alpha", alpha)
    limit = alg.decay_limit_of_step(config.sample_time)
    with pytest.raises(ConfigurationError) as info:
        pipeline.solve(config)
    exc = info.value
    assert exc.key == "alpha" and exc.section == "design" and exc.source == config.source
    assert exc.value == float(alpha)
    assert f"must be < {limit:.4g} 1/s at sample_time = {config.sample_time:g} s" in str(exc)
    assert "\n" not in str(exc)


@pytest.mark.slow       # four designs (the failed one and its measured retries)
def test_a_legal_alpha_lmi_39_cannot_meet_names_a_lower_alpha_that_designs(toml):
    config = with_setting(toml, "alpha", "300.0")
    assert 300.0 < alg.decay_limit_of_step(config.sample_time)
    with pytest.raises(InfeasibleLMIError) as info:
        pipeline.solve(config)
    said = re.search(r"measured: with \[design\] alpha = ([0-9.e+-]+) the design is solved and certified",
                     str(info.value))
    assert said, str(info.value)
    b, _ = pipeline.solve(with_setting(toml, "alpha", said.group(1)))       # the advice applied: it designs
    assert b.settings.alpha == float(said.group(1))
