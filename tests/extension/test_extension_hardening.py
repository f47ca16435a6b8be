"""The compiled module's argument checks (python_bindings/templates/pymodule.c.j2).

``step(state, inputs, out)`` and ``run(state, inputs, outputs, status, n)`` take raw arrays and
hand their memory to C, so every array that is not exactly what the C reads (C-contiguous,
aligned, native-endian float64, int32 for the status, writable where written, the right number
of items) must be refused with a TypeError/ValueError naming the argument, and ``n`` must be
bounded before anything is multiplied by it. The calls that crashed the interpreter before the
fix run in a subprocess, so a segfault fails a test instead of killing the runner.
"""
import ctypes
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from codegen.extension import build
from python_bindings import load
from conftest import HANG_GUARD

pytestmark = pytest.mark.slow          # the compiled extensions, and a build of its own

ROOT = next(p for p in Path(__file__).resolve().parents if (p / "pyproject.toml").is_file())
# lpv: N_STATE = N_INPUT = N_OUTPUT = 5; stanford: 3 states, 4 inputs, 3 outputs (a mix-up of
# the three sizes shows there)
NAMES = ["lpv_linf_driver_torque", "stanford_sideslip"]
SWAPPED = ">" if sys.byteorder == "little" else "<"
PY_SSIZE_T_MAX = sys.maxsize


@pytest.fixture(scope="module", params=NAMES)
def obs(request):
    return load(request.param)


def args_for(obs):
    state = np.zeros(obs.n_state)
    inputs = np.linspace(0.1, 0.5, obs.n_input)
    out = np.full(obs.n_output, -7.0)
    return [state, inputs, out]


STEP_ARGS = ["state", "inputs", "out"]


def reference(obs):
    state, inputs, out = args_for(obs)
    status = obs.step(state, inputs, out)
    return status, state.copy(), out.copy()


def unaligned(n, dtype=np.float64):
    """A writable ndarray of n items whose data pointer is not aligned for dtype."""
    raw = np.zeros(n * np.dtype(dtype).itemsize + 1, np.uint8)
    arr = raw[1:].view(dtype)
    assert not arr.flags.aligned
    return arr


# ---------------------------------------------------------------------------------------------
# 1. byte order (the red-team bug: '>f8' was accepted and read as native doubles)

@pytest.mark.parametrize("pos", range(3), ids=STEP_ARGS)
def test_step_refuses_byte_swapped_ndarray(obs, pos):
    args = args_for(obs)
    args[pos] = args[pos].astype(SWAPPED + "f8")
    before = [a.copy() for a in args]
    with pytest.raises(TypeError) as err:
        obs.step(*args)
    msg = str(err.value)
    assert msg.startswith(f"{STEP_ARGS[pos]} must be a native-endian float64 array"), msg
    assert f"{SWAPPED}f8" in msg, msg
    for a, b in zip(args, before):   # nothing written
        assert np.array_equal(a, b)


@pytest.mark.parametrize("pos", range(3), ids=STEP_ARGS)
def test_step_refuses_byte_swapped_buffer(obs, pos):
    """The buffer-protocol path: a memoryview (not an ndarray) with format '>d', and a ctypes
    big-endian double array."""
    args = args_for(obs)
    args[pos] = memoryview(args[pos].astype(SWAPPED + "f8"))
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be a native-endian float64 array, "
                                        rf"got format '\{SWAPPED}d'"):
        obs.step(*args)
    args = args_for(obs)
    swapped_double = ctypes.c_double.__ctype_be__ if SWAPPED == ">" else ctypes.c_double.__ctype_le__
    args[pos] = (swapped_double * len(args[pos]))(*args[pos])
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be a native-endian float64 array"):
        obs.step(*args)


