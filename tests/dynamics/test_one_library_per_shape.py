"""One compiled library per model shape for every configuration: the long-substep plant step and the
output map.

A frozen-modes model bakes its modal constants (functions of the configuration) into its
graph; code generated from it would differ per configuration and every configuration of
a study would compile anew (about 28 s for ``amm:5``'s RK4 step and 29 s for its output
map here).  With the constants as an input the generated code must be the same for two
configurations, and the values the same as the model's own graph.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from support import MODEL

from flexctrl.dynamics.build import build_model
from flexctrl.dynamics.parametric import LIFTED, constants_as_parameters
from flexctrl.loop.plant_step import (
    UNROLL_LIMIT,
    _single_step,
    advance_function,
    output_map,
    plant_step_function,
)
from flexctrl.sim.integrator import output_function
from flexctrl.spec.arm import load_arm

CONFIGURATIONS = ([0, 0, 0], [0, 90, -90])  # degrees: the straight arm merges coinciding constants


@pytest.fixture(scope="module")
def models():
    arm = load_arm(MODEL).with_payload(2.0)
    return [
        build_model(arm, "amm:2", modes="frozen", reference_q=np.radians(q)) for q in CONFIGURATIONS
    ]


def code(fun: ca.Function) -> str:
    generator = ca.CodeGenerator("shared.c")
    generator.add(fun)
    return generator.dump()


def lift_anew(fun, per_use=False):
    """:func:`constants_as_parameters` of ``fun`` with no lift kept from another Function."""
    LIFTED.clear()
    return constants_as_parameters(fun, per_use=per_use)


def test_output_constants_per_use_give_one_structure_where_per_node_do_not(models):
    outputs = [output_function(m) for m in models]
    per_node = [lift_anew(f) for f in outputs]
    # the straight arm's graph has constants that coincide and were merged: fewer nodes, other code
    assert per_node[0][1].size != per_node[1][1].size
    per_use = [lift_anew(f, per_use=True) for f in outputs]
    assert per_use[0][1].size == per_use[1][1].size
    assert code(per_use[0][0]) == code(per_use[1][0])
    rng = np.random.default_rng(5)
    for f, (fp, c) in zip(outputs, per_use):
        X = rng.normal(0, 0.3, (f.size1_in(0), 7))
        a, b = np.array(f.map(7)(X)), np.array(fp.map(7)(X, c))
        assert np.array_equal(
            a, b
        )  # same operations in the same order: bit for bit in the virtual machine


def test_long_substep_step_is_shared_and_matches_the_unrolled_chain(models):
    substeps = UNROLL_LIMIT + 8
    texts = []
    for m in models:
        fp, c = lift_anew(m.functions["f"])
        assert c.size > 0
        texts.append(code(_single_step(m, fp, c.size)))
    assert texts[0] == texts[1]
    rng = np.random.default_rng(3)
    for m in models:
        x = np.concatenate([np.radians([10, 20, -30]), rng.normal(0, 1e-3, m.n_x - 3)])
        u = np.array([20.0, -5.0, 3.0])
        looped, _ = advance_function(m, substeps, compile=False)
        unrolled = plant_step_function(m, substeps)  # the model's own constants, no parameter
        a, b = np.array(looped(x, u, 2.5e-4)), np.array(unrolled(x, u, 2.5e-4))
        assert a.shape == (m.n_x, substeps)
        assert np.array_equal(a, b)
        assert not np.allclose(a[:, -1], x)  # the arm moved: the comparison is not trivial


def test_output_map_values_are_the_models_outputs(models):
    m = models[1]
    X = np.random.default_rng(2).normal(0, 0.3, (m.n_x, 5))
    Y = np.array(output_map(m, 5, compile=False)(X))
    assert np.array_equal(Y, np.array(output_function(m).map(5)(X)))
