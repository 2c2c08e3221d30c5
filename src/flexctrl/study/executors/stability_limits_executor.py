"""The ``stability_limits`` study executor: the largest stable step of each integrator on each
model.

One run = one integrator on one model: the run's scene (``kind = "arm"``)
gives the arm file, payload, gravity, damping, fidelity and integrator, with
the study's settings taking precedence (``model``, ``payload``, ``fidelity``,
``configuration`` as the joint angles); the integrator is usually the grid axis
``"scene.integrator"`` (an override of the scene), so one scene file serves
every integrator and the study's table gets an ``scene.integrator`` column.

The run builds the model, puts it in static equilibrium at the joint angles
with the holding torques (:func:`flexctrl.linear.equilibrium`: elastic
coordinates at their static deflection, joints free to move under constant
torque) and calls :func:`flexctrl.analysis.stability.step_search.largest_stable_step`.
The scene's initial rates, elastic coordinates, torque input, ``dt`` and
``duration`` are not used: a stability probe needs a steady state to perturb
(the free-vibration scene's arm falls away from its initial state within tens
of milliseconds, so its Jacobian there predicts nothing for long).  Only the
fixed-step integrators ``rk4``, ``euler`` and ``newmark`` are accepted: for an
adaptive one the output interval is not a step.

Metrics (SI units; all finite, as the study runner requires)
    ``omega_max``            max ``|lambda|`` of ``df/dx`` at the equilibrium, rad/s
    ``omega_max_model``      the model's own ``omega_max`` (at the build configuration, no static
    deflection), rad/s ``h_measured``           largest step found stable, s (the cap when stable at
    every tested step; 0 when unstable at every one) ``h_unstable``           smallest step found
    unstable, s (absent when none was) ``h_theory``             theoretical limit, s (absent when
    unbounded: then ``theory_unbounded`` = 1) ``theory_unbounded``     1 when every step is stable
    in theory (Newmark), else 0 ``ratio``                ``h_measured / h_theory`` (absent when
    undefined) ``omega_h_measured``     ``omega_max * h_measured`` ``omega_h_theory``
    ``omega_max * h_theory`` (absent when unbounded) ``outcome_code``         0 bracketed, 1 stable
    at every tested step (up to the cap), 2 unstable at every tested step (down to the floor)
    ``failure_code``         why the smallest unstable step failed: 0 a mode grew, 1 the run
    diverged, 2 the method's solver (Newton) failed; absent when none did ``h_cap``, ``h_floor``
    the search range, s ``limiting_omega``, ``limiting_zeta``   ``|lambda|`` (rad/s) and
    ``-Re(lambda)/|lambda|`` of the eigenvalue that limits the theory ``n_modes``, ``n_probes``,
    ``probe_steps``, ``growth_tolerance``, ``equilibrium_residual`` (max ``|f|``, SI)

Trajectories: ``probe_h`` (s), ``probe_stable`` (1/0) and ``probe_growth``
(largest modal amplitude ratio; inf for a diverged probe), in the order run.

Report (``report_sections``): writes ``stability_limits.csv`` with the columns
``integrator, fidelity, omega_max, h_measured, h_theory`` first (one row per
run; ``h_theory`` is ``inf`` when unbounded, empty without a theory or for a
failed run), then ``ratio, omega_h_measured, omega_h_theory, h_unstable,
outcome, note`` and any other grid columns; draws
``figures/stability_limits.png`` (h against omega_max on log axes with the
RK4 lines ``2 sqrt 2 / omega`` and ``2.785 / omega``) and a Markdown table.
It reads only the result folder (``results.csv`` rows and ``runs/<id>.json``
records), so ``flexctrl report DIR`` redraws it; the table, figure and text are
:mod:`flexctrl.analysis.stability.limits_report`'s.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
from pathlib import Path
from typing import Any

from flexctrl.analysis.stability.limits_report import (
    CSV_COLUMNS,
    EXTRA_COLUMNS,
    KNOWN_METRICS,
    draw_limits,
    limits_row,
    markdown_lines,
    probe_histories,
    result_metrics,
)
from flexctrl.analysis.stability.step_search import largest_stable_step
from flexctrl.dynamics.build import build_model
from flexctrl.errors import SpecError
from flexctrl.linear import equilibrium
from flexctrl.scenes.arm_setup import scene_arm
from flexctrl.spec.reader import read_toml
from flexctrl.spec.scene import ArmScene, load_scene
from flexctrl.study.outputs import RunOutput, overrides_for, per_worker_cache, scene_overrides
from flexctrl.study.plan import SETTINGS
from flexctrl.study.store import ResultStore, atomic_write

#: Integrators this executor measures (fixed-step methods with a theory).
METHODS = ("rk4", "euler", "newmark")


def _scene(settings: dict):
    source = str(settings["scene"])
    if overrides_for(settings, "model"):
        raise SpecError(
            f"model overrides {overrides_for(settings, 'model')} are not supported by the "
            "stability_limits executor; allowed: scene.KEY overrides (payload, damping, "
            "gravity, fidelity, integrator)",
            source=source,
            key="model",
        )
    scene = load_scene(settings["scene"], scene_overrides(settings))
    if scene.kind != "arm":
        raise SpecError(
            f"scene kind '{scene.kind}' is not allowed; allowed: kind = \"arm\"",
            source=source,
            key="kind",
        )
    if scene.fidelity.kind not in ("rigid", "amm", "fem"):
        raise SpecError(
            f"fidelity '{scene.fidelity}' is not allowed here; allowed: 'rigid', 'amm:N' or "
            "'fem:N' (a model of its own per run: the study compares fidelities)",
            source=source,
            key="fidelity",
        )
    if scene.integrator not in METHODS:
        raise SpecError(
            f"integrator '{scene.integrator}' is not allowed here; allowed: "
            f"{', '.join(map(repr, METHODS))} (fixed-step methods: an adaptive one has no step "
            "to limit)",
            source=source,
            key="integrator",
        )
    return scene


def check_settings(settings: dict) -> None:
    """Validate one run before the study starts (scene with overrides, integrator, model
    overrides)."""
    _scene(settings)


@per_worker_cache(maxsize=8)
def _build(model_key: tuple, scene_source: str):
    """The model and its equilibrium, once per worker per distinct arm (integrators share them)."""
    fields = dict(model_key)
    scene = ArmScene(
        name="stability",
        model=Path(fields["model"]),
        fidelity=fields["fidelity"],
        dt=1.0,
        duration=1.0,
        modes=fields["modes"],
        payload=fields["payload"],
        gravity=fields["gravity"],
        q0=fields["q0"],
        zeta=fields["zeta"],
        friction=fields["friction"],
        source=scene_source,
    )
    arm = scene_arm(scene)
    q0 = scene.q0 if scene.q0 is not None else tuple(arm.configuration)
    model = build_model(arm, scene.fidelity, modes=scene.modes, reference_q=q0)
    return model, equilibrium(model, q0), dataclasses.replace(scene, q0=q0)


def _model_key(scene, settings: dict) -> tuple:
    return (
        ("model", str(scene.model)),
        ("digest", settings.get("digests", {}).get("model")),
        ("fidelity", scene.fidelity),
        ("modes", scene.modes),
        ("payload", scene.payload),
        ("gravity", scene.gravity),
        ("q0", scene.q0),
        ("zeta", scene.zeta),
        ("friction", scene.friction),
    )


def execute(settings: dict) -> RunOutput:
    """Measure one integrator's largest stable step on one model (see the module docstring)."""
    scene = _scene(settings)
    model, op, _ = _build(_model_key(scene, settings), str(settings["scene"]))
    options = {k: v for k, v in scene.solver.items() if k != "chunk"}
    result = largest_stable_step(model, scene.integrator, op.x, op.u, integrator_options=options)
    return RunOutput(
        metrics=result_metrics(result, float(model.omega_max)),
        trajectories=probe_histories(result),
    )