def test_step_accepts_explicit_native_byte_order(obs):
    """'<d' (ctypes on a little-endian host), '=d' (numpy's format when the array is flagged
    unaligned; '=' is native order with standard size, and the pointer is checked separately) and
    '@d'/'d' are all native float64 and give the fast path's result bit for bit."""
    status, state_ref, out_ref = reference(obs)
    # ctypes arrays export '<d' / '>d' explicitly (native here)
    state, inputs, out = args_for(obs)
    c_state = (ctypes.c_double * obs.n_state)(*state)
    c_inputs = (ctypes.c_double * obs.n_input)(*inputs)
    c_out = (ctypes.c_double * obs.n_output)(*out)
    assert memoryview(c_inputs).format == ("<d" if sys.byteorder == "little" else ">d")
    assert obs.step(c_state, c_inputs, c_out) == status
    assert list(c_state) == list(state_ref) and list(c_out) == list(out_ref)
    # '=d' of an aligned pointer, through the buffer path
    state, inputs, out = args_for(obs)
    flagged = inputs.copy()
    flagged.setflags(align=False)
    view = memoryview(flagged)
    assert view.format == "=d"
    assert obs.step(state, view, out) == status
    assert np.array_equal(state, state_ref) and np.array_equal(out, out_ref)
    # native ndarray with an explicit '<' / '=' dtype is the same dtype
    state, inputs, out = args_for(obs)
    assert obs.step(state, inputs.astype("=f8"), out) == status
    assert np.array_equal(out, out_ref)


def test_run_refuses_byte_swapped_arrays(obs):
    n = 3
    good = dict(state=np.zeros(obs.n_state), inputs=np.full((n, obs.n_input), 0.1),
                outputs=np.empty((n, obs.n_output)), status=np.empty(n, np.int32))
    for key, dtype, want in [("state", "f8", "float64"), ("inputs", "f8", "float64"),
                             ("outputs", "f8", "float64"), ("status", "i4", "int32")]:
        args = {k: v.copy() for k, v in good.items()}
        args[key] = args[key].astype(SWAPPED + dtype)
        with pytest.raises(TypeError, match=rf"^{key} must be a native-endian {want} array, got \{SWAPPED}{dtype}"):
            obs.module.run(args["state"], args["inputs"], args["outputs"], args["status"], n)
        args[key] = memoryview(args[key])
        with pytest.raises(TypeError, match=rf"^{key} must be a native-endian {want} array, got format"):
            obs.module.run(args["state"], args["inputs"], args["outputs"], args["status"], n)


# ---------------------------------------------------------------------------------------------
# 2. the other ways an array can be wrong keep a clear error

@pytest.mark.parametrize("pos", range(3), ids=STEP_ARGS)
def test_step_refuses_wrong_dtype(obs, pos):
    for dtype in (np.float32, np.int64, np.complex128, np.longdouble):
        args = args_for(obs)
        args[pos] = args[pos].astype(dtype)
        with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must .*float64"):
            obs.step(*args)
        args[pos] = memoryview(args[pos])
        with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must .*float64"):
            obs.step(*args)


@pytest.mark.parametrize("pos", range(3), ids=STEP_ARGS)
def test_step_refuses_non_contiguous(obs, pos):
    args = args_for(obs)
    args[pos] = np.zeros(2 * len(args[pos]))[::2]
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be a C-contiguous .*float64 array"):
        obs.step(*args)
    args[pos] = memoryview(np.zeros(2 * len(args[pos])))[::2]
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be a C-contiguous .*float64 array"):
        obs.step(*args)


@pytest.mark.parametrize("pos", [0, 2], ids=["state", "out"])
def test_step_refuses_read_only_for_written_args(obs, pos):
    args = args_for(obs)
    args[pos].setflags(write=False)
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be a .*writable .*float64 array"):
        obs.step(*args)
    args = args_for(obs)
    args[pos] = memoryview(args[pos].tobytes()).cast("d")    # bytes: read-only buffer
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be a .*writable .*float64 array"):
        obs.step(*args)


def test_step_accepts_read_only_inputs(obs):
    status, _, out_ref = reference(obs)
    state, inputs, out = args_for(obs)
    inputs.setflags(write=False)
    assert obs.step(state, inputs, out) == status
    assert np.array_equal(out, out_ref)
    state, inputs, out = args_for(obs)
    assert obs.step(state, memoryview(inputs.tobytes()).cast("d"), out) == status
    assert np.array_equal(out, out_ref)


@pytest.mark.parametrize("pos", range(3), ids=STEP_ARGS)
def test_step_refuses_wrong_size(obs, pos):
    want = [obs.n_state, obs.n_input, obs.n_output][pos]
    for size in (0, want - 1, want + 1):
        args = args_for(obs)
        args[pos] = np.zeros(size)
        with pytest.raises(ValueError, match=rf"^{STEP_ARGS[pos]} must hold {want} values, got {size}$"):
            obs.step(*args)
        args[pos] = bytearray(8 * size)           # plain buffer, format 'B': wrong kind first
        with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must .*float64"):
            obs.step(*args)


