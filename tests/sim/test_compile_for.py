"""What is built from a kept lifted Function alone is kept with it (``compile_for``,
``FROM_LIFTED``).

A later configuration of one model shape gets the plant step, the output map's point, the
reference's compiled forces and the dynamics Jacobian without building, serializing or
loading them again, and with the same values to the last bit as a build from scratch.
"""

import gc
import weakref

import casadi as ca
import numpy as np
import pytest
from support import DATA

import flexctrl as fc
import flexctrl.sim.compile as compile_module
from flexctrl.control.reference_trajectory import path_functions
from flexctrl.dynamics import jacobians
from flexctrl.dynamics.build import build_model
from flexctrl.dynamics.parametric import FROM_LIFTED, ObjectMemo
from flexctrl.loop.plant_step import UNROLL_LIMIT, advance_function, output_map

POSES = ([0.0, 0.0, 0.0], [0.0, 1.2, -0.7], [0.0, 1.57, 0.0])


@pytest.fixture(scope="module")
def arm():
    return fc.load_arm(DATA / "models" / "subedi3link.toml")


@pytest.fixture
def compiles(monkeypatch):
    """The Functions compile_function is asked for, by name, in order."""
    asked = []
    real = compile_module.compile_function

    def counting(fun, **kwargs):
        asked.append(fun.name())
        return real(fun, **kwargs)

    monkeypatch.setattr(compile_module, "compile_function", counting)
    return asked


def _point(model, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.2, 0.2, model.n_x), rng.uniform(-5, 5, model.n_u)


def _everything(model):
    """The plant step over 3 substeps, the output map's point, the reference forces and the
    Jacobians, evaluated."""
    x, u = _point(model)
    advance, _ = advance_function(model, 3)
    outputs = output_map(model, 1, energies=False)
    reference = path_functions(model, None)["all"]
    rng = np.random.default_rng(1)
    args = [rng.uniform(-0.3, 0.3, n) for n in (model.n_u,) * 3 + (model.n_q - model.n_u,) * 3]
    values = [
        advance(x, u, 2e-4),
        outputs(x.reshape(-1, 1)),
        *reference(*args),
        *jacobians.jacobian_function(model, inputs=True, shared=True)(x, u),
    ]
    return [np.array(v, dtype=float) for v in values]


def test_a_later_configuration_builds_nothing_again_and_gets_the_same_bits(
    arm, compiles, monkeypatch
):
    keys = []
    real_key = jacobians.content_key
    monkeypatch.setattr(jacobians, "content_key", lambda *a: keys.append(a) or real_key(*a))
    FROM_LIFTED.clear()
    first = build_model(arm, "amm:2", reference_q=POSES[0])
    _everything(first)
    built = list(compiles)
    assert all(
        any(name.startswith(p) for name in built)
        for p in ("advance_p_", "reference_p_", "kinematic_outputs_p")
    ), built
    assert len(keys) == 1
    kept = {}
    for q in POSES[1:]:
        del compiles[:]
        model = build_model(arm, "amm:2", reference_q=q)
        kept[tuple(q)] = _everything(model)
        assert compiles == [], f"built again at {q}: {compiles}"
    assert len(keys) == 1  # the Jacobian's structure was not serialized again
    # the control: with nothing kept, the same configurations build everything and give the same
    # bits
    for q in POSES[1:]:
        FROM_LIFTED.clear()
        jacobians.SHARED.clear()
        del compiles[:]
        model = build_model(arm, "amm:2", reference_q=q)
        fresh = _everything(model)
        assert compiles, "a cleared memo must build again"
        assert len(fresh) == len(kept[tuple(q)])
        assert all(np.array_equal(a, b) for a, b in zip(fresh, kept[tuple(q)])), q


