"""A study's grid expanded into runs: every combination of the axes' values, its settings.

:func:`expand_grid` is the product of the axes (and the replicates) over the fixed settings;
each run's settings name the executor, its files (absolute paths and digests), payload,
configuration, fidelity and overrides, and its seed is derived from the study's seed and the
run's identity (:mod:`flexctrl.study.hashing`).
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flexctrl.study.hashing import canonical_json, derive_seed, file_digest
from flexctrl.study.hashing import run_id as _run_id
from flexctrl.study.plan import FILE_SETTINGS, NO_CONTROLLER, Axis, RunSpec, toml_literal
from flexctrl.study.shared_choice import choice_settings, representative_combo
from flexctrl.study.study_values import JOINT, ReadContext


def axis_labels(
    ctx: ReadContext, axes: Sequence[Axis], fixed: dict[str, Any]
) -> dict[str | None, str]:
    """Display names of files in the table: the stem, or the relative path when stems collide."""
    paths = {v for a in axes if a.key in FILE_SETTINGS for v in a.values if v is not None}
    labels: dict[str | None, str] = {None: NO_CONTROLLER}
    stems = [Path(p).stem for p in paths]
    for p in paths:
        stem = Path(p).stem
        labels[p] = (
            stem
            if stems.count(stem) == 1 and stem != NO_CONTROLLER
            else Path(os.path.relpath(p, ctx.root)).as_posix()
        )
    return labels


def expand_grid(
    ctx: ReadContext,
    executor: str,
    seed: int,
    replicates: int,
    fixed: dict[str, Any],
    origin: dict[str, str],
    axes: list[Axis],
    per_controller: dict[str, dict[str, Any]] | None = None,
    share: tuple[str, ...] = (),
) -> tuple[tuple[RunSpec, ...], tuple[str, ...]]:
    """Every run of the grid, in grid order, and the table's coordinate columns.

    Raises
    ------
    SpecError
        For a run the settings cannot make (a joint the model lacks, an override of a file the
        run does not have, two runs with the same settings), naming the key it comes from.
    """
    labels = axis_labels(ctx, axes, fixed)
    all_axes = list(axes) + (
        [Axis("replicate", tuple(range(replicates)))] if replicates > 1 else []
    )
    keys, first = [a.key for a in all_axes], {a.key: a.values[0] for a in all_axes}
    by_combo: dict[str, dict[str, Any]] = {}
    runs: list[RunSpec] = []
    columns: dict[str, None] = {}
    ids: dict[str, int] = {}
    for index, combo in enumerate(itertools.product(*(a.values for a in all_axes))):
        values, coords = _values_and_coordinates(all_axes, combo, fixed, labels)
        _add_per_controller(values, origin, per_controller or {})
        settings = _run_settings(ctx, executor, values, origin, replicates)
        settings["seed"] = derive_seed(seed, _run_id(settings, ctx.root))
        if share:
            by_combo[canonical_json(list(combo))] = choice_settings(settings)
            rep = representative_combo(combo, keys, share, first)
            settings["choice_from"] = by_combo[canonical_json(list(rep))]
        rid = _run_id(settings, ctx.root)
        if rid in ids:
            raise ctx.error(
                "grid",
                f"runs {ids[rid] + 1} and {index + 1} have the same settings ({dict(coords)}); "
                "allowed: distinct grid points",
            )
        ids[rid] = index
        for column, _ in coords:
            columns.setdefault(column, None)
        runs.append(RunSpec(index, rid, tuple(coords), canonical_json(settings)))
    return tuple(runs), tuple(columns)


def _values_and_coordinates(all_axes, combo, fixed, labels):
    """The settings of one grid point and its table coordinates."""
    values = dict(fixed)
    coords: list[tuple[str, Any]] = []
    for axis, value in zip(all_axes, combo):
        values[axis.key] = value
        if axis.key in FILE_SETTINGS:
            coords.append((axis.key, labels[value]))
        elif axis.key == "configuration":
            coords += [(f"q{i + 1}", a) for i, a in enumerate(value)]
        else:
            coords.append((axis.key, value))
    return values, coords


def _add_per_controller(values, origin, per_controller) -> None:
    """The ``[per_controller.STEM]`` settings of the run's controller, as its overrides."""
    if not values.get("controller"):
        return
    stem = Path(values["controller"]).stem
    for name, value in per_controller.get(stem, {}).items():
        values[f"controller.{name}"] = value
        origin.setdefault(f"controller.{name}", f"per_controller.{stem}.{name}")


