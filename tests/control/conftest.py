"""The three-link arm the controller tests design on: ``amm:2``, gravity, (80, -10, -10) deg."""

import numpy as np
import pytest

from flexctrl.linear import equilibrium
from flexctrl.scenes.model_files import load_model

#: The target of :func:`op3`: the arm raised, the outer links slightly bent down (rad).
TARGET_80 = np.radians([80.0, -10.0, -10.0])


@pytest.fixture(scope="module")
def arm3():
    """The Subedi arm, two assumed modes per link, no modal damping."""
    return load_model("models/subedi3link.toml", fidelity="amm:2")


@pytest.fixture(scope="module")
def op3(arm3):
    """The equilibrium of :func:`arm3` at (80, -10, -10) deg."""
    return equilibrium(arm3, TARGET_80)


@pytest.fixture(scope="module")
def damped3():
    """The arm with 0.5 % modal damping (as the scenes use)."""
    return load_model(
        "models/subedi3link.toml",
        fidelity="amm:2",
        overrides=[f"links[{i}].damping_ratio=0.005" for i in (1, 2, 3)],
    )
