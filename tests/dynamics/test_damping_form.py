"""Modal damping form: Eq 68 of Subedi et al. as printed beside the ratio form, from files and
scenes."""

from __future__ import annotations

import numpy as np
import pytest

from flexctrl.dynamics.build import ModelFamilyUnavailable, build_model
from flexctrl.errors import SpecError
from flexctrl.scenes.arm_setup import scene_arm
from flexctrl.spec.scene import load_scene

SCENE = "studies/scenes/free_vibration_damped.toml"


def _modal_damping(form):
    scene = load_scene(
        SCENE, [f"damping.form='{form}'", "fidelity='amm:1'"] if form else ["fidelity='amm:1'"]
    )
    arm = scene_arm(scene)
    model = build_model(arm, scene.fidelity, reference_q=scene.q0)
    D = model.functions["D"]
    value = D() if D.n_in() == 0 else D(np.zeros(model.n_q))
    value = next(iter(value.values())) if isinstance(value, dict) else value
    return arm, np.diag(np.array(value.full()))


def test_scene_damping_form_paper_divides_the_ratio_form_by_the_link_mass():
    arm, ratio = _modal_damping("ratio")
    _, paper = _modal_damping("paper")
    _, default = _modal_damping(None)
    masses = np.array([link.mass for link in arm.links])
    np.testing.assert_allclose(default, ratio)
    np.testing.assert_allclose(paper[3:] * masses, ratio[3:], rtol=1e-12)
    assert np.all(ratio[3:] > 0) and not np.allclose(paper[3:], ratio[3:])


def test_scene_damping_form_rejects_an_unknown_value_on_one_line():
    with pytest.raises(SpecError) as info:
        load_scene(SCENE, ["damping.form='eq68'"])
    text = str(info.value)
    assert (
        "damping.form" in text
        and "'eq68'" in text
        and "'ratio', 'paper'" in text
        and "\n" not in text
    )


def test_paper_form_is_refused_by_finite_elements():
    arm = scene_arm(load_scene(SCENE, ["damping.form='paper'"]))
    with pytest.raises(ModelFamilyUnavailable, match="assumed modes only"):
        build_model(arm, "fem:2")
