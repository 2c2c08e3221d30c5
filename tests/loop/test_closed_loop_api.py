"""The public Python API (``import flexctrl as fc``): names, inputs, agreement with scene files."""

from __future__ import annotations

import inspect
import math
import subprocess
import sys

import numpy as np
import pytest
from support import DATA

import flexctrl as fc
from flexctrl.errors import SpecError

MODEL = str(DATA / "models" / "subedi3link.toml")
SCENE = str(DATA / "studies" / "scenes" / "move_joint1_30deg.toml")
DAMPED = {f"links[{i}].damping_ratio": 0.005 for i in (1, 2, 3)}


def test_every_public_name_resolves_and_has_a_numpydoc_docstring():
    assert set(fc.__all__) >= {
        "load_model",
        "equilibrium",
        "linearize",
        "load_controller",
        "design",
        "Move",
        "closed_loop",
        "compare",
        "run_study",
        "load_scene",
        "run_scene",
    }
    for name in fc.__all__:
        if name == "__version__":
            continue
        value = getattr(fc, name)
        doc = inspect.getdoc(value) or ""
        assert doc.strip(), f"flexctrl.{name} has no docstring"
        if inspect.isfunction(value) and inspect.signature(value).parameters:
            assert "Parameters\n----------" in doc, (
                f"flexctrl.{name} has no numpydoc Parameters section"
            )


def test_unknown_public_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'closedloop'"):
        fc.closedloop  # noqa: B018


def test_import_is_lazy():
    code = (
        "import flexctrl, sys; "
        "print(sorted(m for m in ('casadi', 'control', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.fixture(scope="module")
def model():
    return fc.load_model(MODEL, payload=2.0, fidelity="amm:2", gravity=[0.0, 0.0], overrides=DAMPED)


@pytest.fixture(scope="module")
def op(model):
    return fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))


def test_load_model_keys_and_overrides_reach_the_description(model):
    assert model.spec.payload.mass == 2.0 and tuple(model.spec.gravity) == (0.0, 0.0)
    assert [link.damping_ratios for link in model.spec.links] == [(0.005,)] * 3
    as_strings = fc.load_model(MODEL, fidelity="rigid", overrides=["links[1].damping_ratio=0.005"])
    assert as_strings.spec.links[0].damping_ratios == (0.005,) and as_strings.spec.links[
        1
    ].damping_ratios == (0.0,)


@pytest.mark.parametrize(
    "kwargs, key, fragment",
    [
        ({"payload": "0.5"}, "payload.mass", "'0.5'"),
        ({"payload": -1.0}, "payload.mass", "-1.0"),
        ({"payload": math.nan}, "payload.mass", "nan"),
        ({"gravity": [0.0]}, "gravity", "2"),
        ({"gravty": [0.0, 0.0]}, "gravty", "did you mean 'gravity'"),
        ({"overrides": {"links[1].EI": "stiff"}}, "links[1].EI", "'stiff'"),
        ({"overrides": {"links[9].EI": 1.0}}, "links[9].EI", "index 9"),
    ],
)
def test_load_model_bad_arguments_are_one_line_spec_errors(kwargs, key, fragment):
    with pytest.raises(SpecError) as info:
        fc.load_model(MODEL, fidelity="rigid", **kwargs)
    message = str(info.value)
    assert "\n" not in message and MODEL in message and key in message and fragment in message, (
        message
    )


def test_linearize_names_states_inputs_and_outputs(model, op):
    sys_ = fc.linearize(model, op)
    assert sys_.nstates == model.n_x and sys_.input_labels == ["tau1", "tau2", "tau3"]
    assert sys_.output_labels == ["q1", "q2", "q3"]
    assert sys_.state_labels[:4] == ["q1", "q2", "q3", "qf11"]


def test_closed_loop_equals_the_scene_file_at_the_same_step(model, op):
    """The Python API and the scene runner build the loop apart (reference, x0, window, sensors)."""
    lqr = fc.design(model, op, fc.load_controller(DATA / "controllers" / "lqr.toml"))
    move = fc.Move(start=np.radians([0, 0, 0]), target=np.radians([30, 0, 0]), time=1.5)
    res = fc.closed_loop(
        model, lqr, move, duration=8.0, dt=5e-4, metrics=fc.MetricSettings(settle_allowance=1.0)
    )
    scene = fc.run_scene(fc.load_scene(SCENE), controller=str(DATA / "controllers" / "lqr.toml"))
    np.testing.assert_array_equal(res.trajectory.tip, scene.trajectory.tip)
    for key in (
        "tip_residual_rms",
        "settling_time",
        "peak_deflection",
        "stable",
        "closed_loop_radius",
    ):
        assert res.metrics[key] == scene.metrics[key], key
    # a designed controller runs the scene file too, with the same result
    again = fc.run_scene(fc.load_scene(SCENE), controller=lqr)
    np.testing.assert_array_equal(again.trajectory.tip, scene.trajectory.tip)
    assert (
        again.summary["controller"]["file"] is None and again.summary["controller"]["kind"] == "lqr"
    )


def test_closed_loop_result_plots_saves_and_tabulates(model, op, tmp_path):
    pd = fc.design(model, op, fc.load_controller(DATA / "controllers" / "pd.toml"))
    move = fc.Move(start=np.radians([0, 0, 0]), target=np.radians([30, 0, 0]), time=1.5)
    res = fc.closed_loop(model, pd, move, duration=4.0)
    fig = res.plot()
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == [
        "tip error (mm)",
        "link tip deflection (mm)",
        "torque (N m)",
        "joint angle (deg)",
    ]
    assert fig.axes[-1].get_xlabel() == "time (s)"
    files = {p.name for p in res.save(tmp_path)}
    assert {"trajectory.csv", "summary.json", "tip.png"} <= files
    frame = res.to_pandas()
    assert frame.shape[0] == res.trajectory.time.size and "tip_x" in frame.columns
    both = fc.compare({"PD": res, "PD again": res})
    assert len(both.axes[0].lines) == 2


def test_closed_loop_refuses_bad_input(model, op):
    pd = fc.design(model, op, fc.load_controller(DATA / "controllers" / "pd.toml"))
    move = fc.Move(start=[0.0, 0.0, 0.0], target=[0.5, 0.0, 0.0], time=1.0)
    with pytest.raises(SpecError, match="key 'controller'"):
        fc.closed_loop(model, "controllers/pd.toml", move, 3.0)
    with pytest.raises(SpecError, match="key 'reference'"):
        fc.closed_loop(model, pd, fc.Move(start=[0.0], target=[0.5], time=1.0), 3.0)
    with pytest.raises(SpecError, match="key 'duration'"):
        fc.closed_loop(model, pd, move, 0.5)
    with pytest.raises(SpecError, match="key 'on_divergence'"):
        fc.closed_loop(model, pd, move, 3.0, on_divergence="ignore")
    with pytest.raises(SpecError, match="key 'move_time'"):
        fc.Move(start=[0.0, 0.0, 0.0], target=[0.5, 0.0, 0.0])  # a quintic needs its time
    with pytest.raises(SpecError, match="key 'target'"):
        fc.Move(start=[0.0, 0.0, 0.0], target=[0.5, math.nan, 0.0], time=1.0)


def test_scene_refuses_design_keys_with_a_designed_controller(model, op):
    lqr = fc.design(model, op, fc.load_controller(DATA / "controllers" / "lqr.toml"))
    scene = fc.load_scene(SCENE, ["design_payload=0.0", "duration=3.0"])
    with pytest.raises(SpecError, match="key 'design_payload'.*designed in Python"):
        fc.run_scene(scene, controller=lqr)