def test_switching_compilation_off_or_moving_the_cache_builds_anew(
    arm, compiles, monkeypatch, tmp_path
):
    FROM_LIFTED.clear()
    advance_function(build_model(arm, "amm:2", reference_q=POSES[0]), 3)
    monkeypatch.setenv("FLEXCTRL_NO_COMPILE", "1")
    del compiles[:]
    _, compiled = advance_function(build_model(arm, "amm:2", reference_q=POSES[1]), 3)
    assert not compiled and any(name.startswith("advance_p") for name in compiles)
    monkeypatch.delenv("FLEXCTRL_NO_COMPILE")
    monkeypatch.setenv("FLEXCTRL_CACHE", str(tmp_path / "elsewhere"))
    del compiles[:]
    _, compiled = advance_function(build_model(arm, "amm:2", reference_q=POSES[2]), 3)
    assert compiled and any(name.startswith("advance_p") for name in compiles)
    assert any(path.name.startswith("advance_p") for path in (tmp_path / "elsewhere").iterdir())


def test_each_step_count_gets_its_own_plant_step(arm):
    # the tag holds the step count: a kept 3-step advance must not serve 5 steps, nor the mapaccum
    # loop
    FROM_LIFTED.clear()
    counts = (3, 5, UNROLL_LIMIT + 1)
    models = [build_model(arm, "amm:2", reference_q=q) for q in POSES]
    x, u = _point(models[0])
    kept = [np.array(advance_function(m, n)[0](x, u, 1e-4)) for m, n in zip(models, counts)]
    FROM_LIFTED.clear()
    fresh = [
        np.array(advance_function(build_model(arm, "amm:2", reference_q=q), n)[0](x, u, 1e-4))
        for q, n in zip(POSES, counts)
    ]
    for n, a, b in zip(counts, kept, fresh):
        assert a.shape == (models[0].n_x, n) and np.array_equal(a, b), n


def test_a_failed_compilation_is_not_kept(arm, compiles, monkeypatch, tmp_path):
    # the same compiler fails once (a full disk, a killed build): that model gets the virtual
    # machine; the next model compiles instead of inheriting the fall-back
    FROM_LIFTED.clear()
    works = tmp_path / "works"
    script = tmp_path / "flaky-cc"
    script.write_text(
        f'#!/bin/sh\ncase "$*" in *--version*) exec {compile_module.find_compiler()} "$@";; esac\n'
        f'[ -f {works} ] && exec {compile_module.find_compiler()} "$@"\nexit 1\n'
    )
    script.chmod(0o755)
    monkeypatch.setenv("FLEXCTRL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", str(script))
    with pytest.warns(UserWarning):
        _, compiled = advance_function(build_model(arm, "amm:2", reference_q=POSES[0]), 3)
    assert not compiled
    works.touch()
    _, compiled = advance_function(build_model(arm, "amm:2", reference_q=POSES[1]), 3)
    assert compiled


def test_another_compiler_builds_anew(arm, compiles, monkeypatch, tmp_path):
    FROM_LIFTED.clear()
    advance_function(build_model(arm, "amm:2", reference_q=POSES[0]), 3)
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "mycc").symlink_to(compile_module.find_compiler())
    monkeypatch.setenv("CC", str(bin_dir / "mycc"))
    del compiles[:]
    advance_function(build_model(arm, "amm:2", reference_q=POSES[1]), 3)
    assert any(name.startswith("advance_p") for name in compiles)


def test_an_object_memo_holds_its_owner_and_tells_owners_apart():
    memo = ObjectMemo(2)
    a, b = ca.Function("a", [], []), ca.Function("b", [], [])
    assert memo.get(a, "t", lambda: 1) == 1
    assert memo.get(a, "t", lambda: 2) == 1
    assert memo.get(a, "other", lambda: 3) == 3
    assert memo.get(b, "t", lambda: 4) == 4  # the least recently used entry, (a, "t"), is forgotten
    assert memo.get(a, "t", lambda: 5) == 5


def test_an_object_memo_keeps_its_owner_alive_so_its_id_cannot_pass_on():
    class Owner:
        pass

    memo = ObjectMemo(4)
    owner = Owner()
    alive = weakref.ref(owner)
    memo.get(owner, "t", lambda: "value")
    del owner
    gc.collect()
    assert alive() is not None and memo.lookup(alive(), "t") == "value"
    assert memo.lookup(Owner(), "t") is None  # another object, whatever its id
