"""``gearsym export-fmu``: FMI 2.0 Model Exchange source FMUs checked by an independent importer.

FMPy (not gearsym) validates each FMU against the FMI schema and its own rules, compiles its
sources with its CMake project and the FMI headers it ships, adding the project's strict warning
flags (a warning fails the build), and simulates it. The expected trajectories come from other
paths: the emitted CasADi module's own integrator and the reference simulation of the 2-3 shift
(:mod:`gearsym.validation.sim.simulate`), and for the Co-Simulation part the emitted ``rk4_step``
compiled by gearsym's own path and driven from Python; the expected ModelStructure from SymPy's
``Matrix.jacobian`` of the model, not from the codegen's forward-mode differentiation.
"""

from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import fmpy  # a pinned dev dependency: missing, the tests fail rather than skip
import numpy as np
import pytest
import sympy as sp
from fmpy.build import build_platform_binary
from fmpy.validation import validate_fmu
from gearsym.symbolic.codegen import emit_casadi
from gearsym.symbolic.export.fmu import fmu_archive, fmu_files
from gearsym.symbolic.export.generate import PARAMETER_BOUNDS, gearbox_models
from gearsym.symbolic.io.output_dir import foreign_file
from gearsym.symbolic.loader import load_description
from gearsym.validation.checks.c_binding import load_casadi_module
from gearsym.validation.checks.c_check import STRICT_FLAGS, write_files
from gearsym.validation.sim.simulate import simulate

from gearsym.cli import main

MODELS = ("full", "shift_2_3", "shift_2_3_mu")


@pytest.fixture(scope="module")
def description():
    return load_description()


@pytest.fixture(scope="module")
def emitted(description):
    return {m.model.name: m for m in gearbox_models(description)}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory, description, emitted):
    """Each FMU of MODELS written by the command line, as ``{name: path}``."""
    folder = tmp_path_factory.mktemp("fmu")
    paths = {}
    for name in MODELS:
        paths[name] = folder / f"{name}.fmu"
        assert main(["export-fmu", "--model", name, "--out", str(paths[name])]) == 0
    return paths


