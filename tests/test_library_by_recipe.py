"""A compiled library found on disk by what its Function is built from, before the Function is
built.

``compile_by_recipe`` must call ``build`` only when no library is linked under the recipe,
never load a library for another recipe, flags or name, and refuse an untrusted link; the
NMPC's horizon linearisation found that way must be the library a full build loads, and one
that does not reproduce the model must be removed and built again.
"""

from __future__ import annotations

import dataclasses
import os

import casadi as ca
import numpy as np
import pytest

import flexctrl.control.nmpc.interval as nmpc_interval
from flexctrl.control.nmpc.controller import design_nmpc
from flexctrl.dynamics.parametric import Memo
from flexctrl.sim.compile import ENV_CACHE, compile_by_recipe, find_compiler

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler")


def square_plus(name: str = "sq") -> ca.Function:
    x = ca.SX.sym("x", 2)
    return ca.Function(name, [x], [x * x + 1])


class Builds:
    """A ``build`` that counts its calls."""

    def __init__(self, fun: ca.Function):
        self.fun, self.calls = fun, 0

    def __call__(self) -> ca.Function:
        self.calls += 1
        return self.fun


def test_a_recipe_finds_its_library_without_building(tmp_path):
    first = Builds(square_plus())
    built = compile_by_recipe("sq", "recipe-1", first, cache_dir=tmp_path)
    assert first.calls == 1 and built.compiled and not built.cache_hit
    links = sorted(p.name for p in tmp_path.rglob("sq_r*.so"))
    assert len(links) == 1
    second = Builds(square_plus())
    found = compile_by_recipe("sq", "recipe-1", second, cache_dir=tmp_path)
    assert second.calls == 0 and found.compiled and found.cache_hit and found.path.name == links[0]
    assert os.path.samefile(found.path, built.path)  # a link to the library the build compiled
    point = [0.3, -1.7]
    assert np.array_equal(np.array(found.function(point)), np.array(built.function(point)))


def test_another_recipe_or_flags_build_again(tmp_path):
    compile_by_recipe("sq", "recipe-1", Builds(square_plus()), cache_dir=tmp_path)
    other = Builds(square_plus())
    compile_by_recipe("sq", "recipe-2", other, cache_dir=tmp_path)
    assert other.calls == 1
    portable = Builds(square_plus())
    compile_by_recipe("sq", "recipe-1", portable, cache_dir=tmp_path, flags=("-O1",))
    assert portable.calls == 1


def test_a_build_of_another_name_is_refused(tmp_path):
    with pytest.raises(ValueError, match="made 'other', not 'sq'"):
        compile_by_recipe("sq", "recipe-1", Builds(square_plus("other")), cache_dir=tmp_path)


def test_an_untrusted_link_is_built_again(tmp_path):
    built = compile_by_recipe("sq", "recipe-1", Builds(square_plus()), cache_dir=tmp_path)
    link = next(tmp_path.rglob("sq_r*.so"))
    os.chmod(link, 0o722)  # others may write it (and so the library it shares an inode with)
    again = Builds(square_plus())
    result = compile_by_recipe("sq", "recipe-1", again, cache_dir=tmp_path)
    assert built.compiled and again.calls == 1 and result.path != link


def test_a_found_library_that_fails_the_check_or_raises_in_it_is_unlinked_and_built(tmp_path):
    compile_by_recipe("sq", "recipe-1", Builds(square_plus()), cache_dir=tmp_path)
    link = next(tmp_path.rglob("sq_r*.so"))
    passing = Builds(square_plus())
    compile_by_recipe(
        "sq",
        "recipe-1",
        passing,
        cache_dir=tmp_path,
        check=lambda f: float(f([1.0, 2.0])[0]) == 2.0,
    )
    assert passing.calls == 0
    failing = Builds(square_plus())
    with pytest.warns(UserWarning, match="does not reproduce what it should"):
        compile_by_recipe("sq", "recipe-1", failing, cache_dir=tmp_path, check=lambda f: False)
    assert failing.calls == 1 and link.exists()  # unlinked, then linked again by the build

    def wrong_signature(f):
        return f([1.0, 2.0, 3.0])  # CasADi refuses a 3-vector for a 2-vector input

    raising = Builds(square_plus())
    with pytest.warns(UserWarning, match="the check raised"):
        compile_by_recipe("sq", "recipe-1", raising, cache_dir=tmp_path, check=wrong_signature)
    assert raising.calls == 1


def test_a_leftover_temporary_file_does_not_fail_a_build(tmp_path):
    first = compile_by_recipe("sq", "recipe-1", Builds(square_plus()), cache_dir=tmp_path)
    link = next(tmp_path.rglob("sq_r*.so"))
    # what a process killed between linking and renaming leaves: a link to the library under a name
    # of its own
    os.link(first.path, link.with_name(f"{link.name}.{os.getpid()}.tmp"))
    link.unlink()
    again = Builds(square_plus())
    result = compile_by_recipe("sq", "recipe-1", again, cache_dir=tmp_path)
    assert again.calls == 1 and result.compiled and link.exists()


def test_switched_off_compilation_builds_for_the_virtual_machine(tmp_path):
    build = Builds(square_plus())
    result = compile_by_recipe("sq", "recipe-1", build, cache_dir=tmp_path, enabled=False)
    assert build.calls == 1 and not result.compiled and not list(tmp_path.rglob("*.so"))


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """An empty library cache, and no linearisation kept in this process."""
    monkeypatch.setenv(ENV_CACHE, str(tmp_path))
    monkeypatch.setattr(nmpc_interval, "_BUILT", Memo(nmpc_interval.MEMO_SIZE))
    return tmp_path


