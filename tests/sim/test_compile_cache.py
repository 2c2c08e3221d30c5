"""The compiled-library cache loads only libraries that are the user's alone (a shared library
runs as its loader)."""

from __future__ import annotations

import os
import shutil
import stat

import casadi as ca
import pytest

from flexctrl.sim.compile import DEFAULT_FLAGS, cache_key, compile_function, find_compiler
from flexctrl.user_cache import trusted_file

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler")
OTHER_UID = 4242


def _function(factor: float, name: str = "scaled") -> ca.Function:
    x = ca.SX.sym("x")
    return ca.Function(name, [x], [factor * x])


def _plant(tmp_path, cache, name):
    """Plant a library computing 3 x where the library of ``name`` (2 x) is looked for; return its
    path.

    Each test uses its own function name: a process never opens the same library path twice
    (the dynamic loader would hand back the first one).
    """
    fun = _function(2.0, name)
    cache.mkdir(mode=0o700, exist_ok=True)
    path = cache / f"{name}_{cache_key(fun, DEFAULT_FLAGS, find_compiler())}.so"
    evil = compile_function(_function(3.0, name), cache_dir=tmp_path / "elsewhere")
    shutil.copyfile(evil.path, tmp_path / "planted.so")
    os.replace(tmp_path / "planted.so", path)
    return fun, path


def test_cache_folder_is_created_owner_only(tmp_path):
    cache = tmp_path / "new" / "cache"
    result = compile_function(_function(2.0, "fresh"), cache_dir=cache)
    assert result.compiled and result.path.parent == cache
    assert stat.S_IMODE(os.stat(cache).st_mode) == 0o700
    assert not os.stat(result.path).st_mode & (stat.S_IWGRP | stat.S_IWOTH)
    assert float(result.function(1.5)) == 3.0


def test_the_users_own_library_is_loaded_as_it_is(tmp_path):
    # the control of the next tests: a planted library that is the user's alone is loaded
    fun, path = _plant(tmp_path, tmp_path / "cache", "own")
    os.chmod(path, 0o700)
    loaded = compile_function(fun, cache_dir=tmp_path / "cache")
    assert loaded.cache_hit and loaded.path == path and float(loaded.function(1.0)) == 3.0


def test_a_library_others_can_write_is_rebuilt_not_loaded(tmp_path):
    fun, path = _plant(tmp_path, tmp_path / "cache", "writable")
    os.chmod(path, 0o777)
    assert not trusted_file(path)
    rebuilt = compile_function(fun, cache_dir=tmp_path / "cache")
    assert not rebuilt.cache_hit and rebuilt.path == path
    assert float(rebuilt.function(1.0)) == 2.0
    assert trusted_file(path)


@pytest.mark.skipif(os.geteuid() != 0, reason="changing a file's owner needs root")
def test_a_library_another_user_owns_is_rebuilt_not_loaded(tmp_path):
    fun, path = _plant(tmp_path, tmp_path / "cache", "foreign")
    os.chown(path, OTHER_UID, OTHER_UID)
    os.chmod(path, 0o700)
    rebuilt = compile_function(fun, cache_dir=tmp_path / "cache")
    assert not rebuilt.cache_hit and float(rebuilt.function(1.0)) == 2.0
    assert os.stat(path).st_uid == os.geteuid()


def test_a_cache_folder_others_can_write_is_not_used(tmp_path):
    cache = tmp_path / "shared"
    cache.mkdir()
    os.chmod(cache, 0o777)
    with pytest.warns(UserWarning, match="is not the user's alone"):
        result = compile_function(_function(2.0, "shared"), cache_dir=cache)
    assert result.compiled and result.path.parent != cache and not list(cache.iterdir())
    assert stat.S_IMODE(os.stat(result.path.parent).st_mode) == 0o700
    assert float(result.function(2.0)) == 4.0