def _run_settings(ctx, executor, values, origin, replicates) -> dict[str, Any]:
    """The settings dict an executor receives for one run (its seed added by the caller)."""
    overrides = {k: v for k, v in values.items() if "." in k}
    payload, config = _payload_and_configuration(ctx, values, origin, overrides)
    _check_file_overrides(ctx, values, origin, overrides)
    settings: dict[str, Any] = {
        "executor": executor,
        "scene": values["scene"],
        "model": values.get("model"),
        "controller": values.get("controller"),
        "payload": None if payload is None else float(payload) + 0.0,
        "q0_deg": config,
        "fidelity": values.get("fidelity"),
        "overrides": sorted(f"{k}={toml_literal(v)}" for k, v in overrides.items()),
        "digests": {k: file_digest(values[k]) for k in FILE_SETTINGS if values.get(k)},
    }
    if replicates > 1:
        settings["replicate"] = values["replicate"]
    return settings


def _payload_and_configuration(ctx, values, origin, overrides):
    """The run's payload (kg) and joint angles (degrees): the model's, the grid's or fixed."""
    model_overrides = tuple(
        sorted(
            f"{k[len('model.') :]}={toml_literal(v)}"
            for k, v in overrides.items()
            if k.startswith("model.")
        )
    )
    if values.get("model") is None:  # an executor that needs no arm (the beam over supports)
        for k in values:
            if k.startswith("model.") or JOINT.match(k):
                raise ctx.error(
                    origin[k],
                    "needs a model file (joint angles and model overrides refer to an arm); "
                    "allowed: add 'model = ...' or drop this key",
                )
        return values.get("payload"), list(values.get("configuration") or [])
    model_key = (
        origin["model"]
        if not model_overrides
        else next(origin[k] for k in overrides if k.startswith("model."))
    )
    arm = ctx.arm(model_key, values["model"], model_overrides)
    config = values.get("configuration")
    if config is None:
        config = [math.degrees(a) + 0.0 for a in arm.configuration]
    elif len(config) != arm.n_links:
        raise ctx.error(
            origin["configuration"],
            f"configuration {config} has {len(config)} angles; the model '{arm.name}' has "
            f"{arm.n_links} joints",
        )
    config = list(config)
    for k, v in values.items():
        match = JOINT.match(k)
        if match:
            joint = int(match[1])
            if joint > arm.n_links:
                raise ctx.error(
                    origin[k],
                    f"joint {joint} does not exist; the model '{arm.name}' has {arm.n_links} "
                    "joints",
                )
            config[joint - 1] = v
    return values.get("payload", arm.payload.mass), config


def _check_file_overrides(ctx, values, origin, overrides) -> None:
    """Overrides of the scene and controller files apply to those files' documents."""
    if values.get("controller") is None and any(k.startswith("controller.") for k in overrides):
        key = next(origin[k] for k in overrides if k.startswith("controller."))
        raise ctx.error(
            key,
            "overrides a controller setting, but the run has no controller; allowed: a "
            "controller file, fixed or as an axis",
        )
    for target in ("scene", "controller"):
        stripped = tuple(
            f"{k[len(target) + 1 :]}={toml_literal(v)}"
            for k, v in overrides.items()
            if k.startswith(target + ".")
        )
        if stripped and values.get(target):
            key = next(origin[k] for k in overrides if k.startswith(target + "."))
            ctx.apply(key, values[target], stripped)


__all__ = ["axis_labels", "expand_grid"]