def linmap_at_a_point(ctrl) -> list[np.ndarray]:
    lay = ctrl.layout
    rng = np.random.default_rng(5)
    Z, V = rng.normal(0, 0.2, (lay.n, lay.N)), rng.normal(0, 0.2, (lay.m, lay.N))
    return [
        np.array(a, dtype=float) for a in ctrl.functions["linmap"](Z, V, ctrl.functions["params"])
    ]


SMALL = dict(compile=True, horizon=6, sample_time=0.02, deflection_limit=0.02)


def test_an_nmpc_linearization_is_found_by_its_recipe_and_is_the_built_one(
    onelink, fresh_cache, monkeypatch
):
    from flexctrl.spec.controller_settings import NMPCSettings

    model, op = onelink
    settings = NMPCSettings(**SMALL)
    built = design_nmpc(model, op, settings)
    assert built.functions["build"]["cache_hit"] is False
    monkeypatch.setattr(
        nmpc_interval, "_BUILT", Memo(nmpc_interval.MEMO_SIZE)
    )  # as a new worker process

    def no_symbolic_build(*args, **kwargs):
        raise AssertionError("the linearisation was built although its library is on disk")

    monkeypatch.setattr(nmpc_interval, "symbolic_linearization", no_symbolic_build)
    found = design_nmpc(model, op, settings)
    assert found.functions["build"]["cache_hit"] is True
    for a, b in zip(linmap_at_a_point(found), linmap_at_a_point(built)):
        np.testing.assert_array_equal(a, b)


def test_a_library_that_does_not_reproduce_the_model_is_removed_and_built_again(
    onelink, fresh_cache, monkeypatch
):
    from flexctrl.spec.controller_settings import NMPCSettings

    model, op = onelink
    settings = NMPCSettings(**SMALL)
    design_nmpc(model, op, settings)
    link = next(fresh_cache.rglob("nmpc_linearize_*_r*.so"))
    # a stale library under the link's name: the same symbol, another model (the dynamics doubled)
    other = dataclasses.replace(settings, sample_time=0.04)
    monkeypatch.setattr(nmpc_interval, "_BUILT", Memo(nmpc_interval.MEMO_SIZE))
    stale = design_nmpc(model, op, other)
    stale_library = next(p for p in fresh_cache.rglob("nmpc_linearize_*_r*.so") if p != link)
    stale_inode = os.stat(stale_library).st_ino
    os.replace(stale_library, link)
    monkeypatch.setattr(nmpc_interval, "_BUILT", Memo(nmpc_interval.MEMO_SIZE))
    with pytest.warns(UserWarning, match="does not reproduce what it should"):
        rebuilt = design_nmpc(model, op, settings)
    monkeypatch.setattr(nmpc_interval, "_BUILT", Memo(nmpc_interval.MEMO_SIZE))
    monkeypatch.setenv("FLEXCTRL_CACHE", str(fresh_cache.parent / "another_cache"))
    reference = design_nmpc(model, op, settings)  # built anew in an empty cache
    for a, b in zip(linmap_at_a_point(rebuilt), linmap_at_a_point(reference)):
        np.testing.assert_array_equal(a, b)
    # the build linked the right library in the stale one's place (checked by file: this process has
    # the
    # stale one loaded under the link's path, and the loader would hand it back for that path)
    assert link.exists() and os.stat(link).st_ino != stale_inode
    content = [p for p in fresh_cache.rglob("nmpc_linearize_*.so") if "_r" not in p.name]
    assert any(os.path.samefile(link, p) for p in content)
    assert stale.functions["build"]["n_constants"] == rebuilt.functions["build"]["n_constants"]


def test_an_edit_to_the_code_that_builds_it_builds_it_again(onelink, fresh_cache, monkeypatch):
    from flexctrl.spec.controller_settings import NMPCSettings

    model, op = onelink
    settings = NMPCSettings(**SMALL)
    design_nmpc(model, op, settings)
    calls = []
    symbolic = nmpc_interval.symbolic_linearization
    monkeypatch.setattr(
        nmpc_interval,
        "symbolic_linearization",
        lambda *a, **k: calls.append(1) or symbolic(*a, **k),
    )
    monkeypatch.setattr(nmpc_interval, "_BUILT", Memo(nmpc_interval.MEMO_SIZE))
    design_nmpc(model, op, settings)
    assert calls == []  # found by its recipe
    monkeypatch.setattr(
        nmpc_interval, "builder_source_digest", lambda: "the builder's source, edited"
    )
    monkeypatch.setattr(nmpc_interval, "_BUILT", Memo(nmpc_interval.MEMO_SIZE))
    design_nmpc(model, op, settings)
    assert calls == [1]


def test_the_builder_digest_covers_the_interval_rk4_and_lift_modules_as_imported():
    """The digest is of the three modules' files as they were when this process imported them."""
    import hashlib
    from pathlib import Path

    from flexctrl.dynamics import parametric
    from flexctrl.sim import rk4

    digest = hashlib.sha256()
    for module in (nmpc_interval, rk4, parametric):
        digest.update(Path(module.__file__).read_bytes())
    assert nmpc_interval.builder_source_digest() == digest.hexdigest()