# -- report ---------------------------------------------------------------------------


def _run_facts(directory: Path, row: dict) -> tuple[str, str, str, dict]:
    """Integrator, fidelity, scene label and every metric of a row, from its grid columns and its
    record.

    The record (``runs/<id>.json``) holds every metric even when the study's
    ``metrics`` list keeps some out of ``results.csv``.
    """
    integrator = row.get("scene.integrator")
    fidelity = row.get("fidelity")
    scene_label = row.get("scene") or ""
    record = ResultStore(directory).read_record(str(row.get("run_id"))) or {}
    metrics = {k: v for k, v in (record.get("metrics") or {}).items() if v is not None}
    metrics.update({k: v for k, v in row.items() if v is not None})
    if integrator is None or fidelity is None or not scene_label:
        settings = record.get("settings", {})
        scene_path = settings.get("scene")
        scene_label = scene_label or (Path(scene_path).stem if scene_path else "")
        fidelity = fidelity or settings.get("fidelity")
        for item in settings.get("overrides", []):
            if item.startswith("scene.integrator="):
                integrator = integrator or json.loads(item.split("=", 1)[1])
        if (integrator is None or fidelity is None) and scene_path:
            try:
                doc = read_toml(scene_path)
                integrator = integrator or doc.get("integrator", "rk4")
                fidelity = fidelity or doc.get("fidelity", "amm:2")
            except (SpecError, OSError):
                pass
    return str(integrator or "?"), str(fidelity or "?"), str(scene_label), metrics


def _other_columns(rows: list[dict]) -> list[str]:
    """The study's own grid columns that the table carries beside its own."""
    skip = set(CSV_COLUMNS) | set(EXTRA_COLUMNS) | set(KNOWN_METRICS)
    skip |= {"scene.integrator", "seed", "error", "wall_time_s", "peak_memory_mb"}
    skip |= {"bytes_written", "worker", "run_id", "status"}
    return [
        c
        for c in (rows[0] if rows else {})
        if c not in skip and (c in SETTINGS or "." in c or c.startswith("q") or c == "replicate")
    ]


def stability_rows(directory: Path, rows: list[dict]) -> tuple[list[str], list[dict[str, Any]]]:
    """The ``stability_limits.csv`` table (columns, rows) from the study table's rows."""
    other = _other_columns(rows)
    out = []
    for original in rows:
        integrator, fidelity, scene_label, row = _run_facts(directory, original)
        entry = limits_row(integrator, fidelity, scene_label, row)
        for column in other:
            value = row.get(column)
            entry[column] = "" if value is None else value
        out.append(entry)
    return list(CSV_COLUMNS) + list(EXTRA_COLUMNS) + other, out


def report_sections(directory: Path, rows: list[dict], figures: Path) -> list[str]:
    """Write ``stability_limits.csv`` and ``figures/stability_limits.png``; the Markdown lines."""
    directory = Path(directory)
    columns, table = stability_rows(directory, rows)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(table)
    atomic_write(directory / "stability_limits.csv", text.getvalue().encode())
    lines = ["## Largest stable step (stability_limits)", "", *markdown_lines(table)]
    if any(e["omega_max"] for e in table):
        name = "stability_limits.png"
        draw_limits(figures / name, table)
        lines += ["", f"![largest stable step]({figures.name}/{name})"]
    return lines
