"""A campaign's memory: the limit that applies (cgroup v2, v1, physical, RLIMIT_AS), the estimate of
what a run holds (held against a measured run), and the refusal before anything starts of a
campaign that cannot fit (before: a 30,000 s excitation campaign was estimated at 1.9 GiB against
the host's memory, grew to 21 GB and was killed by the kernel, exit status 137 and no message)."""
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from codegen.campaign import engine, memory, spec as campaign_spec
from codegen.errors import ConfigurationError
from conftest import HANG_GUARD

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
OBSERVER = "lpv_linf_driver_torque"
GB = 10 ** 9


def _fake_root(tmp_path, cgroup: str, files: dict) -> Path:
    (tmp_path / "proc" / "self").mkdir(parents=True)
    (tmp_path / "proc" / "self" / "cgroup").write_text(cgroup)
    for rel, text in files.items():
        f = tmp_path / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    return tmp_path


def test_the_limit_is_the_cgroup_v2_one_of_the_process_or_a_parent(tmp_path):
    root = _fake_root(tmp_path, "0::/user.slice/job.scope\n",
                      {"sys/fs/cgroup/user.slice/job.scope/memory.max": "max\n",
                       "sys/fs/cgroup/user.slice/memory.max": f"{3 * GB}\n"})
    lim = memory.memory_limit(root, physical=64 * GB, address_space=None)
    assert lim.bytes == 3 * GB
    assert lim.source == f"cgroup v2 {root / 'sys/fs/cgroup/user.slice/memory.max'}"


def test_max_everywhere_leaves_the_physical_memory(tmp_path):
    root = _fake_root(tmp_path, "0::/\n", {"sys/fs/cgroup/memory.max": "max\n"})
    assert memory.memory_limit(root, physical=64 * GB, address_space=None) == memory.Limit(64 * GB,
                                                                                          "physical memory")


def test_the_limit_is_the_cgroup_v1_one_and_rlimit_as_when_smaller(tmp_path):
    root = _fake_root(tmp_path, "12:cpu,cpuacct:/docker/abc\n11:memory:/docker/abc\n",
                      {"sys/fs/cgroup/memory/docker/abc/memory.limit_in_bytes": f"{2 * GB}\n"})
    lim = memory.memory_limit(root, physical=64 * GB, address_space=None)
    assert lim == memory.Limit(2 * GB, f"cgroup v1 {root / 'sys/fs/cgroup/memory/docker/abc/memory.limit_in_bytes'}")
    assert memory.memory_limit(root, physical=64 * GB, address_space=GB) == memory.Limit(GB, "RLIMIT_AS")


def test_what_the_cgroup_or_the_machine_already_holds_is_not_available(tmp_path):
    root = _fake_root(tmp_path, "0::/job\n", {"sys/fs/cgroup/job/memory.max": f"{8 * GB}\n",
                                               "sys/fs/cgroup/job/memory.current": f"{5 * GB}\n",
                                               "proc/meminfo": "MemTotal: 67108864 kB\nMemAvailable: 4000000 kB\n"})
    lim = memory.memory_limit(root, physical=64 * GB, address_space=None)
    assert lim.bytes == 3 * GB and lim.source.endswith("less the 5000000000 bytes in use")
    (root / "sys/fs/cgroup/job/memory.current").write_text("0\n")
    assert memory.memory_limit(root, physical=64 * GB, address_space=None) == memory.Limit(
        4000000 * 1024, "available memory, MemAvailable of /proc/meminfo")


def test_the_limit_of_this_machine_is_at_most_its_physical_memory():
    import os
    lim = memory.memory_limit()
    assert 0 < lim.bytes <= os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _spec(duration: float, runs: int = 2, source: str = "mem.toml", **more):
    return campaign_spec.parse({"observer": OBSERVER, "scenarios": ["excitation"], "runs": runs,
                                "scenario_seed": "per_run", "duration": duration, **more}, source)


# a run's peak resident memory, measured in a process of its own: the first run warms every lazy import
# and cache, the peak (VmHWM, reset through clear_refs) of the second above the resident memory before
# it is what a run holds; glibc returns every block of 64 kB or more to the system on free (a fixed mmap
# threshold), so the first run's freed arrays do not hide the second's
_MEASURE = textwrap.dedent("""
    import json, sys
    from codegen.campaign import memory, runner, spec as campaign_spec
    spec = campaign_spec.parse({"observer": sys.argv[1], "scenarios": ["excitation"], "runs": 2,
                                "scenario_seed": "per_run", "duration": float(sys.argv[2])}, "mem.toml")
    runner.prepare(spec)
    runner.run_one(spec, 0)
    def status(key):
        line = next(l for l in open("/proc/self/status") if l.startswith(key + ":"))
        return 1024 * int(line.split()[1])
    before = status("VmRSS")
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")
    runner.run_one(spec, 1)
    print(json.dumps({"measured": status("VmHWM") - before, "estimate": memory.run_bytes(memory.sizes(spec))}))
""")


