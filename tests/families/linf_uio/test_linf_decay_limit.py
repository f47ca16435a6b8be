"""An alpha Theorem 1 cannot certify under the gain bound ||M|| <= gain_bound_times_sample_time / Ts is
refused naming the sample time and the bound; a legal alpha that does not solve names a lower one measured
to work (issue 39 weak point: alpha = 1e9 ended in retries that said nothing solves)."""
import re
from pathlib import Path

import numpy as np
import pytest

from codegen import pipeline
from codegen.errors import ConfigurationError, SolverError
from codegen.families.linf_uio import build as lb, design as ld
from tests.conftest import new_starter, with_setting

FAMILY = "linf_uio"


@pytest.fixture(scope="module")
def toml(tmp_path_factory) -> Path:
    return new_starter(tmp_path_factory.mktemp("decay") / "p", FAMILY) / "obs1.toml"


def test_the_bound_is_the_trace_of_21_under_the_gain_bound(toml):
    """Any gains within the bound leave the frozen error matrix a trace >= -n alpha_max: an error matrix
    A + M C with ||M|| <= g has an eigenvalue with real part >= tr / n, so no such M decays faster."""
    config = with_setting(toml, "alpha", "5.0")
    _, poly, _ = lb.representation(config)
    g = lb._settings(config).gain_bound
    bound, i = ld.decay_bound(poly, g)
    C = poly.C[i] * ld.output_scaling(poly)[:, None]
    u, s, vt = np.linalg.svd(C, full_matrices=False)
    M = -g * vt.T @ u.T              # the gain of ||M|| = g that makes tr(M C) the most negative
    assert np.linalg.norm(M, 2) == pytest.approx(g)
    eig = np.linalg.eigvals(poly.A[i] + M @ C)
    assert -eig.real.max() <= bound * (1 + 1e-12)
    assert np.trace(poly.A[i] + M @ C).real / poly.A.shape[1] == pytest.approx(-bound)


def test_alpha_1e9_is_refused_naming_the_sample_time_and_the_bound(toml):
    config = with_setting(toml, "alpha", "1e9")
    _, poly, _ = lb.representation(config)
    bound, _ = ld.decay_bound(poly, lb._settings(config).gain_bound)
    with pytest.raises(ConfigurationError) as info:
        pipeline.solve(config)
    exc = info.value
    assert exc.key == "alpha" and exc.section == "design" and exc.source == config.source and exc.value == 1e9
    assert f"must be < {bound:.4g} 1/s with sample_time = {config.sample_time:g} s" in str(exc)
    assert "\n" not in str(exc)


@pytest.mark.slow       # four designs (the failed one and its measured retries)
def test_a_legal_alpha_that_does_not_solve_names_a_lower_alpha_that_designs(toml):
    config = with_setting(toml, "alpha", "100.0")
    _, poly, _ = lb.representation(config)
    assert 100.0 < ld.decay_bound(poly, lb._settings(config).gain_bound)[0]
    with pytest.raises(SolverError) as info:
        pipeline.solve(config)
    said = re.search(r"measured: with \[design\] alpha = ([0-9.e+-]+) the design is solved", str(info.value))
    assert said, str(info.value)
    b, _ = pipeline.solve(with_setting(toml, "alpha", said.group(1)))
    assert b.design.settings.alpha == float(said.group(1))
