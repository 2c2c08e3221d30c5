"""Scene files: validation messages, overrides, and every paper scene through the CLI."""

from __future__ import annotations

import json
import math
import textwrap

import numpy as np
import pytest
from support import MODEL

import flexctrl as fc
from flexctrl.cli import main
from flexctrl.errors import SpecError
from flexctrl.scenes import run_scene
from flexctrl.spec.arm_scene import INTEGRATOR_NAMES, InputSpec
from flexctrl.spec.scene import SCENE_READERS as SCENE_KINDS
from flexctrl.spec.scene import load_scene

PAPER_SCENES = ("free_vibration", "free_vibration_damped", "bangbang", "bangbang_damped")

BASE = """
kind = "arm"
model = "{model}"
dt = 1e-3
duration = 0.05
"""


def _scene(tmp_path, body: str = "", model=None, name="scene.toml"):

    model = model or str(MODEL)
    path = tmp_path / name
    path.write_text(BASE.format(model=model) + textwrap.dedent(body))
    return path


def test_paper_scenes_hold_the_papers_settings(root):
    fv = load_scene(root / "studies/scenes/free_vibration.toml")
    assert (
        fv.payload == 2.0
        and fv.dt == 1e-3
        and fv.integrator == "rk4"
        and str(fv.fidelity) == "amm:2"
    )
    assert fv.qf0 == {"qf31": 0.1, "qf32": 0.002} and fv.q0 == (0.0, 0.0, 0.0) and fv.zeta == 0.0
    assert fv.gravity == (0.0, -9.81) and fv.input.kind == "none"
    damped = load_scene(root / "studies/scenes/free_vibration_damped.toml")
    assert damped.zeta == 0.005 and damped.qf0 == fv.qf0 and damped.friction == (0.0,)
    bb = load_scene(root / "studies/scenes/bangbang.toml")
    assert bb.gravity == (0.0, 0.0) and bb.qf0 == {} and bb.zeta == 0.0
    assert (
        bb.input.kind,
        bb.input.joint,
        bb.input.amplitude,
        bb.input.t_accel,
        bb.input.t_decel,
    ) == ("bangbang", 3, 50.0, 0.1, 0.1)
    assert load_scene(root / "studies/scenes/bangbang_damped.toml").zeta == 0.005


def test_bangbang_samples_are_symmetric():
    spec = InputSpec("bangbang", joint=2, amplitude=50.0, t_accel=0.1, t_decel=0.1)
    u = spec.samples(300, 1e-3, 3)
    assert (
        np.all(u[:100, 1] == 50.0) and np.all(u[100:200, 1] == -50.0) and np.all(u[200:, 1] == 0.0)
    )
    assert np.all(u[:, [0, 2]] == 0.0) and u[:, 1].sum() == 0.0