def _compile(fmu: Path, folder: Path) -> Path:
    """Unpack ``fmu`` and build its binary with FMPy's CMake project and the strict flags."""
    unpacked = folder / fmu.stem
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(unpacked)
    build = folder / f"{fmu.stem}-build"
    build.mkdir()
    # FMPy runs `cmake` from PATH; the cmake wheel it depends on installs it beside python.
    path = os.environ.get("PATH", "")
    os.environ["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{path}"
    try:
        build_platform_binary(
            unpacked.resolve(),
            build.resolve(),
            cmake_options={"CMAKE_C_FLAGS:STRING": " ".join(STRICT_FLAGS)},
        )
    finally:
        os.environ["PATH"] = path
    return unpacked


@pytest.fixture(scope="module")
def shift_fmu(tmp_path_factory, fmus):
    """The 2-3 shift FMU, unpacked and compiled."""
    return _compile(fmus["shift_2_3"], tmp_path_factory.mktemp("build"))


@pytest.mark.parametrize("name", MODELS)
def test_fmpy_validates_the_fmu(fmus, name):
    assert validate_fmu(str(fmus[name])) == []


@pytest.mark.parametrize("name", MODELS)
def test_the_sources_compile_with_strict_warnings(tmp_path, fmus, name):
    unpacked = _compile(fmus[name], tmp_path)
    binaries = list((unpacked / "binaries").rglob(f"gearsym_{name}.*"))
    assert binaries, "no platform binary was built"
    with zipfile.ZipFile(fmus[name]) as archive:
        listed = sorted(archive.namelist())
    # a source FMU: no binary, no FMI header (the importer brings both)
    assert listed == [
        "modelDescription.xml",
        "sources/fmi2_gearsym.c",
        f"sources/gearsym_{name}.c",
        f"sources/gearsym_{name}.h",
    ]


def _description(path: Path) -> ET.Element:
    with zipfile.ZipFile(path) as archive:
        return ET.fromstring(archive.read("modelDescription.xml"))


def test_model_description_has_units_ranges_and_causalities(fmus, emitted):
    root = _description(fmus["shift_2_3_mu"])
    model = emitted["shift_2_3_mu"].model
    variables = {v.get("name"): v for v in root.iter("ScalarVariable")}
    # parameters: tunable, start = the model default, min/max = PARAMETER_BOUNDS (or μ's range)
    for p in model.parameters:
        v = variables[p.name]
        real = v.find("Real")
        assert (v.get("causality"), v.get("variability"), v.get("initial")) == (
            "parameter",
            "tunable",
            "exact",
        )
        assert float(real.get("start")) == p.default
        lo, hi = (0.0, 1.0) if p.name.startswith("mu_") else PARAMETER_BOUNDS[p.name]
        assert (float(real.get("min")), float(real.get("max"))) == (lo, hi)
    assert variables["m_veh"].find("Real").get("unit") == "kg"
    # states continuous with a start, each with its derivative pointing back to it (1-based)
    index = {v.get("name"): k + 1 for k, v in enumerate(root.iter("ScalarVariable"))}
    for s in model.states:
        der = variables[f"der({s.name})"].find("Real")
        assert int(der.get("derivative")) == index[s.name]
        assert variables[s.name].get("variability") == "continuous"
    assert {variables[u.name].get("causality") for u in model.inputs} == {"input"}
    assert {variables[y.name].get("causality") for y in model.outputs} == {"output"}
    # units in SI base units, written out by hand
    units = {
        u.get("name"): {k: int(x) for k, x in u.find("BaseUnit").attrib.items()}
        for u in root.iter("Unit")
    }
    assert units["N*m*s/rad"] == {"kg": 1, "m": 2, "s": -1, "rad": -1}
    assert units["kg*m^2"] == {"kg": 1, "m": 2}
    assert units["rad/s^2"] == {"s": -2, "rad": 1}
    assert root.get("numberOfEventIndicators") == "0"


@pytest.mark.parametrize("name", MODELS)
def test_model_structure_is_the_jacobian_sparsity(fmus, emitted, name):
    """Dependencies against SymPy's own Jacobian of f and h (not the codegen's)."""
    model = emitted[name].model
    root = _description(fmus[name])
    index = {v.get("name"): k + 1 for k, v in enumerate(root.iter("ScalarVariable"))}
    x = [index[v.name] for v in model.states]
    u = [index[v.name] for v in model.inputs]
    p = [index[v.name] for v in model.parameters]

    def expected(expr: sp.Expr, with_parameters: bool) -> set[int]:
        groups = [(model.states, x), (model.inputs, u)]
        if with_parameters:
            groups.append((model.parameters, p))
        return {
            i
            for variables, indices in groups
            for v, i in zip(variables, indices, strict=True)
            if sp.simplify(sp.diff(expr, v.symbol)) != 0
        }

    def listed(section: str) -> dict[int, set[int]]:
        return {
            int(u.get("index")): {int(d) for d in u.get("dependencies").split()}
            for u in root.find("ModelStructure").find(section)
        }

    derivatives = {index[f"der({v.name})"]: f for v, f in zip(model.states, model.rhs, strict=True)}
    h = model.output_expressions
    outputs = {index[v.name]: e for v, e in zip(model.outputs, h, strict=True)}
    assert listed("Derivatives") == {i: expected(f, False) for i, f in derivatives.items()}
    assert listed("Outputs") == {i: expected(h, False) for i, h in outputs.items()}
    initial = {i: expected(e, True) for i, e in {**derivatives, **outputs}.items()}
    assert listed("InitialUnknowns") == initial


@pytest.fixture(scope="module")
def shift_run(tmp_path_factory, description, emitted):
    """The reference simulation's 2-3 shift (torque and speed phase): sample times, the shift
    model's inputs and states as recorded, and the emitted CasADi module of the model."""
    result = simulate(description, check_models=False)
    torque, speed = result.phases[1], result.phases[2]
    inside = (result.t >= torque.t_start) & (result.t <= speed.t_end)
    m = emitted["shift_2_3"]
    files = emit_casadi(m.model, m.config)
    (name,) = files
    folder = tmp_path_factory.mktemp("casadi")
    write_files(files, folder)
    module = load_casadi_module(folder / name)
    # the record's times less the phase's start, on the exact grid of the sample time (the
    # bare difference carries rounding, and FMPy counts its output steps from it)
    step = round(float(result.t[1] - result.t[0]), 9)
    times = np.round((result.t[inside] - result.t[inside][0]) / step) * step
    inputs = np.column_stack([result.signals[v.name][inside] for v in m.model.inputs])
    states = np.column_stack([result.signals[v.name][inside] for v in m.model.states])
    # a scenario breakpoint within rounding of a sample is recorded beside it: keep one
    once = np.concatenate([[True], np.diff(times) > step / 2])
    return times[once], inputs[once], states[once], module, m.model


def _simulate_fmu(unpacked, times, inputs, x0, model, start_values=None):
    """FMPy's Model Exchange run with the inputs held over each sample (a staircase: FMPy then
    stops at every sample, as at an input event, and restarts CVODE there)."""
    n = len(times) - 1
    signal = np.zeros(2 * n, dtype=[("time", float)] + [(v.name, float) for v in model.inputs])
    signal["time"][0::2], signal["time"][1::2] = times[:n], times[1:]
    for k, v in enumerate(model.inputs):
        signal[v.name][0::2] = signal[v.name][1::2] = inputs[:n, k]
    values = {v.name: float(x0[k]) for k, v in enumerate(model.states)}
    values.update(start_values or {})
    result = fmpy.simulate_fmu(
        str(unpacked),
        fmi_type="ModelExchange",
        start_time=0.0,
        stop_time=float(times[-1]),
        output_interval=float(times[1] - times[0]),
        input=signal,
        relative_tolerance=1e-10,
        start_values=values,
        output=[v.name for v in model.states],
    )
    # an input event records its instant twice (before and after); the state is continuous
    _, first = np.unique(result["time"], return_index=True)
    result = result[first]
    assert np.allclose(result["time"], times, rtol=0, atol=1e-9)
    return np.column_stack([result[v.name] for v in model.states])


def _held_casadi(module, times, inputs, x0, parameters):
    """The emitted CasADi module's own simulator with the inputs held over each sample."""
    n = len(times) - 1
    simulator = module.held_input_simulator(float(times[1] - times[0]), n)
    xf = simulator(x0=x0, p=parameters, u=inputs[:n].T)["xf"]
    return np.vstack([x0, np.array(xf).T])


#: Relative to each state's largest magnitude over the shift. Both sides integrate the same
#: ODE with the same held inputs by CVODE(S) restarted at every sample at rtol 1e-10 (FMPy:
#: atol = rtol * nominal; the CasADi module: atol 1e-10); over the 618 samples of the shift
#: the difference measured 6e-7 on the twist phi (3e-8 rad of 0.06 rad) and 6e-8 on the speeds.
FMU_TOLERANCE = 2e-6
#: The shift model against the full reference (elastic elements, bristle friction): the bound
#: of the reduced-model check (tests/test_simulate.py).
REFERENCE_TOLERANCE = 2e-2


def test_simulated_fmu_follows_the_emitted_model_and_the_reference(shift_fmu, shift_run):
    times, inputs, states, module, model = shift_run
    fmu = _simulate_fmu(shift_fmu, times, inputs, states[0], model)
    casadi = _held_casadi(module, times, inputs, states[0], module.parameter_defaults())
    scale = np.max(np.abs(casadi), axis=0)
    assert np.all(np.max(np.abs(fmu - casadi), axis=0) <= FMU_TOLERANCE * scale)
    assert np.all(np.max(np.abs(fmu - states), axis=0) <= REFERENCE_TOLERANCE * scale)


def test_a_parameter_set_through_the_fmu_acts_as_in_the_model(shift_fmu, shift_run):
    times, inputs, states, module, model = shift_run
    names = [v.name for v in model.parameters]
    heavy = np.array(module.parameter_defaults()).ravel()
    heavy[names.index("m_veh")] *= 2
    m_veh = float(heavy[names.index("m_veh")])
    fmu = _simulate_fmu(shift_fmu, times, inputs, states[0], model, {"m_veh": m_veh})
    casadi = _held_casadi(module, times, inputs, states[0], heavy)
    default = _held_casadi(module, times, inputs, states[0], module.parameter_defaults())
    scale = np.max(np.abs(casadi), axis=0)
    assert np.all(np.max(np.abs(fmu - casadi), axis=0) <= FMU_TOLERANCE * scale)
    # and the heavier vehicle is visibly another trajectory (wheel speed, last column)
    assert np.max(np.abs(casadi - default)[:, -1]) > 1e3 * FMU_TOLERANCE * scale[-1]


def test_a_parameter_outside_its_range_is_refused(shift_fmu, shift_run):
    times, inputs, states, _, model = shift_run
    lo, _ = PARAMETER_BOUNDS["m_veh"]
    with pytest.raises(Exception, match="fmi2ExitInitializationMode"):
        _simulate_fmu(shift_fmu, times[:3], inputs, states[0], model, {"m_veh": lo / 2})


def test_export_is_byte_identical_and_replaces_its_own_file(tmp_path, description, emitted):
    a, b = tmp_path / "a.fmu", tmp_path / "b" / "b.fmu"
    for path in (a, b, a):  # the third run replaces a signed FMU of its own
        assert main(["export-fmu", "--model", "shift_2_3", "--out", str(path)]) == 0
    assert a.read_bytes() == b.read_bytes()
    assert foreign_file(a) is None
    # the same bytes as the library's archive of the same files, plus the signature comment
    unsigned = fmu_archive(fmu_files(emitted["shift_2_3"], description.name))
    assert a.read_bytes()[: len(unsigned) - 2] == unsigned[:-2]
    # an edited FMU is no longer gearsym's
    data = bytearray(a.read_bytes())
    data[100] ^= 0xFF  # inside the first entry's compressed data
    a.write_bytes(bytes(data))
    assert foreign_file(a) is not None


def test_the_guid_follows_the_content(description, emitted):
    guids = {
        _guid(fmu_files(emitted[name], description.name)) for name in ("shift_2_3", "shift_3_4")
    }
    assert len(guids) == 2


def _guid(files: dict[str, bytes]) -> str:
    root = ET.fromstring(files["modelDescription.xml"])
    guid = root.get("guid")
    assert f'#define FMU_GUID "{guid}"'.encode() in files["sources/fmi2_gearsym.c"]
    return guid


@pytest.mark.parametrize(
    "args, key",
    [
        (["--model", "shift_9_9", "--out", "{d}/x/m.fmu"], "--model"),
        (["--model", "full", "--out", "{d}/x/m.zip"], "--out"),
        (["--model", "full", "--out", "{d}/user.fmu"], "--out"),
        (["--model", "full", "--out", "{d}"], "--out"),
    ],
)
def test_bad_model_or_out_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, args, key):
    user = tmp_path / "user.fmu"
    user.write_bytes(b"someone else's FMU")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    status = main(["export-fmu", *[a.format(d=tmp_path) for a in args]])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if not line.startswith("  … ")]
    assert status == 2
    assert len(lines) == 1 and lines[0].startswith("gearsym: ") and key in lines[0], err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before
    assert user.read_bytes() == b"someone else's FMU"