@pytest.mark.parametrize("pos", range(3), ids=STEP_ARGS)
def test_step_refuses_unaligned(obs, pos):
    """An unaligned double pointer is undefined behaviour in C (and vectorized code may use aligned
    loads); before the fix the buffer path accepted it ('=d' from numpy, 'd' from a memoryview)."""
    want = [obs.n_state, obs.n_input, obs.n_output][pos]
    args = args_for(obs)
    args[pos] = unaligned(want)
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be an aligned float64 array"):
        obs.step(*args)
    args[pos] = memoryview(bytearray(8 * want + 8))[1:8 * want + 1].cast("d")
    with pytest.raises(TypeError, match=rf"^{STEP_ARGS[pos]} must be an aligned float64 array"):
        obs.step(*args)


def test_step_arity_and_non_arrays(obs):
    state, inputs, out = args_for(obs)
    with pytest.raises(TypeError, match="takes exactly 3 arrays"):
        obs.step(state, inputs)
    with pytest.raises(TypeError, match=r"^inputs must be a C-contiguous .*float64 array"):
        obs.step(state, list(inputs), out)


def test_run_status_must_be_int32(obs):
    n = 2
    state, inputs, outputs = np.zeros(obs.n_state), np.zeros((n, obs.n_input)), np.empty((n, obs.n_output))
    for bad in (np.empty(n, np.int64), np.empty(n, np.uint32), np.empty(n, np.float64), np.empty(n, np.int16)):
        with pytest.raises(TypeError, match=r"^status must .*int32"):
            obs.module.run(state, inputs, outputs, bad, n)
        with pytest.raises(TypeError, match=r"^status must .*int32"):
            obs.module.run(state, inputs, outputs, memoryview(bad), n)   # '@l' is 8 bytes here
    ok = (ctypes.c_int32 * n)()                                            # '<i'
    obs.module.run(state, inputs, outputs, ok, n)
    ro = np.empty(n, np.int32)
    ro.setflags(write=False)
    with pytest.raises(TypeError, match=r"^status must be a .*writable .*int32 array"):
        obs.module.run(state, inputs, outputs, ro, n)


def test_run_matches_step_and_accepts_index_n(obs):
    rng = np.random.default_rng(0)
    n = 50
    inputs = rng.standard_normal((n, obs.n_input)) * 0.1
    outputs, status, final = obs.run(inputs)
    state = np.zeros(obs.n_state)
    out = np.empty(obs.n_output)
    for k in range(n):
        assert obs.step(state, inputs[k], out) == status[k]
        assert np.array_equal(out, outputs[k])
    assert np.array_equal(state, final)
    # n through __index__ (a numpy integer) is the same n
    state2 = np.zeros(obs.n_state)
    outputs2, status2 = np.empty_like(outputs), np.empty_like(status)
    obs.module.run(state2, inputs, outputs2, status2, np.int64(n))
    assert np.array_equal(outputs2, outputs) and np.array_equal(status2, status)
    # n = 0 on empty arrays is a no-op
    state3 = np.zeros(obs.n_state)
    obs.module.run(state3, np.zeros((0, obs.n_input)), np.zeros((0, obs.n_output)), np.zeros(0, np.int32), 0)
    assert not state3.any()


# ---------------------------------------------------------------------------------------------
# 3. run's n: bounded before it is multiplied (the red-team bug: n = 2**62 made n * N_INPUT * 8
#    wrap to 0, the empty buffers passed the size check and the C loop wrote through memory)

CHILD = textwrap.dedent("""
    import importlib.util, json, sys
    import numpy as np
    name, path, n = sys.argv[1], sys.argv[2], sys.argv[3]
    if path:
        spec = importlib.util.spec_from_file_location("_" + name, path)
        m = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(m)
    else:
        from python_bindings import load
        m = load(name).module
    n = eval(n)
    try:
        m.run(np.zeros(m.N_STATE), np.zeros(0), np.zeros(0), np.zeros(0, np.int32), n)
        res = {"error": None, "message": ""}
    except Exception as e:
        res = {"error": type(e).__name__, "message": str(e)}
    print(json.dumps(res))
""")


