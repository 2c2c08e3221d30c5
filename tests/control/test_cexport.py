"""C export of designed controllers: the library builds with the system compiler and its
torques replay Python's (``flexctrl export`` then ``make -C DIR check``)."""

import shutil
import subprocess

import numpy as np
import pytest

import flexctrl as fc
from flexctrl.cli import main
from flexctrl.control.cexport import StepRecorder
from flexctrl.errors import SpecError

SCENE = "studies/scenes/move_joint1_30deg.toml"
needs_cc = pytest.mark.skipif(
    shutil.which("cc") is None or shutil.which("make") is None,
    reason="no C compiler (cc) or make",
)


def export(controller: str, out, *extra: str) -> None:
    """``flexctrl export CONTROLLER --scene SCENE --out OUT`` in this process."""
    assert main(["export", controller, "--scene", SCENE, "--out", str(out), *extra]) == 0


def make_check(folder) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["make", "-s", "-C", str(folder), "check", "REPEATS=1"], capture_output=True, text=True
    )


def worst_relative(stdout: str, what: str = "pass A (") -> list[float]:
    """The harness's largest difference per joint relative to the joint's largest torque."""
    lines = stdout.split(what, 1)[1].split("pass", 1)[0].splitlines()
    return [
        float(line.split(" of max |u_py|")[0].rsplit(", ", 1)[1]) for line in lines if "tau" in line
    ]


@pytest.fixture(scope="module")
def lqr_export(tmp_path_factory):
    out = tmp_path_factory.mktemp("lqr")
    export("controllers/lqr.toml", out, "--repeats", "1")
    return out


@needs_cc
def test_lqr_export_replays_python_to_1e9(lqr_export):
    done = make_check(lqr_export)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "CHECK PASSED" in done.stdout
    assert "rejected, torques equal to pass A's" in done.stdout  # the NaN contract in C
    worst = worst_relative(done.stdout)
    assert len(worst) == 3 and max(worst) <= 1e-9
    replayed = np.loadtxt(lqr_export / "replay.csv", delimiter=",", skiprows=1)
    assert replayed.shape[0] == 942  # 8 s at 8.5 ms, every sample of the scene's loop