# ---------------------------------------------------------------- Co-Simulation (RK4 inside)


def _simulate_cs(unpacked, times, inputs, x0, model, start_values=None):
    """FMPy's Co-Simulation run, one communication step per sample: the inputs are the recorded
    samples (FMPy sets u(t_k) at t_k; the FMU holds it over the step). Returns the states and
    the inputs the FMU held over each step (recorded at the step's end)."""
    signal = np.zeros(len(times), dtype=[("time", float)] + [(v.name, float) for v in model.inputs])
    signal["time"] = times
    for k, v in enumerate(model.inputs):
        signal[v.name] = inputs[:, k]
    values = {v.name: float(x0[k]) for k, v in enumerate(model.states)}
    values.update(start_values or {})
    result = fmpy.simulate_fmu(
        str(unpacked),
        fmi_type="CoSimulation",
        start_time=0.0,
        stop_time=float(times[-1]),
        output_interval=float(times[1] - times[0]),
        input=signal,
        start_values=values,
        output=[v.name for v in model.states] + [v.name for v in model.inputs],
    )
    assert np.allclose(result["time"], times, rtol=0, atol=1e-9)
    states = np.column_stack([result[v.name] for v in model.states])
    held = np.column_stack([result[v.name] for v in model.inputs])
    return states, held