def measure_run(duration: float) -> dict:
    env = {**__import__("os").environ, "MALLOC_MMAP_THRESHOLD_": "65536"}
    proc = subprocess.run([sys.executable, "-c", _MEASURE, OBSERVER, str(duration)], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=HANG_GUARD)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="needs Linux's /proc/self/clear_refs")
def test_the_estimate_of_a_run_is_within_its_factor_of_a_measured_run():
    m = measure_run(600.0)                 # 60,001 samples: about 100 MB, far above the noise of a process
    assert m["measured"] <= m["estimate"] <= memory.FACTOR * m["measured"], m


def test_the_estimate_grows_linearly_with_the_duration_beyond_one_chunk_of_the_plant():
    a, b, c = (memory.sizes(_spec(d)) for d in (100.0, 200.0, 30000.0))
    assert (a.samples, b.samples, c.samples) == (10_001, 20_001, 3_000_001)
    slope = (memory.run_bytes(b) - memory.run_bytes(a)) / 10_000
    assert memory.run_bytes(c) - memory.run_bytes(a) == pytest.approx(slope * 2_990_000, rel=1e-9)


def test_a_campaign_that_cannot_fit_is_refused_before_anything_is_written(tmp_path, monkeypatch):
    """The case of the issue: 30,000 s excitation runs, here against an injected 4 GiB cgroup."""
    limit = memory.Limit(4 * memory.GiB, "cgroup v2 /sys/fs/cgroup/memory.max")
    monkeypatch.setattr(memory, "memory_limit", lambda: limit)

    def started(spec):          # were the check gone, the campaign would stop here, not run 30,000 s runs
        raise AssertionError("the campaign started")
    monkeypatch.setattr(engine.runner, "prepare", started)
    spec = _spec(30000.0, source=str(tmp_path / "long.toml"))
    out = tmp_path / "out"
    with pytest.raises(ConfigurationError) as info:
        engine.run(spec, out, workers=2)
    err = info.value
    assert err.key == "duration" and err.source == spec.source
    assert str(err).startswith(f"{spec.source}: duration = 30000.0: the campaign needs about ")
    assert "more than the limit of 4 GiB (cgroup v2 /sys/fs/cgroup/memory.max)" in str(err)
    fit = float(str(err).split("a run of at most ")[1].split(" s")[0])
    # the duration it names fits, and a tenth more does not
    assert memory.check(_spec(fit), 1, limit)
    with pytest.raises(ConfigurationError):
        memory.check(_spec(1.1 * fit), 1, limit)
    assert not out.exists()


def test_too_many_workers_are_refused_naming_the_workers_that_fit(monkeypatch):
    spec = _spec(3000.0)
    one = memory.estimate(spec, 1)
    limit = memory.Limit(one.total + 2 * one.worker + one.worker // 2, "physical memory")
    with pytest.raises(ConfigurationError, match=r"mem.toml: --workers 8: the campaign needs about .* at most 3 "
                                                 r"local worker\(s\) fit \(`--workers 3`\)") as info:
        memory.check(spec, 8, limit)
    assert info.value.key == "--workers"
    assert memory.check(spec, 3, limit).total <= limit.bytes


def test_the_cli_refuses_without_a_traceback(tmp_path):
    """A limit set on the process itself, RLIMIT_AS (2 GiB: a 30,000 s run of 3,000,001 samples holds more): the
    CLI exits as on every campaign file mistake (2), with its message and nothing written."""
    spec = tmp_path / "long.toml"
    spec.write_text(f'observer = "{OBSERVER}"\nscenarios = ["excitation"]\nruns = 4\nduration = 30000.0\n')
    out = tmp_path / "out"
    code = ("import resource, sys\nfrom codegen.cli import main\n"
            "resource.setrlimit(resource.RLIMIT_AS, (2 * 2 ** 30, resource.RLIM_INFINITY))\n"
            "sys.exit(main(sys.argv[1:]))\n")
    proc = subprocess.run([sys.executable, "-c", code, "campaign", str(spec), "--workers", "1", "--out", str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=HANG_GUARD)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"{spec}: duration = 30000.0: the campaign needs about " in proc.stderr
    assert "(RLIMIT_AS)" in proc.stderr and "a run of at most " in proc.stderr
    assert not out.exists()


def test_a_campaign_that_fits_still_runs(tmp_path):
    summary = engine.run(_spec(12.0, runs=2), tmp_path / "out", workers=1)
    assert summary["runs"] == 2
    assert (tmp_path / "out" / "runs.csv").is_file()
