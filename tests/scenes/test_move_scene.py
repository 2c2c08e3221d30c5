"""The move scene: a 30 degree move of joint 1, horizontal plane, 2 kg, zeta = 0.005.

The reference is a 1.5 s quintic (the fastest within joint 1's 200 N m at 2 kg); every
controller tracks it, and what is compared is what each leaves behind after it arrives.
"""

from __future__ import annotations

import json

import pytest
from support import DATA

from flexctrl.cli import main

SCENE = "studies/scenes/move_joint1_30deg.toml"
SETTLED_WITHIN_S = 6.0  # tip error stays below 1 mm after this time


@pytest.fixture(scope="module")
def runs(tmp_path_factory):

    root = DATA
    results = {}
    for name in ("pd", "lqr", "mpc"):
        out = tmp_path_factory.mktemp(name)
        assert (
            main(
                [
                    "simulate",
                    str(root / SCENE),
                    "--controller",
                    str(DATA / "controllers" / f"{name}.toml"),
                    "--out",
                    str(out),
                    "--no-plots",
                ]
            )
            == 0
        )
        results[name] = json.loads((out / "summary.json").read_text())
    return results


@pytest.mark.parametrize("name", ["lqr", "mpc"])
def test_lqr_and_mpc_bring_the_tip_below_1mm_within_the_stated_time(runs, name):
    m = runs[name]["metrics"]
    assert m["settling_time"] < SETTLED_WITHIN_S
    assert m["tip_residual_peak"] < 1e-2
    assert not m["torque_limit_exceeded"]
    assert max(m["peak_torque"][i] / lim for i, lim in enumerate((200.0, 100.0, 50.0))) <= 1 + 1e-9
    # (no assertion on fallbacks: mpc.toml's 8 ms real-time guard makes them depend on machine load)


def test_pd_leaves_the_largest_residual_peak(runs):
    pd = runs["pd"]["metrics"]["tip_residual_peak"]
    assert pd > runs["lqr"]["metrics"]["tip_residual_peak"]
    assert pd > runs["mpc"]["metrics"]["tip_residual_peak"]


@pytest.mark.parametrize("name", ["lqr", "mpc"])
def test_lqr_and_mpc_beat_pd_on_residual_vibration_with_the_smooth_reference(runs, name):
    """With the quintic, the model-based controllers leave less tip residual than PD (2 kg)."""
    pd, other = runs["pd"]["metrics"], runs[name]["metrics"]
    assert runs[name]["reference"]["profile"] == "quintic"
    assert other["tip_residual_rms"] < pd["tip_residual_rms"]
    assert other["stable"] == 1 and pd["stable"] == 1


def test_summary_interface_keys(runs):
    m = runs["mpc"]["metrics"]
    for key in (
        "tip_residual_rms",
        "tip_residual_peak",
        "settling_time",
        "peak_deflection",
        "peak_torque",
        "controller_time_median",
        "controller_time_p95",
        "fallbacks",
    ):
        assert key in m
    assert m["controller_time_median"] > 0 and len(m["peak_torque"]) == 3


def test_arm_scene_refuses_a_controller(tmp_path):
    root = DATA
    assert (
        main(
            [
                "simulate",
                str(root / "studies/scenes/bangbang.toml"),
                "--controller",
                str(root / "controllers/pd.toml"),
                "--out",
                str(tmp_path),
            ]
        )
        == 2
    )


def test_bench_mpc_smoke(capsys):
    assert main(["bench", "mpc", "--json", "--steps", "5", "--pc-solves", "0", "--no-nmpc"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["median_solve_s"] > 0 and "variants" in result