@pytest.fixture(scope="module")
def rk4_library(tmp_path_factory, emitted):
    """The emitted C of the 2-3 shift model, compiled by gearsym's own path (not the FMU's)."""
    from gearsym.symbolic.codegen import emit_c
    from gearsym.validation.checks.c_binding import load_functions
    from gearsym.validation.checks.c_check import compile_shared

    m = emitted["shift_2_3"]
    folder = tmp_path_factory.mktemp("rk4")
    return load_functions(
        compile_shared(emit_c(m.model, m.config), folder), m.model, False, m.config
    )


def _direct_rk4(c, times, held, x0, p, fixed_step):
    """The emitted rk4_step driven from Python: per communication interval h, the whole steps of
    ``fixed_step`` that fit and one step of the rest (the brief's subdivision, written here
    independently of the wrapper, with integer arithmetic on the sample grid)."""
    x = np.array(x0, dtype=float)
    out = [x.copy()]
    for k in range(len(times) - 1):
        h = float(times[k + 1] - times[k])
        ratio = h / fixed_step
        whole = round(ratio) if abs(ratio - round(ratio)) < 1e-9 else int(ratio)
        x = c.step("rk4_step", x, held[k + 1], p, fixed_step, whole)
        rest = h - whole * fixed_step
        if rest > 1e-9 * fixed_step:
            x = c.step("rk4_step", x, held[k + 1], p, rest)
        out.append(x.copy())
    return np.vstack(out)


