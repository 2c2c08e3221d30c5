"""Inputs that cannot silently mislead: ``flexctrl check``, bad values in every kind of file, unit
traps.

Every kind of file a user writes (model, open-loop scene, closed-loop scene, FEM scene,
controller, study, tuning) is mutated five ways (a NaN, an infinity, a string where a
number belongs, a misspelt key, a missing required key); each mutation must give exit
status 2 and one line on stderr naming the file, the key, the value and what is allowed.
"""

from __future__ import annotations

import math
import re
import shutil
import warnings
from pathlib import Path

import pytest
from support import DATA, ROOT

from flexctrl.cli import main
from flexctrl.errors import SpecError, SpecWarning

SHIPPED = sorted(
    str(p.relative_to(DATA))
    for d in ("models", "controllers", "studies")
    for p in (DATA / d).rglob("*.toml")
)


def _cli(*argv: str) -> tuple[int, str]:
    """Exit status and stderr of ``flexctrl ARGV`` run in its own process from the repository
    root."""
    import subprocess
    import sys

    env = dict(__import__("os").environ)
    done = subprocess.run(
        [sys.executable, "-m", "flexctrl.cli", *argv],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    return done.returncode, done.stderr


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    """A copy of the shipped descriptions (relative paths between them still resolve)."""
    root = tmp_path_factory.mktemp("tree")
    for folder in ("models", "controllers", "studies"):
        shutil.copytree(
            DATA / folder, root / folder, ignore=shutil.ignore_patterns("notebooks", "*.ipynb")
        )
    return root


def test_check_accepts_every_shipped_file_quietly(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    with warnings.catch_warnings():
        warnings.simplefilter(
            "error", SpecWarning
        )  # the unit and inertia warnings stay silent on shipped files
        status = main(["check", *SHIPPED])
    out, err = capsys.readouterr()
    assert status == 0, err
    assert err == ""
    assert len(out.splitlines()) == len(SHIPPED) and all(
        ": ok (" in line for line in out.splitlines()
    )


# (file, regex of the line to change, replacement, key named, value named) per kind and mutation
CASES = {
    "model": (
        "models/subedi3link.toml",
        [
            ("nan", r"^EI = 7\.0361e3", "EI = nan", "links[2].EI", "nan"),
            ("inf", r"^hub_mass = .*", "hub_mass = inf", "joints[1].hub_mass", "inf"),
            ("string", r"^length = 1\.5 ", 'length = "1.5" ', "links[1].length", "'1.5'"),
            (
                "misspelt",
                r"^torque_limit = 200\.0",
                "torque_limt = 200.0",
                "joints[1].torque_limit",
                "torque_limt",
            ),
            ("missing", r"^EI = 7\.0361e3.*", "", "links[2].EI", "missing required key"),
        ],
    ),
    "open-loop scene": (
        "studies/scenes/free_vibration.toml",
        [
            ("nan", r"^dt = 1e-3", "dt = nan", "dt", "nan"),
            ("inf", r"^duration = 5\.0", "duration = inf", "duration", "inf"),
            ("string", r"^payload = 2\.0", 'payload = "heavy"', "payload", "'heavy'"),
            (
                "misspelt",
                r"^integrator = ",
                "integrater = ",
                "integrater",
                "did you mean 'integrator'",
            ),
            ("missing", r"^dt = 1e-3.*", "", "dt", "missing required key"),
        ],
    ),
    "closed-loop scene": (
        "studies/scenes/move_joint1_30deg.toml",
        [
            ("nan", r"^move_time = 1\.5", "move_time = nan", "target.move_time", "nan"),
            ("inf", r"^move = \[30\.0", "move = [inf", "target.move[0]", "inf"),
            ("string", r"^payload = 2\.0", 'payload = "2"', "payload", "'2'"),
            (
                "misspelt",
                r"^controller = ",
                "controler = ",
                "controler",
                "did you mean 'controller'",
            ),
            ("missing", r"^move = \[30\.0.*", "", "target.q", "missing required key"),
        ],
    ),
    "FEM scene": (
        "studies/scenes/rp_extend_rotate.toml",
        [
            ("nan", r"^C1 = 0\.3", "C1 = nan", "C1", "nan"),
            ("inf", r"^T = 1\.0", "T = inf", "T", "inf"),
            ("string", r"^rotation = 60\.0", 'rotation = "sixty"', "rotation", "'sixty'"),
            (
                "misspelt",
                r"^tracked_end = ",
                "traked_end = ",
                "traked_end",
                "did you mean 'tracked_end'",
            ),
            ("missing", r"^C2 = -0\.4.*", "", "C2", "missing required key"),
        ],
    ),
    "controller": (
        "controllers/lqr.toml",
        [
            ("nan", r"^sample_time = 0\.0085", "sample_time = nan", "sample_time", "nan"),
            ("inf", r"^torque_noise = 2\.0", "torque_noise = inf", "estimator.torque_noise", "inf"),
            ("string", r"^modal = 0\.0144209", 'modal = "small"', "weights.modal", "'small'"),
            (
                "misspelt",
                r"^saturate = true",
                "saturte = true",
                "saturte",
                "did you mean 'saturate'",
            ),
            ("missing", r'^kind = "lqr".*', "", "kind", "missing required key"),
        ],
    ),
    "study": (
        "studies/quickstart.toml",
        [
            ("nan", r"^payload = \[0\.0, 2\.0\]", "payload = [nan, 2.0]", "grid.payload[1]", "nan"),
            ("inf", r"^q2 = \[0, 90\]", "q2 = [0, inf]", "grid.q2[2]", "inf"),
            ("string", r"^seed = 1", 'seed = "one"', "seed", "'one'"),
            ("misspelt", r"^worst = 3", "wrost = 3", "report.wrost", "did you mean 'worst'"),
            (
                "missing",
                r'^scene = "scenes/move_joint1_30deg.toml".*',
                "",
                "scene",
                "missing required key",
            ),
        ],
    ),
    "tuning": (
        "studies/tune_lqr.toml",
        [
            ("nan", r"^low = 0\.01", "low = nan", "parameters[1].low", "nan"),
            ("inf", r"^high = 1\.0", "high = inf", "parameters[1].high", "inf"),
            ("string", r"^low = 0\.01", 'low = "low"', "parameters[1].low", "'low'"),
            (
                "misspelt",
                r"^step = 5e-4",
                "stepp = 5e-4",
                "parameters[6].stepp",
                "did you mean 'step'",
            ),
            (
                "missing",
                r'^controller = "tuning/start/lqr.toml".*',
                "",
                "controller",
                "missing required key",
            ),
        ],
    ),
}
PARAMS = [
    pytest.param(kind, path, *case, id=f"{kind}-{case[0]}")
    for kind, (path, cases) in CASES.items()
    for case in cases
]


@pytest.mark.parametrize("kind, path, mutation, pattern, replacement, key, value", PARAMS)
def test_bad_input_is_one_line_naming_file_key_value_and_allowed(
    tree, capsys, monkeypatch, kind, path, mutation, pattern, replacement, key, value
):
    original = tree / path
    text = original.read_text()
    mutated_text, count = re.subn(pattern, replacement, text, count=1, flags=re.M)
    assert count == 1, f"the case's line {pattern!r} is not in {path}"
    mutated = original.with_name(f"mutated_{mutation}_{original.name}")
    mutated.write_text(mutated_text)
    monkeypatch.chdir(tree)
    name = str(mutated.relative_to(tree))
    try:
        status = main(["check", name])
    finally:
        mutated.unlink()
    out, err = capsys.readouterr()
    assert status == 2, out
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert name in err
    assert f"'{key}'" in err
    assert value in err
    assert "allowed" in err.lower()


def test_check_tells_an_unknown_file_and_a_missing_one(tmp_path, capsys):
    odd = tmp_path / "odd.toml"
    odd.write_text("colour = 'blue'\n")
    assert main(["check", str(odd), str(tmp_path / "none.toml")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert (
        len(err) == 2
        and "cannot tell what the file describes" in err[0]
        and "file not found" in err[1]
    )


def test_check_kind_option_reads_the_file_as_told(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert main(["check", "--kind", "controller", "models/subedi3link.toml"]) == 2
    assert "key 'kind'" in capsys.readouterr().err


# -- degrees and radians
# ------------------------------------------------------------------------------


def test_degree_field_that_looks_like_radians_warns_on_one_line(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    scene = "studies/scenes/move_joint1_30deg.toml"
    from flexctrl.spec.scene import load_scene

    with pytest.warns(
        SpecWarning,
        match=r"key 'target.move': value \[0.5236, 0.0, 0.0\] looks like radians; the "
        r"unit expected is degrees \(in degrees that would be \[30.0",
    ):
        load_scene(scene, ["target.move=[0.5236, 0, 0]"])
    with warnings.catch_warnings():
        warnings.simplefilter("error", SpecWarning)
        load_scene(
            scene, ["target.move=[5, 0, 0]"]
        )  # a whole number of degrees is a plausible angle
        load_scene(scene, ["target.move=[0, 0, 0]"])
    # the CLI (a process of its own, as a user runs it): one line on stderr, no source-line dump
    status, err = _cli(
        "modes", "models/subedi3link.toml", "--set", "configuration=[0.5, 1.2, 0]", "--json"
    )
    assert status == 0
    assert (
        err.count("\n") == 1
        and err.startswith("flexctrl modes: warning: ")
        and (
            "models/subedi3link.toml: key 'configuration': value [0.5, 1.2, 0.0] looks like radians"
        )
        in err
    )


def test_radian_argument_that_looks_like_degrees_warns():
    import numpy as np

    import flexctrl as fc

    with pytest.warns(
        SpecWarning,
        match=r"key 'target': value \[30.0, 0.0, 0.0\] looks like degrees.*unit expected "
        r"is radians",
    ):
        fc.Move(start=[0, 0, 0], target=[30, 0, 0], time=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SpecWarning)
        fc.Move(start=[0, 0, 0], target=np.radians([30, 0, 0]), time=1.0)


def test_study_axis_in_radians_warns(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    from flexctrl.study.study_file import load_study

    with pytest.warns(SpecWarning, match=r"key 'grid.q2': value .* looks like radians"):
        load_study("studies/quickstart.toml", ["grid.q2=[0, 1.5708]"], check_executor=False)


# -- torque limits and link inertia
# -------------------------------------------------------------------


def test_torque_limit_is_required_and_inf_must_be_written(tmp_path):
    from flexctrl.spec.arm import load_arm

    text = (DATA / "models/subedi3link.toml").read_text()
    path = tmp_path / "arm.toml"
    path.write_text(re.sub(r"(?m)^torque_limit = 100\.0.*$", "", text, count=1))
    with pytest.raises(
        SpecError,
        match=r"key 'joints\[2\].torque_limit': missing required key; allowed: .*or inf for "
        r"an actuator without a limit",
    ):
        load_arm(path)
    path.write_text(re.sub(r"(?m)^torque_limit = 100\.0", "torque_limit = inf", text, count=1))
    assert load_arm(path).joints[1].torque_limit == math.inf
    for bad in ("-inf", "nan", "0.0", '"lots"'):
        path.write_text(
            re.sub(r"(?m)^torque_limit = 100\.0", f"torque_limit = {bad}", text, count=1)
        )
        with pytest.raises(SpecError, match=r"joints\[2\].torque_limit'.*allowed"):
            load_arm(path)


def test_link_inertia_defaults_to_the_uniform_link_and_warns_far_from_it(tmp_path):
    from flexctrl.spec.arm import INERTIA_FACTOR, load_arm

    text = (DATA / "models/subedi3link.toml").read_text()
    path = tmp_path / "arm.toml"
    path.write_text(re.sub(r"(?m)^inertia = 0\.5589.*$", "", text, count=1))
    link = load_arm(path).links[0]
    assert link.inertia == pytest.approx(link.mass * link.length**2 / 12, rel=1e-12)
    assert link.inertia == pytest.approx(
        0.5589, rel=2e-4
    )  # Table 2 of Subedi et al.: the same number
    with pytest.warns(SpecWarning, match=r"links\[1\].inertia': value 5.589 kg m\^2 is 10 times"):
        load_arm(DATA / "models/subedi3link.toml", ["links[1].inertia=5.589"])
    with warnings.catch_warnings():  # inside the factor: quiet
        warnings.simplefilter("error", SpecWarning)
        load_arm(
            DATA / "models/subedi3link.toml", [f"links[1].inertia={0.5589 * INERTIA_FACTOR * 0.99}"]
        )
    with pytest.warns(SpecWarning):
        load_arm(
            DATA / "models/subedi3link.toml", [f"links[1].inertia={0.5589 / INERTIA_FACTOR * 0.99}"]
        )


# -- known keys per file kind
# ---------------------------------------------------------------------------


def test_closed_loop_scene_lists_its_own_keys(monkeypatch):
    monkeypatch.chdir(ROOT)
    from flexctrl.spec.scene import load_scene

    with pytest.raises(SpecError) as info:
        load_scene("studies/scenes/move_joint1_30deg.toml", ["design_paylod=2.0"])
    message = str(info.value)
    assert "did you mean 'design_payload'" in message
    known = message.split("known keys here: ")[1].split(", ")
    assert {
        "target",
        "controller",
        "design_configuration",
        "metrics",
        "noise",
        "dt",
        "model",
    } <= set(known)
    with pytest.raises(SpecError) as info:  # an open-loop scene does not list the closed-loop keys
        load_scene("studies/scenes/free_vibration.toml", ["design_paylod=2.0"])
    assert "target" not in str(info.value).split("known keys here: ")[1].split(", ")


def test_optional_key_misspelt_gets_a_suggestion():
    from flexctrl.spec.arm import load_arm

    with pytest.raises(
        SpecError,
        match=r"joints\[1\].torque_limt': unknown key \(value 3\); did you mean "
        r"'torque_limit'\?",
    ):
        load_arm(DATA / "models/subedi3link.toml", ["joints[1].torque_limt=3"])
    with pytest.raises(
        SpecError, match=r"links\[1\].EAA'.*did you mean 'EA'"
    ):  # an optional key the file lacks
        load_arm(DATA / "models/subedi3link.toml", ["links[1].EAA=3"])


# -- holding torques, poles, per-link modes
# ---------------------------------------------------------------


def test_linearize_text_marks_unstable_poles_and_prints_damping(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    # an upright rigid arm with free joints is an inverted pendulum chain (unstable real poles);
    # hanging, it is not
    assert (
        main(["linearize", "models/subedi3link.toml", "--q", "90", "0", "0", "--fidelity", "rigid"])
        == 0
    )
    upright = capsys.readouterr().out
    assert (
        main(
            ["linearize", "models/subedi3link.toml", "--q", "-90", "0", "0", "--fidelity", "rigid"]
        )
        == 0
    )
    hanging = capsys.readouterr().out
    assert "zeta" in upright and "UNSTABLE" in upright and "no unstable pole" not in upright
    assert "UNSTABLE" not in hanging and "no unstable pole" in hanging
    rows = [
        line for line in upright.splitlines() if line.strip().endswith(")") and "UNSTABLE" in line
    ]
    assert rows and all(
        float(r.split()[1]) < 0 for r in rows
    )  # a growing pole has a negative damping ratio
    assert (
        main(
            [
                "linearize",
                "models/subedi3link.toml",
                "--q",
                "90",
                "0",
                "0",
                "--fidelity",
                "rigid",
                "--json",
            ]
        )
        == 0
    )
    data = __import__("json").loads(capsys.readouterr().out)
    assert sum(data["unstable"]) == upright.count("UNSTABLE")
    assert all((re > 0) == u for re, u in zip(data["eigenvalues_real_1_s"], data["unstable"]))


def test_linearize_warns_on_one_line_when_the_limits_cannot_hold_the_pose(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    status, err = _cli(
        "linearize",
        "models/subedi3link.toml",
        "--q",
        "0",
        "90",
        "0",
        "--fidelity",
        "rigid",
        "--json",
    )
    assert status == 0
    assert err.count("\n") == 1 and "Traceback" not in err
    assert re.search(
        r"warning: models/subedi3link.toml: key '--q': .*holding torques \[[0-9.]+, .*beyond the "
        r"torque "
        r"limits \[200.0, 100.0, 50.0\] N m \(joint 1: \|[0-9.]+\| > 200\)",
        err,
    )


def test_design_refuses_a_target_the_limits_cannot_hold(monkeypatch, tmp_path, capsys):
    monkeypatch.chdir(ROOT)
    import numpy as np

    import flexctrl as fc

    model = fc.load_model("models/subedi3link.toml", payload=2.0, fidelity="rigid")
    op = fc.equilibrium(model, np.radians([0.0, 90.0, 0.0]))
    with pytest.raises(
        SpecError,
        match=r"models/subedi3link.toml.*: key 'target': the static equilibrium at q = "
        r"\[0.0, 90.0, 0.0\] deg needs holding torques .*allowed: a target",
    ):
        fc.design(model, op, fc.PDSettings())
    # the closed-loop scene in a vertical plane: exit 2 with that line, before any step is simulated
    status = main(
        [
            "simulate",
            "studies/scenes/move_joint1_30deg.toml",
            "--out",
            str(tmp_path / "out"),
            "--no-plots",
            "--set",
            "gravity=[0.0, -9.81]",
            "--set",
            'fidelity="rigid"',
            "--controller",
            "controllers/pd.toml",
        ]
    )
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "holding torques" in err and "joint 1" in err
    assert not (tmp_path / "out" / "trajectory.csv").exists()


def test_per_link_modes_take_a_model_as_well_as_a_description(monkeypatch):
    monkeypatch.chdir(ROOT)
    import numpy as np

    import flexctrl as fc

    model = fc.load_model("models/subedi3link.toml", payload=2.0, fidelity="amm:1")
    spec = fc.load_arm("models/subedi3link.toml").with_payload(2.0)
    q = np.radians([0.0, 45.0, 0.0])
    for link in range(3):
        assert fc.link_modes(model, q, link, 2).frequency_hz == pytest.approx(
            fc.link_modes(spec, q, link, 2).frequency_hz, rel=1e-12
        )
    assert [m.frequency_hz[0] for m in fc.arm_modes(model, q, 1)] == pytest.approx(
        [fc.link_modes(spec, q, i, 1).frequency_hz[0] for i in range(3)], rel=1e-12
    )
    with pytest.raises(SpecError, match="allowed: an ArmSpec"):
        fc.link_modes("models/subedi3link.toml", q, 0)


# -- controller keys from the command line and per controller in a study
# --------------------------------------


def test_simulate_set_reaches_the_controller_file(capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)
    scene = "studies/scenes/move_joint1_30deg.toml"
    assert (
        main(["simulate", scene, "--out", str(tmp_path), "--set", "controller.sample_tim=0.005"])
        == 2
    )
    err = capsys.readouterr().err
    assert (
        err.count("\n") == 1
        and "controllers/lqr.toml: key 'sample_tim'" in err
        and "did you mean 'sample_time'" in err
    )
    assert (
        main(
            [
                "simulate",
                "studies/scenes/free_vibration.toml",
                "--out",
                str(tmp_path),
                "--set",
                "controller.sample_time=0.005",
            ]
        )
        == 2
    )
    assert "runs no controller" in capsys.readouterr().err
    status = main(
        [
            "simulate",
            scene,
            "--out",
            str(tmp_path),
            "--no-plots",
            "--json",
            "--controller",
            "controllers/pd.toml",
            "--set",
            "duration=3.0",
            "--set",
            "controller.sample_time=0.002",
        ]
    )
    summary = __import__("json").loads(capsys.readouterr().out)
    assert status == 0
    assert (
        summary["controller"]["sample_time"] == 0.002 and summary["controller"]["steps"] == 1500
    )  # 3 s / 2 ms


def test_study_overrides_one_controller_of_its_grid_only(monkeypatch):
    monkeypatch.chdir(ROOT)
    from flexctrl.study.study_file import load_study

    spec = load_study("studies/quickstart.toml", ["per_controller.mpc.horizon=30"])
    by_controller = {}
    for run in spec.runs:
        by_controller.setdefault(run.coordinates["controller"], set()).update(
            run.settings["overrides"]
        )
    assert by_controller["mpc"] == {"controller.horizon=30"}
    assert all(not v for k, v in by_controller.items() if k != "mpc")
    with pytest.raises(
        SpecError,
        match=r"key 'per_controller.mcp': 'mcp' is not a controller of the study \(did you "
        r"mean 'mpc'\?\); allowed: .*lqr, lqr_payload, mpc, mpc_payload, pd, robust",
    ):
        load_study("studies/quickstart.toml", ["per_controller.mcp.horizon=30"])
    with pytest.raises(
        SpecError, match=r"refuses run .*controller = pd.*key 'horizon': unknown key"
    ):
        load_study("studies/quickstart.toml", ["per_controller.pd.horizon=30"])


# -- metrics a controller cannot produce
# ------------------------------------------------------------------------


def test_closed_loop_radius_of_an_nmpc_is_known_unavailable_before_any_run(monkeypatch):
    monkeypatch.chdir(ROOT)
    from flexctrl.study.study_file import load_study

    spec = load_study(
        "studies/controller_stability.toml",
        [
            'grid.controller=["../controllers/pd.toml", "../controllers/lqg.toml", '
            '"../controllers/nmpc.toml"]',
            "grid.payload=[2.0]",
            "grid.q2=[0]",
            "grid.q3=[0]",
        ],
    )
    radius = [entry for entry in spec.unavailable if entry[1] == "closed_loop_radius"]
    assert [(spec.runs[i].coordinates["controller"], m) for i, m, _ in radius] == [
        ("nmpc", "closed_loop_radius")
    ]
    assert "no linear law" in radius[0][2]
    assert f"closed_loop_radius stays empty in 1 of 3 runs: {radius[0][2]}" in (
        spec.unavailable_notes()
    )
    payload = {m for _, m, _ in spec.unavailable if m.startswith("payload_estimate")}
    assert payload == {"payload_estimate_error", "payload_estimate_time"}


@pytest.mark.parametrize("declared", [True, False])
def test_a_metric_a_run_cannot_produce_is_an_empty_cell_with_its_reason(
    tmp_path, monkeypatch, declared
):
    import csv

    from flexctrl.study.executors import selftest_executor as selftest
    from flexctrl.study.outputs import RunOutput
    from flexctrl.study.runner import run_study
    from flexctrl.study.study_file import load_study

    real = selftest.execute

    def hides_frequency(settings):  # the stiff controller produces no frequency_hz
        out = real(settings)
        if "stiff" in settings["controller"]:
            return RunOutput(
                {k: v for k, v in out.metrics.items() if k != "frequency_hz"}, out.trajectories
            )
        return out

    monkeypatch.setattr(selftest, "execute", hides_frequency)
    if declared:  # ... and says so (without it, the control: those runs fail)
        monkeypatch.setattr(
            selftest,
            "unavailable_metrics",
            lambda s: (
                {"frequency_hz": "the stiff one hides it"} if "stiff" in s["controller"] else {}
            ),
            raising=False,
        )
    spec = load_study(ROOT / "tests/data/study_selftest.toml", ["grid.q2=[0]", "grid.q3=[0]"])
    assert len(spec.unavailable) == (2 if declared else 0)
    run_study(spec, tmp_path / "out", workers=0, progress="none", report=False)
    with open(tmp_path / "out" / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    stiff = [r for r in rows if r["controller"] == "stiff"]
    soft = [r for r in rows if r["controller"] == "soft"]
    assert len(stiff) == len(soft) == 2 and all(
        r["status"] == "ok" and float(r["frequency_hz"]) > 0 for r in soft
    )
    if declared:
        assert all(
            r["status"] == "ok" and r["frequency_hz"] == "" and float(r["tip_peak"]) > 0
            for r in stiff
        )
        assert all(r["error"] == "no frequency_hz: the stiff one hides it" for r in stiff)
    else:
        assert all(
            r["status"] == "failed" and "no metric 'frequency_hz'" in r["error"] for r in stiff
        )