@pytest.mark.parametrize("name", PAPER_SCENES)
def test_paper_scene_runs_through_the_cli(name, root, tmp_path, capsys):
    out = tmp_path / name
    status = main(
        [
            "simulate",
            str(root / f"studies/scenes/{name}.toml"),
            "--out",
            str(out),
            "--set",
            "duration=0.2",
        ]
    )
    assert status == 0
    for fname in (
        "trajectory.csv",
        "summary.json",
        "joints.png",
        "deflections.png",
        "tip.png",
        "energies.png",
    ):
        assert (out / fname).is_file(), fname
    header = (out / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert header[:16] == [
        "t",
        "q1",
        "q2",
        "q3",
        "qf11",
        "qf12",
        "qf21",
        "qf22",
        "qf31",
        "qf32",
        "tip_x",
        "tip_y",
        "E_kin",
        "E_el",
        "E_grav",
        "E_total",
    ]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scene"]["name"] == name and summary["n_steps"] == 200
    assert summary["realtime_factor"] == pytest.approx(
        0.2 / summary["wall_time_s"], rel=1e-12
    )  # simulated / wall
    assert set(summary["dominant_frequencies_hz"]) == {"w1", "w2", "w3"}
    assert "drift_rel" in summary["energy"]
    assert name in capsys.readouterr().out


def test_cli_fidelity_override_and_json(root, tmp_path, capsys):
    status = main(
        [
            "simulate",
            str(root / "studies/scenes/bangbang.toml"),
            "--out",
            str(tmp_path),
            "--fidelity",
            "amm:1",
            "--set",
            "duration=0.02",
            "--no-plots",
            "--json",
        ]
    )
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["fidelity"] == "amm:1" and summary["model_info"]["coordinates"][3:] == [
        "qf11",
        "qf21",
        "qf31",
    ]
    assert not list(tmp_path.glob("*.png"))


def test_cli_bad_input_is_one_line_and_exit_2(root, tmp_path, capsys):
    status = main(
        [
            "simulate",
            str(root / "studies/scenes/bangbang.toml"),
            "--out",
            str(tmp_path),
            "--set",
            "dt=-1e-3",
        ]
    )
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "key 'dt'" in err and "> 0" in err


def test_misspelt_key_gets_a_suggestion(tmp_path):
    with pytest.raises(SpecError, match=r"key 'duratoin'.*did you mean 'duration'"):
        load_scene(_scene(tmp_path, "duratoin = 2.0\n"))
    body = """
    [input]
    kind = "bangbang"
    joint = 3
    amplitud = 50.0
    t_accel = 0.1
    """
    with pytest.raises(SpecError, match=r"input.amplitud'.*did you mean 'amplitude'"):
        load_scene(_scene(tmp_path, body))


@pytest.mark.parametrize(
    "override, pattern",
    [
        ("dt=-1e-3", r"key 'dt'.*-0.001.*allowed: a finite number > 0"),
        (
            "integrator='rk5'",
            r"key 'integrator'.*'rk5'.*allowed: 'rk4', 'cvodes', 'idas', 'scipy'.*did you mean "
            r"'rk4'",
        ),
        ("modes='moving'", r"key 'modes'.*allowed: 'frozen', 'scheduled'"),
        ("fidelity='amm:9'", r"key 'fidelity'.*'amm:9'"),
        ("fidelity='auto'", r"key 'tolerance'.*fidelity = 'auto' needs it"),
        ("dt=1.0", r"key 'dt'.*longer than the duration"),
        ("solver.rtol=1e-6", r"key 'solver.rtol'.*does not apply to integrator 'rk4'"),
        ("initial.qf.q31=0.1", r"key 'initial.qf.q31'.*allowed: qf<link><mode>"),
        ("payload=-2", r"key 'payload'.*>= 0"),
        ("kind='beam'", r"key 'kind'.*'beam'.*allowed: 'arm'"),
        ("gravity=[0, 1, 2]", r"key 'gravity'.*exactly 2"),
    ],
)
def test_invalid_values_are_named(override, pattern, tmp_path):
    with pytest.raises(SpecError, match=pattern):
        load_scene(_scene(tmp_path), [override])


def test_missing_model_lists_where_it_looked(tmp_path):
    with pytest.raises(SpecError, match=r"key 'model'.*not found \(looked at"):
        load_scene(_scene(tmp_path, model="nowhere/arm.toml"))


def test_model_coordinates_are_checked_when_built(tmp_path):
    scene = load_scene(_scene(tmp_path), ["initial.qf.qf41=0.1", "fidelity='amm:1'"])
    with pytest.raises(SpecError, match=r"key 'initial.qf.qf41'.*allowed: qf11, qf21, qf31"):
        run_scene(scene)
    scene = load_scene(
        _scene(tmp_path),
        ["input.kind='bangbang'", "input.joint=4", "input.amplitude=1.0", "input.t_accel=0.01"],
    )
    with pytest.raises(SpecError, match=r"key 'input.joint'.*allowed: 1 to 3"):
        run_scene(scene)


def test_overrides_reach_the_model(tmp_path):
    scene = load_scene(
        _scene(tmp_path),
        [
            "payload=0.5",
            "gravity=[0.0, 0.0]",
            "damping.zeta=0.02",
            "initial.q=[10.0, 0.0, 0.0]",
            "fidelity='amm:1'",
            "duration=0.01",
        ],
    )
    assert scene.q0[0] == pytest.approx(math.radians(10.0))
    result = run_scene(scene)
    traj = result.trajectory
    assert traj.q[0, 0] == pytest.approx(math.radians(10.0))
    assert np.allclose(traj.energies["E_grav"], 0.0)
    assert result.model.spec.payload.mass == 0.5  # the model file's payload is 2 kg


def test_scene_kinds_and_integrators_are_in_one_place():
    from flexctrl.sim import INTEGRATORS

    assert set(INTEGRATOR_NAMES) == set(INTEGRATORS)
    assert "arm" in SCENE_KINDS


@pytest.mark.parametrize("integrator", ["cvodes", "euler"])
def test_a_closed_loop_scene_refuses_an_integrator_it_would_not_use(integrator):
    """The closed loop steps its plant with the compiled RK4; another name is refused, not
    silently replaced."""
    with pytest.raises(SpecError) as info:
        load_scene("studies/scenes/move_joint1_30deg.toml", [f"integrator={integrator}"])
    message = str(info.value)
    assert "move_joint1_30deg.toml" in message and "key 'integrator'" in message
    assert f"value '{integrator}' is not allowed in a closed-loop scene" in message
    assert "allowed: 'rk4'" in message
    assert load_scene("studies/scenes/move_joint1_30deg.toml", ["integrator=rk4"]).plant.dt > 0


@pytest.mark.parametrize("fidelity", ["rigid", "amm:2", "fem:2"])
def test_a_prismatic_joint_in_an_arm_file_is_refused_not_built_revolute(fidelity):
    with pytest.raises(SpecError) as info:
        fc.load_model("subedi3link", fidelity=fidelity, overrides={"joints[2].type": "prismatic"})
    message = str(info.value)
    assert "subedi3link.toml" in message and "key 'joints[2].type'" in message
    assert "value 'prismatic' is not supported" in message and "allowed: 'revolute'" in message
