"""An explicit cache for scene runs: models, references, integrators, runs and fidelity choices.

Building a model (symbolic derivation, modes, compilation) costs far more than most
runs, and a study worker or a fidelity chooser runs many scenes on the same arm.  What
is kept lives in a :class:`SceneCache` that its owner creates and passes down
(``run_scene(scene, cache=cache)``): nothing is cached in module globals, two owners
never share state by accident, and dropping the object frees everything.  A function
given no cache makes a fresh one for the call, so repeated work *within* that call is
still shared (the chooser's rungs, the design model reused as the plant).

Arrays handed out from the cache (a run's times and tip path) are read-only, so a
caller cannot change what the next caller gets.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

from flexctrl.spec.arm_scene import Modes


class SceneCache:
    """Least-recently-used stores, one per kind of thing kept.

    Parameters
    ----------
    maxsize : int
        Entries kept per kind (models, integrators, runs, choices); the least recently
        used is dropped beyond it.
    limits : dict, optional
        Another number for some kinds, e.g. ``{"models": 8}``.

    Examples
    --------
    >>> cache = SceneCache(maxsize=2)
    >>> cache.get("runs", "a", lambda: 1), cache.get("runs", "a", lambda: 2)
    (1, 1)
    >>> cache.stats()["runs"]
    {'entries': 1, 'hits': 1, 'misses': 1}
    >>> small = SceneCache(maxsize=2, limits={"models": 1})
    >>> [small.get(kind, k, lambda: k) for kind in ("models", "runs") for k in "abc"] and None
    >>> {kind: v["entries"] for kind, v in small.stats().items()}
    {'models': 1, 'runs': 2}
    """

    def __init__(self, maxsize: int = 64, limits: dict[str, int] | None = None):
        for name, size in {"maxsize": maxsize, **(limits or {})}.items():
            if isinstance(size, bool) or not isinstance(size, int) or size < 1:
                raise ValueError(f"{name} {size!r} is not allowed; allowed: a whole number >= 1")
        self.maxsize = maxsize
        #: entries kept per kind where it differs from ``maxsize`` (kinds that hold models hold the
        #: most memory)
        self.limits = dict(limits or {})
        self._stores: dict[str, OrderedDict[Hashable, Any]] = {}
        self._hits: dict[str, int] = {}
        self._misses: dict[str, int] = {}

    def get(self, kind: str, key: Hashable, build: Callable[[], Any]) -> Any:
        """The entry ``key`` of ``kind``, built by ``build()`` the first time.

        An exception raised by ``build()`` is not kept.
        """
        store = self._stores.setdefault(kind, OrderedDict())
        if key in store:
            store.move_to_end(key)
            self._hits[kind] = self._hits.get(kind, 0) + 1
            return store[key]
        value = build()
        self._misses[kind] = self._misses.get(kind, 0) + 1
        store[key] = value
        while len(store) > self.limits.get(kind, self.maxsize):
            store.popitem(last=False)
        return value

    def keep(self, kind: str, key: Hashable, value: Any, limit: int = 1) -> None:
        """Keep ``value`` under ``key`` for one :meth:`take`; ``limit`` entries of ``kind`` at most.

        The oldest is dropped beyond ``limit``.

        For large things worth reusing once, such as a whole run the next call will ask for.

        >>> cache = SceneCache()
        >>> cache.keep("whole", "a", 1); cache.keep("whole", "b", 2)
        >>> cache.take("whole", "a"), cache.take("whole", "b"), cache.take("whole", "b")
        (None, 2, None)
        """
        store = self._stores.setdefault(kind, OrderedDict())
        store[key] = value
        store.move_to_end(key)
        while len(store) > limit:
            store.popitem(last=False)

    def take(self, kind: str, key: Hashable) -> Any:
        """The value :meth:`keep` left under ``key`` (removed), or None."""
        store = self._stores.get(kind)
        value = None if store is None else store.pop(key, None)
        counts = self._hits if value is not None else self._misses
        counts[kind] = counts.get(kind, 0) + 1
        return value

    def drop(self, kind: str, keep: Hashable | None = None) -> None:
        """Forget every entry of ``kind`` but ``keep``."""
        store = self._stores.get(kind, OrderedDict())
        for key in [k for k in store if k != keep]:
            del store[key]

    def model(
        self,
        arm,
        fidelity: str,
        modes: Modes = "frozen",
        reference_q: tuple[float, ...] | None = None,
    ):
        """:func:`flexctrl.dynamics.build.build_model` of a (hashable) arm description, once."""
        # the model code loads when a model is first asked for: a SceneCache itself is light
        from flexctrl.dynamics.build import build_model

        reference_q = None if reference_q is None else tuple(float(a) for a in reference_q)
        key = (arm, str(fidelity), modes, reference_q)
        return self.get(
            "models",
            key,
            lambda: build_model(arm, str(fidelity), modes=modes, reference_q=reference_q),
        )

    def reference(
        self,
        arm,
        fidelity: str,
        modes: Modes,
        reference_q,
        path,
        deflection: str,
        compile: bool | None = False,
    ):
        """The reference trajectory of ``path`` on :meth:`model`'s model, built once.

        A :class:`~flexctrl.control.reference_trajectory.ReferenceTrajectory`.

        Keyed on the model's description, the joint path and the deflection (plain data), so
        the controllers designed on one model for one move share its tables (one per sample
        time): a table is a pure function of those and the sample time.
        """
        # the control layer loads when a reference is first asked for
        from flexctrl.control.reference_trajectory import ReferenceTrajectory

        reference_q = None if reference_q is None else tuple(float(a) for a in reference_q)
        key = (arm, str(fidelity), modes, reference_q, path, deflection, compile)
        return self.get(
            "references",
            key,
            lambda: ReferenceTrajectory(
                self.model(arm, fidelity, modes, reference_q), path, deflection, compile=compile
            ),
        )

    def integrator(
        self,
        arm,
        fidelity: str,
        modes: Modes,
        reference_q,
        integrator: str,
        dt: float,
        solver: tuple[tuple[str, Any], ...] = (),
    ):
        """A set-up integrator on :meth:`model`'s model and its setup time (s)."""
        # the integrators load when one is first asked for
        from flexctrl.sim import get_integrator

        def build():
            start = time.perf_counter()
            model = self.model(arm, fidelity, modes, reference_q)
            built = get_integrator(integrator)(model, dt, **dict(solver)).setup()
            return built, time.perf_counter() - start

        key = (
            arm,
            str(fidelity),
            modes,
            None if reference_q is None else tuple(reference_q),
            integrator,
            float(dt),
            tuple(solver),
        )
        return self.get("integrators", key, build)

    def clear(self) -> None:
        """Forget everything."""
        self._stores.clear()
        self._hits.clear()
        self._misses.clear()

    def stats(self) -> dict[str, dict[str, int]]:
        """Entries, hits and misses per kind."""
        kinds = sorted(set(self._stores) | set(self._misses))
        return {
            k: {
                "entries": len(self._stores.get(k, ())),
                "hits": self._hits.get(k, 0),
                "misses": self._misses.get(k, 0),
            }
            for k in kinds
        }


def read_only(*arrays):
    """The arrays, made read-only in place (a cached run's arrays are shared by every caller)."""
    for array in arrays:
        if array is not None:
            array.setflags(write=False)
    return arrays
