"""A misspelt keyword argument of a public function is answered with the allowed names, as an
unknown key in a file is (python-control's kwargs test does the same for its functions)."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

import flexctrl as fc
from flexctrl import _EXPORTS

FUNCTIONS = [name for name in _EXPORTS if inspect.isfunction(getattr(fc, name))]


@pytest.mark.parametrize("name", FUNCTIONS)
def test_an_unknown_keyword_lists_the_allowed_ones(name):
    function = getattr(fc, name)
    parameters = inspect.signature(function).parameters.values()
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        pytest.skip("takes **options and checks them itself (see the test below)")
    keywords = [p.name for p in parameters if p.kind is not inspect.Parameter.VAR_POSITIONAL]
    misspelt = keywords[-1] + "s"  # one letter off the last keyword
    with pytest.raises(TypeError, match=rf"'{misspelt}' \(did you mean '{keywords[-1]}'\?\)"):
        function(**{misspelt: None})
    with pytest.raises(TypeError, match="allowed: " + ", ".join(keywords)):
        function(**{misspelt: None})


def test_functions_taking_options_name_the_allowed_ones_too():
    with pytest.raises(fc.SpecError, match="did you mean 'payload'"):
        fc.load_model("subedi3link", payloud=2.0)
    model = fc.load_model("subedi3link", fidelity="rigid", gravity=[0.0, 0.0])
    with pytest.raises((TypeError, fc.SpecError), match="allowed"):
        fc.simulate(model, np.zeros(model.n_x), 0.01, dt=1e-3, integrator="rk4", stepp=1e-3)


#: The public dataclasses built from keywords; the others (a trajectory, a result, the sensors)
#: are what the toolkit builds and hands back.
SETTINGS = [
    name
    for name in _EXPORTS
    if dataclasses.is_dataclass(getattr(fc, name))
    and name not in ("Trajectory", "ClosedLoopResult", "Sensors")
]


@pytest.mark.parametrize("name", SETTINGS)
def test_a_misspelt_keyword_of_a_public_dataclass_lists_the_allowed_ones(name):
    cls = getattr(fc, name)
    fields = [f.name for f in dataclasses.fields(cls) if f.init]
    misspelt = fields[-1] + "s"
    with pytest.raises(TypeError, match=rf"{name}\(\) got .*'{misspelt}' \(did you mean"):
        cls(**{misspelt: None})
    with pytest.raises(TypeError, match="allowed: " + ", ".join(fields)):
        cls(**{misspelt: None})