@needs_cc
def test_a_broken_c_law_fails_the_harness(lqr_export, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(lqr_export, broken)
    law = broken / "law.c"
    text = law.read_text()
    assert "    u[i] = ui;\n" in text
    law.write_text(text.replace("    u[i] = ui;\n", "    u[i] = ui + 1e-6;\n"))
    done = make_check(broken)
    assert done.returncode != 0  # make reports the harness's failure
    assert "CHECK FAILED" in done.stdout and "FAIL" in done.stdout.split("pass A (", 1)[1]


@needs_cc
def test_full_state_lqr_from_python(tmp_path):
    damped = [f"links[{i}].damping_ratio=0.005" for i in (1, 2, 3)]
    model = fc.load_model(
        "subedi3link", payload=2.0, fidelity="amm:2", gravity=[0.0, 0.0], overrides=damped
    )
    op = fc.equilibrium(model, np.radians([20.0, 0.0, 0.0]))
    ctrl = fc.design(model, op, fc.load_controller("lqr_ideal"))
    rec = StepRecorder(ctrl)
    move = fc.Move(start=np.radians([0.0, 0, 0]), target=np.radians([20.0, 0, 0]), time=1.5)
    fc.closed_loop(model, rec, move, 4.0, dt=ctrl.sample_time / 17)
    result = ctrl.export_c(tmp_path / "ideal", replay=rec.replay())
    assert result.samples == int(np.ceil(4.0 / ctrl.sample_time - 1e-9))
    header = (tmp_path / "ideal" / "flexctrl_controller.h").read_text()
    assert "y[0] q1         rad" in header and "u[2] tau3" in header
    done = make_check(tmp_path / "ideal")
    assert done.returncode == 0, done.stdout
    assert max(worst_relative(done.stdout)) <= 1e-9


def test_kinds_without_export_raise(tmp_path):
    model = fc.load_model("subedi3link", payload=2.0, fidelity="rigid", gravity=[0.0, 0.0])
    op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
    pd = fc.design(model, op, fc.load_controller("pd"))
    with pytest.raises(SpecError, match="no C export.*allowed: an LQR/LQG"):
        pd.export_c(tmp_path / "pd")
    lqr = fc.design(model, op, fc.load_controller("lqr_ideal"))
    with pytest.raises(SpecError, match="qp_eps"):
        lqr.export_c(tmp_path / "lqr", qp_eps=1e-6)
    with pytest.raises(SpecError, match="no steps were recorded"):
        StepRecorder(lqr).replay()


@pytest.fixture(scope="module")
def mpc_export(tmp_path_factory):
    out = tmp_path_factory.mktemp("mpc")
    export("controllers/mpc.toml", out, "--repeats", "1", "--set", "duration=4.0")
    return out


@needs_cc
def test_mpc_export_replays_python_at_the_qps_tolerance(mpc_export):
    done = make_check(mpc_export)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "rejected, torques equal to pass A's" in done.stdout
    # u*: the same QPs solved tightly in Python; the C torques are closer to it than Python's
    exact = np.loadtxt(mpc_export / "exact.csv", delimiter=",", skiprows=1)[:, 1:]
    c = np.loadtxt(mpc_export / "c_torques.csv", delimiter=",", skiprows=1)[:, 2:]
    replay = np.loadtxt(mpc_export / "replay.csv", delimiter=",", skiprows=1)[:, -3:]
    python_gap = np.abs(replay - exact).max(axis=0)
    assert np.all(np.abs(c - exact).max(axis=0) <= 1.1 * python_gap)
    assert np.all(np.abs(c - replay).max(axis=0) <= 2.0 * python_gap)
    # and Python's OSQP is within a few of its own tolerances of u* (eps_abs 1e-3 on v = du/S_u)
    assert np.all(python_gap < 1.0)


@needs_cc
def test_a_loose_c_solver_fails_the_harness(mpc_export, tmp_path):
    broken = tmp_path / "loose"
    shutil.copytree(mpc_export, broken)
    header = broken / "flexctrl_controller.h"
    text = header.read_text()
    eps = [line for line in text.splitlines() if line.startswith("#define FLEXCTRL_EPS_")]
    assert len(eps) == 2
    for line in eps:
        text = text.replace(line, line.rsplit(" ", 1)[0] + " 0.1")
    header.write_text(text)
    subprocess.run(["make", "-s", "-C", str(broken), "clean"], check=True)
    done = make_check(broken)
    assert done.returncode != 0 and "CHECK FAILED" in done.stdout


def test_mpc_options_without_export_raise(tmp_path):
    import dataclasses

    model = fc.load_model("subedi3link", payload=2.0, fidelity="amm:1", gravity=[0.0, 0.0])
    op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
    settings = fc.load_controller("mpc")
    blocked = dataclasses.replace(settings, formulation="condensed", blocks=(5, 5, 10))
    with pytest.raises(SpecError, match="move blocking"):
        fc.design(model, op, blocked).export_c(tmp_path / "blocked")
    with pytest.raises(SpecError, match="qp_eps"):
        fc.design(model, op, settings).export_c(tmp_path / "eps", qp_eps=-1.0)


def test_exported_law_functions_are_the_python_step():
    """Without a compiler: the two generated functions reproduce ``ctrl.step`` sample by sample."""
    model = fc.load_model("subedi3link", payload=2.0, fidelity="amm:1", gravity=[0.0, 0.0])
    op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
    ctrl = fc.design(model, op, fc.load_controller("lqr"))
    start, later = ctrl.law_function(start=True), ctrl.law_function(start=False)
    rng = np.random.default_rng(1)
    y0 = ctrl.sensors.evaluate(op.x, op.u)
    r = np.r_[op.x, op.u]
    ctrl.reset()
    xi = None
    for k in range(4):
        y = y0 + 1e-3 * rng.standard_normal(y0.size)
        u_prev = ctrl.u_previous.copy()
        u = ctrl.step(k * ctrl.sample_time, y)
        if xi is None:
            xi, v = start(y, u_prev, r)
        else:
            xi, v = later(xi, y, u_prev, r)
        v = np.clip(np.asarray(v).ravel(), -ctrl.limits, ctrl.limits)
        assert np.allclose(v, u, rtol=1e-12, atol=1e-12 * np.abs(u).max())
        assert np.allclose(np.asarray(xi).ravel(), ctrl.observer.memory, rtol=1e-12, atol=1e-15)


def test_mpc_parameters_are_the_controllers_shifts():
    """The generated QP parameters ``p = [z, dv, dc]`` equal the controller's own, and the
    condensed QP's solution at ``p`` is the controller's first move."""
    from flexctrl.control.cexport.mpc_dense import condensed_data, pre_functions
    from flexctrl.control.reference_trajectory import ReferenceTrajectory

    model = fc.load_model("subedi3link", payload=2.0, fidelity="amm:1", gravity=[0.0, 0.0])
    op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
    ctrl = fc.design(model, op, fc.load_controller("mpc"))
    move = fc.Move(start=np.radians([0.0, 0, 0]), target=np.radians([30.0, 0, 0]), time=1.5)
    ctrl.set_reference(ReferenceTrajectory(model, move.joint_reference(), move.deflection))
    ctrl.reset()
    start, _ = pre_functions(ctrl)
    pb, t, N = ctrl.problem, 0.3, ctrl.problem.horizon
    X, U, _ = ctrl.reference.window(t, ctrl.sample_time, N + 1)
    y = ctrl.sensors.evaluate(X[0], U[0])
    _xi, p, u_lqr = start(y, ctrl.u_previous, X.T, U.T)
    x = ctrl.observer.estimate(y, ctrl.u_previous)
    r, u_ref, dv, dc = ctrl.reference_shifts(t)
    z = (x - op.x) / pb.Sx - r[0]
    assert np.allclose(np.asarray(p).ravel(), np.r_[z, dv.ravel(), dc.ravel()], atol=1e-12)
    assert np.allclose(np.asarray(u_lqr).ravel(), u_ref[0] - pb.Su * (pb.K @ z), atol=1e-9)
    # the condensed QP's data: with the DARE terminal cost and no constraint active, its first
    # move is the LQR move -K z (an analytic limit, independent of the QP's assembly)
    d = condensed_data(ctrl)
    v = np.linalg.solve(d["H"], -d["F"] @ z)
    assert np.allclose(v[: pb.m], -pb.K @ z, rtol=1e-8, atol=1e-10 * np.abs(z).max())


def test_the_command_refuses_a_payload_aware_file_by_name_before_recording(tmp_path, capsys):
    out = tmp_path / "payload"
    assert (
        main(["export", "controllers/lqr_payload.toml", "--scene", SCENE, "--out", str(out)]) == 2
    )
    err = capsys.readouterr().err
    assert "controllers/lqr_payload.toml" in err and "key 'payload'" in err
    assert "payload-aware lqr" in err and "allowed:" in err
    assert not out.exists()  # nothing recorded, nothing written
