"""A lift of constants kept per structure: the same Function and the same constants as a lift anew.

:func:`~flexctrl.dynamics.parametric.constants_as_parameters` keeps each lifted Function
by its operation sequence and reads a later Function's constants from the instructions
the kept lift recorded, instead of walking and rebuilding the graph.  It must give what a
lift anew gives (the constants to the bit, the outputs to the bit), across configurations
whose graphs merge coinciding constants (per use), and must not hand a kept lift to a
Function wired otherwise.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from support import MODEL

from flexctrl.dynamics.build import build_model
from flexctrl.dynamics.parametric import LIFTED, constants_as_parameters
from flexctrl.sim.integrator import output_function
from flexctrl.spec.arm import load_arm

# degrees: the straight arm merges coinciding constants, so its graph has fewer constant nodes
CONFIGURATIONS = ([0, 90, -90], [0, 0, 0], [0, 30, 60])


@pytest.fixture(scope="module")
def models():
    arm = load_arm(MODEL).with_payload(2.0)
    return [
        build_model(arm, "amm:2", modes="frozen", reference_q=np.radians(q)) for q in CONFIGURATIONS
    ]


def _evaluate(fp, c, f, rng):
    args = [rng.normal(0, 0.3, f.sparsity_in(i).shape) for i in range(f.n_in())]
    outs = fp(*args, c)
    return [np.array(o, dtype=float) for o in (outs if isinstance(outs, tuple) else [outs])]


@pytest.mark.parametrize("per_use", [False, True])
@pytest.mark.parametrize("which", ["f", "outputs"])
def test_a_kept_lift_serves_later_configurations_as_a_lift_anew_would(models, per_use, which):
    LIFTED.clear()
    funs = [m.functions["f"] if which == "f" else output_function(m) for m in models]
    first, _ = constants_as_parameters(funs[0], per_use=per_use)
    nodes = [
        sum(f.instruction_id(k) == ca.OP_CONST for k in range(f.n_instructions())) for f in funs
    ]
    for fun in funs[1:]:
        kept, c = constants_as_parameters(fun, per_use=per_use)
        anew, c_anew = lift_anew(fun, per_use)
        if per_use or which == "f":
            assert kept is first  # no walk, no rebuild
        assert np.array_equal(c, c_anew)
        if kept is first:
            assert (
                kept.serialize() == anew.serialize()
            )  # the kept structure is the one a lift anew builds
        for a, b, d in zip(
            _evaluate(kept, c, fun, np.random.default_rng(4)),
            _evaluate(anew, c_anew, fun, np.random.default_rng(4)),
            [np.array(o, dtype=float) for o in _outputs(fun, np.random.default_rng(4))],
        ):
            assert np.array_equal(a, b)
            np.testing.assert_allclose(a, d, rtol=1e-12, atol=1e-12)
    if which == "outputs":
        assert (
            len(set(nodes)) > 1
        )  # the case per use is for: the graphs' constant nodes differ in number


def lift_anew(fun, per_use):
    """A lift of ``fun`` with nothing kept (the kept lifts are put back after)."""
    kept = dict(LIFTED._built)
    LIFTED.clear()
    try:
        return constants_as_parameters(fun, per_use=per_use)
    finally:
        LIFTED.clear()
        for key, value in kept.items():
            LIFTED.keep(key, value)


def _outputs(fun, rng):
    args = [rng.normal(0, 0.3, fun.sparsity_in(i).shape) for i in range(fun.n_in())]
    outs = fun(*args)
    return outs if isinstance(outs, tuple) else [outs]


@pytest.mark.parametrize("per_use", [False, True])
def test_a_function_with_the_same_operations_wired_otherwise_gets_a_lift_of_its_own(per_use):
    LIFTED.clear()
    x = ca.SX.sym("x", 2)
    f1 = ca.Function("g", [x], [x[0] - 3.0 * x[1]])
    f2 = ca.Function("g", [x], [x[1] - 5.0 * x[0]])  # the same operation sequence, other operands
    ops = lambda f: [f.instruction_id(k) for k in range(f.n_instructions())]  # noqa: E731
    assert ops(f1) == ops(f2)
    p1, c1 = constants_as_parameters(f1, per_use=per_use)
    p2, c2 = constants_as_parameters(f2, per_use=per_use)
    assert p2 is not p1 and c1.tolist() == [3.0] and c2.tolist() == [5.0]
    point = np.array([0.7, -0.2])
    assert float(p2(point, c2)) == float(f2(point)) == -0.2 - 3.5
