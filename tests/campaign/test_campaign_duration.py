"""A campaign's excitation run is held whole in memory: a ``duration`` whose run cannot fit is the
campaign file's mistake, named before anything is allocated (before: ``duration = 1e6`` ended in a
numpy ``_ArrayMemoryError`` traceback, "Unable to allocate 188. GiB", after the 17 GiB stage-time
matrix had been allocated)."""
import types

import pytest

from codegen.campaign import runner
from codegen.errors import ConfigurationError
from codegen.project import observer_file as observers


def test_a_duration_whose_run_cannot_fit_in_memory_is_refused_naming_the_key():
    config = observers.get("lpv_linf_driver_torque")
    spec = types.SimpleNamespace(source="long.toml", duration=1e9)
    with pytest.raises(ConfigurationError, match=r"long.toml: duration = 1000000000.0: a run that fits in memory "
                                                 r"\(1e\+11 samples at the sample time 0.01 s: its stage inputs alone "
                                                 r"take .* GiB, the machine has .* GiB\)"):
        runner._excitation(spec, config, 0)


def test_a_duration_that_fits_gives_its_run():
    config = observers.get("lpv_linf_driver_torque")
    run = runner._excitation(types.SimpleNamespace(source="short.toml", duration=3.0), config, 0)
    assert run.t.size == 301                   # t = 0, 0.01, ..., 3