#: CS (RK4 at 1e-4 s, five steps per 5e-4 s sample) against ME (CVODE at rtol 1e-10), relative
#: to each state's largest magnitude: the ME test's tolerance. Measured: 2.4e-7 on the twist phi,
#: 2e-8 on the speeds (the RK4 error at 1e-4 s plus CVODE's).
CS_ME_TOLERANCE = FMU_TOLERANCE


@pytest.fixture(scope="module")
def cs_run(shift_fmu, shift_run):
    times, inputs, states, _, model = shift_run
    return _simulate_cs(shift_fmu, times, inputs, states[0], model)


def test_cosimulation_is_the_emitted_rk4(cs_run, shift_run, rk4_library):
    times, inputs, states, module, model = shift_run
    cs, held = cs_run
    # the held inputs are the samples FMPy set (interpolation exactly on the sample times)
    assert np.allclose(held[1:], inputs[:-1], rtol=1e-12, atol=1e-12)
    direct = _direct_rk4(rk4_library, times, held, states[0], rk4_library.params_default(), 1e-4)
    scale = np.max(np.abs(direct), axis=0)
    assert np.all(np.max(np.abs(cs - direct), axis=0) <= 1e-12 * scale)


def test_cosimulation_follows_model_exchange_and_the_reference(cs_run, shift_fmu, shift_run):
    times, inputs, states, module, model = shift_run
    cs, _ = cs_run
    me = _simulate_fmu(shift_fmu, times, inputs, states[0], model)
    scale = np.max(np.abs(me), axis=0)
    assert np.all(np.max(np.abs(cs - me), axis=0) <= CS_ME_TOLERANCE * scale)
    assert np.all(np.max(np.abs(cs - states), axis=0) <= REFERENCE_TOLERANCE * scale)


def test_a_fixed_step_that_does_not_divide_the_interval(shift_fmu, shift_run, rk4_library):
    """fixed_step 3e-4 s in 5e-4 s intervals: one whole step and a last one of 2e-4 s."""
    times, inputs, states, module, model = shift_run
    times, inputs = times[:40], inputs[:40]
    assert np.isclose(times[1] - times[0], 5e-4, rtol=1e-12)
    cs, held = _simulate_cs(shift_fmu, times, inputs, states[0], model, {"fixed_step": 3e-4})
    p = rk4_library.params_default()
    direct = _direct_rk4(rk4_library, times, held, states[0], p, 3e-4)
    scale = np.max(np.abs(direct), axis=0)
    assert np.all(np.max(np.abs(cs - direct), axis=0) <= 1e-12 * scale)
    # and not the same as 1e-4 steps in the last digits: the setting reached the FMU
    fine = _direct_rk4(rk4_library, times, held, states[0], p, 1e-4)
    assert np.max(np.abs(fine - direct)) > 0


@pytest.mark.parametrize("kind", ["me", "cs"])
def test_a_single_kind_validates_lists_its_interface_and_compiles(tmp_path, kind):
    path = tmp_path / f"{kind}.fmu"
    assert main(["export-fmu", "--model", "shift_2_3", "--kind", kind, "--out", str(path)]) == 0
    assert validate_fmu(str(path)) == []
    root = _description(path)
    assert (root.find("ModelExchange") is not None) == (kind == "me")
    assert (root.find("CoSimulation") is not None) == (kind == "cs")
    names = {v.get("name") for v in root.iter("ScalarVariable")}
    assert ("fixed_step" in names) == (kind == "cs")
    # and the sources of the one interface build with the strict flags
    unpacked = _compile(path, tmp_path)
    assert list((unpacked / "binaries").rglob("gearsym_shift_2_3.*"))


@pytest.mark.parametrize(
    "args, key",
    [(["--kind", "fmi3"], "--kind"), (["--fixed-step", "0"], "--fixed-step")],
)
def test_bad_kind_or_fixed_step_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, args, key):
    with pytest.raises(SystemExit) as stop:
        main(["export-fmu", "--model", "full", *args, "--out", str(tmp_path / "x" / "m.fmu")])
    lines = capsys.readouterr().err.splitlines()
    assert stop.value.code == 2
    assert len(lines) == 1 and lines[0].startswith("gearsym: ") and key in lines[0], lines
    assert list(tmp_path.iterdir()) == []


def test_a_fixed_step_outside_its_range_is_refused(shift_fmu, shift_run):
    times, inputs, states, _, model = shift_run
    with pytest.raises(Exception, match="fmi2ExitInitializationMode"):
        _simulate_cs(shift_fmu, times[:3], inputs[:3], states[0], model, {"fixed_step": 2.0})
