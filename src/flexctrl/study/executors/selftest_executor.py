"""The ``_selftest`` executor: a damped oscillator simulated with numpy in a few milliseconds.

Its natural frequency follows the model's last link, the payload and the configuration,
its damping the controller file.  It needs no controller code, so it checks the runner,
the store, the report and a Dask cluster end to end; the test suite uses it.  Scene keys
(all optional): ``duration`` (s, 2), ``dt`` (s, 1e-3), ``amplitude`` (m, 0.01),
``noise_std`` (m, 0), ``sleep_s`` (s, 0: pretend to be slow), ``fail_payload`` (kg: raise
for that payload), ``warn_payload`` (kg: warn for that payload), ``crash_payload`` (kg: kill
the worker process for that payload; refused in the main process).  Controller keys:
``damping_ratio`` (-1..10, negative diverges), ``stiffness_gain`` (> -1).  Metrics:
``tip_residual_rms``, ``tip_peak``, ``settling_time``, ``frequency_hz``; trajectories ``t``,
``w`` (deflection, m), ``w_measured``, ``w_dot``.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from flexctrl.errors import SimulationError
from flexctrl.study.outputs import RunOutput, overrides_for, per_worker_cache


@dataclass(frozen=True)
class _SelftestScene:
    duration: float
    dt: float
    amplitude: float
    noise_std: float
    sleep_s: float
    fail_payload: float | None
    warn_payload: float | None
    crash_payload: float | None


@per_worker_cache(maxsize=32)
def _selftest_documents(
    scene: str,
    scene_overrides: tuple[str, ...],
    controller: str | None,
    controller_overrides: tuple[str, ...],
    digest_key: tuple,
) -> tuple[_SelftestScene, float, float]:
    from flexctrl.spec.overrides import apply_overrides
    from flexctrl.spec.reader import TableReader, read_toml

    doc = apply_overrides(read_toml(scene), scene_overrides, source=f"{scene} (overrides)")
    r = TableReader(doc, scene)
    parsed = _SelftestScene(
        duration=r.positive("duration", 2.0, unit="s"),
        dt=r.positive("dt", 1e-3, unit="s"),
        amplitude=r.positive("amplitude", 0.01, unit="m"),
        noise_std=r.nonnegative("noise_std", 0.0, unit="m"),
        sleep_s=r.number("sleep_s", 0.0, low=0.0, high=60.0, unit="s"),
        fail_payload=r.nonnegative("fail_payload", unit="kg") if r.has("fail_payload") else None,
        warn_payload=r.nonnegative("warn_payload", unit="kg") if r.has("warn_payload") else None,
        crash_payload=r.nonnegative("crash_payload", unit="kg") if r.has("crash_payload") else None,
    )
    r.string("source", "")
    r.finish()
    if parsed.duration / parsed.dt > 1e6:
        raise r.error(
            "dt", f"gives {parsed.duration / parsed.dt:.3g} samples; allowed: at most 1e6"
        )
    zeta, gain = 0.005, 0.0
    if controller is not None:
        doc = apply_overrides(
            read_toml(controller), controller_overrides, source=f"{controller} (overrides)"
        )
        c = TableReader(doc, controller)
        zeta = c.number("damping_ratio", low=-1.0, high=10.0)
        gain = c.number("stiffness_gain", 0.0, low=-1.0, low_open=True)
        c.string("source", "")
        c.string("type", "")
        c.finish()
    return parsed, zeta, gain


def _selftest_inputs(settings: Mapping[str, Any]):
    digests = settings.get("digests", {})
    return _selftest_documents(
        settings["scene"],
        tuple(overrides_for(settings, "scene")),
        settings.get("controller"),
        tuple(overrides_for(settings, "controller")),
        (digests.get("scene"), digests.get("controller")),
    )


@per_worker_cache(maxsize=8)
def _selftest_build(
    model: str, model_digest: str | None, model_overrides: tuple[str, ...]
) -> tuple[float, float]:
    """First clamped-free frequency (Hz) and modal mass (kg) of the model's last link; built once
    per worker."""
    from flexctrl.spec.arm import load_arm

    link = load_arm(model, overrides=model_overrides).links[-1]
    f0 = 1.8751**2 / (2 * math.pi * link.length**2) * math.sqrt(link.EI / link.mass_per_length)
    return f0, 0.25 * link.mass


def _in_main_process() -> bool:
    if multiprocessing.parent_process() is not None:
        return False
    try:
        from distributed import get_worker

        get_worker()
        return False
    except (ImportError, ValueError):
        return True


def _expm(a: np.ndarray) -> np.ndarray:
    """Matrix exponential of a small matrix: scaling and squaring of a 16-term Taylor series."""
    squarings = max(0, int(math.ceil(math.log2(max(np.abs(a).sum(axis=1).max(), 1e-300)))) + 1)
    scaled = a / 2.0**squarings
    term = np.eye(a.shape[0])
    result = term.copy()
    for k in range(1, 17):
        term = term @ scaled / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def execute(settings: dict) -> RunOutput:
    """The ``_selftest`` executor (see the module docstring)."""
    scene, zeta, gain = _selftest_inputs(settings)
    payload = float(settings["payload"])
    if scene.sleep_s:
        time.sleep(scene.sleep_s)
    if scene.fail_payload is not None and payload == scene.fail_payload:
        raise RuntimeError(
            f"selftest failure requested for payload {payload:g} kg (scene key fail_payload)"
        )
    if scene.warn_payload is not None and payload == scene.warn_payload:
        warnings.warn(
            f"selftest warning requested for payload {payload:g} kg (scene key warn_payload)",
            stacklevel=2,
        )
    if scene.crash_payload is not None and payload == scene.crash_payload:
        if _in_main_process():
            raise RuntimeError(
                "selftest crash requested, but the run is in the main process (--workers 0); "
                "refusing to exit"
            )
        os._exit(70)
    f0, modal_mass = _selftest_build(
        settings["model"],
        settings.get("digests", {}).get("model"),
        tuple(overrides_for(settings, "model")),
    )
    q = np.radians(np.asarray(settings["q0_deg"], dtype=float))
    shape = 1.0 + 0.2 * float(np.mean(np.cos(q[1:]))) if q.size > 1 else 1.0
    freq = f0 * math.sqrt(modal_mass / (modal_mass + payload)) * shape * math.sqrt(1.0 + gain)
    omega = 2 * math.pi * freq
    n = int(round(scene.duration / scene.dt)) + 1
    t = np.arange(n) * scene.dt
    phi = _expm(np.array([[0.0, 1.0], [-(omega**2), -2 * zeta * omega]]) * scene.dt)
    states = np.empty((n, 2))
    states[0] = (scene.amplitude * (1.0 + 0.5 * math.sin(q[0])), 0.0)
    limit = 1e3 * scene.amplitude
    for k in range(1, n):
        states[k] = phi @ states[k - 1]
        if abs(states[k, 0]) > limit:
            raise SimulationError(
                f"diverged: |w| exceeded {limit:g} m at t = {t[k]:.3f} s (damping ratio {zeta:g})"
            )
    rng = np.random.default_rng(settings["seed"])
    measured = states[:, 0] + scene.noise_std * rng.standard_normal(n)
    residual = measured[t >= scene.duration / 2]
    peak = float(np.max(np.abs(measured)))
    above = np.nonzero(np.abs(measured) > 0.05 * peak)[0]
    return RunOutput(
        metrics={
            "tip_residual_rms": float(np.sqrt(np.mean(residual**2))),
            "tip_peak": peak,
            "settling_time": float(t[above[-1]]) if above.size else 0.0,
            "frequency_hz": freq,
        },
        trajectories={"t": t, "w": states[:, 0], "w_measured": measured, "w_dot": states[:, 1]},
    )


def check_settings(settings: dict) -> None:
    """Validate the run's scene and controller documents (with overrides; memoised)."""
    _selftest_inputs(settings)