def run_child(name, n_expr, path=""):
    proc = subprocess.run([sys.executable, "-c", CHILD, name, str(path), n_expr], cwd=ROOT,
                          capture_output=True, text=True, timeout=HANG_GUARD)
    assert proc.returncode == 0, (f"run(..., n={n_expr}) killed the interpreter (rc {proc.returncode}):\n"
                                  f"{proc.stdout}{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def n_max(module):
    return PY_SSIZE_T_MAX // max(module.N_INPUT, module.N_OUTPUT, 1)


def check_n_result(module, n, res):
    assert res["error"] == "ValueError", res
    msg = res["message"]
    if n < 0:
        assert msg == f"n must be >= 0, got {n}", msg
    elif n > n_max(module):
        widest = max(module.N_INPUT, module.N_OUTPUT, 1)
        assert msg == (f"n must be at most {n_max(module)} (PY_SSIZE_T_MAX / {widest} values per row), "
                       f"got {n}"), msg
    else:   # in range: refused because the empty buffers do not hold n rows
        assert msg == f"inputs must hold n * {module.N_INPUT} = {n * module.N_INPUT} values for n = {n}, got 0", msg


HUGE_N = ["2**62", "-1", "2**63 - 1", "2**64", "-2**70", "2**61 + 1", "NMAX + 1", "NMAX"]


def eval_n(expr, module):
    return eval(expr, {"NMAX": n_max(module)})


@pytest.mark.parametrize("n_expr", HUGE_N)
def test_run_refuses_huge_or_negative_n_without_crashing(obs, n_expr):
    n = eval_n(n_expr, obs.module)
    res = run_child(obs.name, str(n))
    check_n_result(obs.module, n, res)


def test_run_n_mismatch_names_the_counts(obs):
    m = obs.module
    n = 4
    state, inputs = np.zeros(m.N_STATE), np.zeros((n, m.N_INPUT))
    outputs, status = np.empty((n, m.N_OUTPUT)), np.empty(n, np.int32)
    with pytest.raises(ValueError, match=rf"^inputs must hold n \* {m.N_INPUT} = {5 * m.N_INPUT} values "
                                         rf"for n = 5, got {n * m.N_INPUT}$"):
        m.run(state, inputs, outputs, status, 5)
    with pytest.raises(ValueError, match=rf"^outputs must hold n \* {m.N_OUTPUT} = {n * m.N_OUTPUT} values "
                                         rf"for n = {n}, got {(n - 1) * m.N_OUTPUT}$"):
        m.run(state, inputs, outputs[:-1], status, n)
    with pytest.raises(ValueError, match=rf"^status must hold n \* 1 = {n} values for n = {n}, got {n + 1}$"):
        m.run(state, inputs, outputs, np.empty(n + 1, np.int32), n)
    with pytest.raises(ValueError, match=rf"^state must hold {m.N_STATE} values, got {m.N_STATE + 1}$"):
        m.run(np.zeros(m.N_STATE + 1), inputs, outputs, status, n)
    with pytest.raises(TypeError, match=r"^n must be an integer, got float"):
        m.run(state, inputs, outputs, status, 4.0)
    with pytest.raises(TypeError, match="takes 5 arguments"):
        m.run(state, inputs, outputs, status)


def test_unoptimized_build_is_safe_too(tmp_path):
    """-O0 keeps every store the optimizer might drop, so undefined behaviour shows as a crash;
    the same hostile calls on an -O0 build of the glue in a scratch directory."""
    name = NAMES[0]
    path = build.build_extension(name, extra_flags=["-O0"], ext_dir=tmp_path / "ext", suffix="_O0")
    module = load(name).module   # same sizes
    for n_expr in ["2**62", "-1", "2**64", "NMAX + 1", "NMAX"]:
        n = eval_n(n_expr, module)
        check_n_result(module, n, run_child(name, str(n), path))
    probe = textwrap.dedent(f"""
        import importlib.util, sys
        import numpy as np
        spec = importlib.util.spec_from_file_location("_{name}", {str(path)!r})
        m = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(m)
        try:
            m.step(np.zeros(m.N_STATE), np.full(m.N_INPUT, 0.1).astype("{SWAPPED}f8"), np.empty(m.N_OUTPUT))
            print("accepted")
        except TypeError as e:
            print(e)
    """)
    proc = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=HANG_GUARD)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("inputs must be a native-endian float64 array"), proc.stdout
