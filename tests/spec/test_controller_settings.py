"""Controller settings: shipped files load; bad values name file, key, value and what is allowed."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from support import DATA

from flexctrl.errors import SpecError
from flexctrl.spec.controller_reader import load_controller
from flexctrl.spec.controller_settings import (
    LQRSettings,
    MPCSettings,
    NMPCSettings,
    PDSettings,
    ScheduleSettings,
    SensorSettings,
    ShapedSettings,
)

SHIPPED = sorted((DATA / "controllers").glob("*.toml"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_controller_files_load(path):
    settings = load_controller(path)
    assert settings.sample_time > 0
    assert settings.kind in ("pd", "lqr", "mpc", "nmpc", "shaped")


def test_all_six_files_are_shipped():
    assert {p.stem for p in SHIPPED} >= {"pd", "lqr", "lqg", "mpc", "nmpc", "shaped"}


def test_degrees_in_files_become_radians():
    import tomllib

    for name in ("lqr", "lqg", "pd"):
        path = DATA / "controllers" / f"{name}.toml"
        document = tomllib.loads(path.read_text())
        s = load_controller(path)
        if "weights" in document:
            assert s.weights.joint == pytest.approx(
                math.radians(document["weights"]["joint_deg"]), rel=1e-15
            )
            assert s.weights.joint_rate == pytest.approx(
                math.radians(document["weights"]["joint_rate_deg_s"]), rel=1e-15
            )
        noise = document["sensors"]["noise"]
        assert s.sensors.outputs == tuple(document["sensors"]["outputs"])
        assert s.sensors.joints == pytest.approx(math.radians(noise["joints_deg"]), rel=1e-15)
        assert s.sensors.strain == noise.get("strain", s.sensors.strain)  # not an angle: unchanged


def _write(tmp_path, text: str) -> Path:
    path = tmp_path / "ctrl.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text, key, fragments",
    [
        (
            'kind = "mpc"\nformulation = "dense"\n',
            "formulation",
            ["'dense'", "'sparse'", "'condensed'"],
        ),
        ('kind = "mpc"\nhorizon = 0\n', "horizon", ["0", "from 1"]),
        ('kind = "mpc"\nhorizn = 20\n', "horizn", ["did you mean 'horizon'"]),
        ('kind = "mpc"\n[osqp]\nmax_iter = -3\n', "osqp.max_iter", ["-3", "from 1"]),
        ('kind = "mpc"\n[osqp]\nrho = "big"\n', "osqp.rho", ["'big'", "not a number"]),
        ('kind = "lqr"\n[weights]\njoint_deg = -1\n', "weights.joint_deg", ["-1", "> 0", "deg"]),
        ('kind = "lqr"\n[weights]\njoint = 0.5\n', "weights.joint", ["renamed 'joint_deg'", "0.5"]),
        (
            'kind = "lqr"\n[weights]\njoint_rate = 30\n',
            "weights.joint_rate",
            ["renamed 'joint_rate_deg_s'"],
        ),
        (
            'kind = "lqr"\n[sensors]\nnoise = { joints = 0.005 }\n',
            "sensors.noise.joints",
            ["renamed 'joints_deg'"],
        ),
        (
            'kind = "lqr"\n[sensors]\nnoise = { joint_rates = 0.05 }\n',
            "sensors.noise.joint_rates",
            ["renamed 'joint_rates_deg_s'"],
        ),
        ('kind = "lqr"\n[schedule]\nq2 = [0, 10]\n', "schedule.q2", ["renamed 'q2_deg'"]),
        (
            'kind = "lqr"\n[sensors]\noutputs = ["joints", "strian"]\n',
            "sensors.outputs[1]",
            ["'strian'", "did you mean 'strain'"],
        ),
        (
            'kind = "lqr"\n[sensors]\noutputs = ["state", "joints"]\n',
            "sensors.outputs",
            ["'state'", "stands alone"],
        ),
        (
            'kind = "lqr"\n[sensors]\nnoise = { joints_deg = -0.1 }\n',
            "sensors.noise.joints_deg",
            ["-0.1", ">= 0"],
        ),
        (
            'kind = "lqr"\n[schedule]\nq2_deg = [10, 0]\n',
            "schedule.q2_deg",
            ["strictly increasing"],
        ),
        ('kind = "lqr"\n[schedule]\nx2 = [0, 10]\n', "schedule.x2", ["'q1_deg', 'q2_deg'"]),
        ('kind = "pd"\nkp = [1, 2]\nkd = [1]\n', "kd", ["1 gains", "kp has 2"]),
        ('kind = "pd"\ngravity = "measure"\n', "gravity", ["'measure'", "did you mean 'measured'"]),
        ('kind = "pd"\n[sensors]\noutputs = ["joints"]\n', "sensors.outputs", ["'joint_rates'"]),
        ('kind = "nmpc"\nqp_solver = "gurobi"\n', "qp_solver", ["'gurobi'", "'hpipm'"]),
        ('kind = "shaped"\nshaper = "zvdd"\n', "shaper", ["'zvdd'", "'zvd'"]),
        ('kind = "shaped"\n[pd]\nbandwidth = 0\n', "pd.bandwidth", ["0", "> 0", "Hz"]),
        (
            'kind = "shaped"\n[pd.sensors]\noutputs = ["tip"]\n',
            "pd.sensors.outputs",
            ["'joint_rates'"],
        ),
        ('kind = "fuzzy"\n', "kind", ["'fuzzy'", "'mpc'"]),
        (
            'kind = "mpc"\nbackend = "hpipm"\nformulation = "condensed"\n',
            "formulation",
            ["'sparse'"],
        ),
    ],
)
def test_bad_values_name_file_key_value_and_allowed(tmp_path, text, key, fragments):
    path = _write(tmp_path, text)
    with pytest.raises(SpecError) as info:
        load_controller(path)
    message = str(info.value)
    assert str(path) in message
    assert f"key '{key}'" in message
    for fragment in fragments:
        assert fragment in message, message


def test_overrides_apply_before_validation(tmp_path):
    s = load_controller(DATA / "controllers" / "mpc.toml", ["horizon=30", "osqp.eps_abs=1e-5"])
    assert s.horizon == 30 and s.osqp.eps_abs == 1e-5
    with pytest.raises(SpecError, match="horizon"):
        load_controller(DATA / "controllers" / "mpc.toml", ["horizon=-1"])


def test_schedule_reads_degrees_and_sorts_joints(tmp_path):
    path = _write(tmp_path, 'kind = "lqr"\n[schedule]\nq3_deg = [-20, 0, 20]\nq2_deg = [-10, 10]\n')
    s = load_controller(path)
    assert s.schedule.joints == (2, 3)
    assert s.schedule.grid[1] == pytest.approx(tuple(math.radians(a) for a in (-20, 0, 20)))


@pytest.mark.parametrize(
    "factory, key",
    [
        (lambda: MPCSettings(horizon=0), "horizon"),
        (lambda: MPCSettings(warm_start="hot"), "warm_start"),
        (lambda: LQRSettings(sample_time=0.0), "sample_time"),
        (lambda: NMPCSettings(mode="sqp"), "mode"),
        (lambda: PDSettings(damping=-1.0), "damping"),
        (lambda: ShapedSettings(modes=0), "modes"),
        (lambda: SensorSettings(outputs=("joints", "joints")), "outputs"),
        (lambda: ScheduleSettings(joints=(2,), grid=((0.1,),)), "q2"),
    ],
)
def test_settings_validate_when_built_in_python(factory, key):
    with pytest.raises(SpecError) as info:
        factory()
    assert info.value.key == key


def test_settings_are_frozen():
    s = MPCSettings()
    with pytest.raises(AttributeError):
        s.horizon = 3  # type: ignore[misc]


@pytest.mark.parametrize("kind", ["pd", "lqr", "mpc", "nmpc", "shaped"])
def test_on_bad_measurement_reads_from_files(tmp_path, kind):
    table = "[pd]\n" if kind == "shaped" else ""
    path = _write(tmp_path, f'kind = "{kind}"\n{table}on_bad_measurement = "hold"\n')
    assert load_controller(path).on_bad_measurement == "hold"
    path = _write(tmp_path, f'kind = "{kind}"\n{table}on_bad_measurement = "skip"\n')
    with pytest.raises(SpecError) as info:
        load_controller(path)
    assert "'skip'" in str(info.value) and "'hold'" in str(info.value)
    assert info.value.key.endswith("on_bad_measurement")
