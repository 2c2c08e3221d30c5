"""Study files (``studies/*.toml``) as a frozen, validated :class:`StudySpec` with its runs.

A study is a grid of runs: the cartesian product of its axes, each run a plain
dict of settings handed to an *executor* (see :mod:`flexctrl.study.executors`).
:func:`load_study` validates everything a run needs (files exist and parse, the
model loads, configurations fit the model, the executor exists and accepts
every run's settings) and expands the grid, so a broken study is refused before
any run starts with a :class:`~flexctrl.errors.SpecError` naming the file and
the key.

File format (paths relative to the study file; angles in degrees; SI units)::

    name = "quickstart"                  # default: the file's stem
    executor = "closed_loop"             # a name from the executor registry (default)
    seed = 1                             # study seed; each run's seed derives from it
    replicates = 1                       # > 1 adds a 'replicate' axis (new seed each)
    metrics = ["tip_residual_rms"]       # optional: the table's metric columns
                                         # (then required of every run)
    # fixed settings (each may instead be an axis in [grid], not both)
    scene = "scenes/move_joint1_30deg.toml"
    model = "../models/subedi3link.toml"
    controller = "../controllers/pd.toml"   # "none": open loop; default none
    payload = 0.0                        # kg; default: the model file's
    configuration = [0, 0, 0]            # degrees; default: the model file's
    fidelity = "amm:2"                   # default: the model file's own modes

    [set]                                # fixed KEY=VALUE overrides of the files
    "scene.duration" = 3.0               # scene.KEY, controller.KEY or model.KEY

    [per_controller.mpc]                 # overrides of ONE controller of the study (its file's stem,
    horizon = 30                         # as in the table's controller column): only the runs with
    "weights.torque" = 0.2               # controllers/mpc.toml get them (over any [set] value)

    [grid]                               # axes: every key takes a list of values
    payload = [0.0, 2.0]
    configuration = [[0, 0, 0], [0, 90, 0]]
    q3 = [-90, 0, 90]                    # one joint (degrees), on top of configuration
    controller = ["../controllers/pd.toml", "../controllers/lqr.toml", "none"]
    fidelity = ["amm:1", "amm:2"]
    "scene.noise_std" = [0.0, 1e-4]      # any scene/controller/model key

    [trajectories]
    keep = true                          # store runs/<id>.npz
    decimation = 1                       # keep every n-th sample

    [report]
    metric = "tip_residual_rms"          # default: the first metric
    lower_is_better = true               # the worst cases are the largest values
    map_axes = ["q2", "q3"]              # heat-map axes (default q2, q3 if they vary)
    facet = ["payload", "controller"]    # one map per combination (default: other axes)
    rank_by = "controller"               # ranking of ... (default controller)
    group_by = "payload"                 # ... per value of (default payload)
    worst = 3                            # worst runs shown with trajectories
    signals = ["w"]                      # trajectories to plot (default: all but t)
    time = "t"                           # name of the time array
    timing = ["controller_time_median"]  # computing-time metrics (default: names
                                         # like controller_time*, solve_time*, ...)
    plots = ["maps", "ranking", "worst", "timing", "failures"]

Table columns of the grid coordinates: ``payload``, ``q1..qn`` (for a
``configuration`` axis) or ``q<k>``, ``controller``/``scene``/``model`` (the
file's stem), ``fidelity``, the override keys as written, ``replicate``.
"""

from __future__ import annotations

import dataclasses
import difflib
import itertools
import math
import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError
from flexctrl.spec import shipped
from flexctrl.spec.fidelity import parse_fidelity
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml
from flexctrl.spec.units import warn_if_radians
from flexctrl.study.hashing import canonical_json, derive_seed, file_digest
from flexctrl.study.hashing import run_id as _run_id
from flexctrl.study.plan import (
    FILE_SETTINGS,
    MAX_RUNS,
    NO_CONTROLLER,
    PLOTS,
    RESERVED_COLUMNS,
    SETTINGS,
    TARGETS,
    Axis,
    ReportSpec,
    RunSpec,
    StudySpec,
    toml_literal,
)

_JOINT = re.compile(r"^q([1-9][0-9]?)$")


class _Context:
    """Reading state: the study file, its folder and memoised model loads."""

    def __init__(self, source: str, root: Path):
        self.source = source
        self.root = root
        self._arms: dict[tuple, Any] = {}
        self._docs: dict[str, None] = {}
        self._applied: set[tuple] = set()

    def error(self, key: str, message: str) -> SpecError:
        return SpecError(message, source=self.source, key=key)

    def file(self, key: str, value: Any, role: str) -> str | None:
        """An existing, parseable TOML file (absolute path), or None for ``"none"`` controllers."""
        if role == "controller" and value == NO_CONTROLLER:
            return None
        if not isinstance(value, str) or not value:
            raise self.error(
                key,
                f"value {value!r} is not a file path; allowed: a path to a {role} TOML file "
                "relative to the study file" + (" or 'none'" if role == "controller" else ""),
            )
        path = (self.root / value).resolve()
        if not path.is_file():
            try:
                path = shipped.find(
                    value, role if role in shipped.FOLDERS else None, self.root
                ).resolve()
            except SpecError:
                near = ""
                if path.parent.is_dir():
                    hint = difflib.get_close_matches(
                        path.name, [p.name for p in path.parent.glob("*.toml")], n=1
                    )
                    near = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise self.error(
                    key, f"{role} file {value!r} not found (looked at '{path}'){near}"
                ) from None
        if str(path) not in self._docs:
            try:
                read_toml(path)
            except SpecError as exc:
                raise self.error(key, f"{role} file {value!r} is unreadable: {exc}") from None
            self._docs[str(path)] = None
        return str(path)

    def apply(self, key: str, path: str, overrides: tuple[str, ...]) -> None:
        """Check that ``overrides`` apply to the file's document (structure only)."""
        if (path, overrides) not in self._applied:
            try:
                apply_overrides(read_toml(path), overrides, source=path)
            except SpecError as exc:
                raise self.error(key, f"cannot be applied: {exc}") from None
            self._applied.add((path, overrides))

    def arm(self, key: str, model: str, overrides: tuple[str, ...]):
        from flexctrl.spec.arm import load_arm

        cache_key = (model, overrides)
        if cache_key not in self._arms:
            try:
                self._arms[cache_key] = load_arm(model, overrides=overrides)
            except SpecError as exc:
                raise self.error(key, f"model does not load: {exc}") from None
        return self._arms[cache_key]


def _setting_value(ctx: _Context, key: str, name: str, value: Any) -> Any:
    """Validate one value of a named setting (``payload``, ``scene``, ...)."""
    if name in FILE_SETTINGS:
        return ctx.file(key, value, name)
    if name == "payload":
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value < 0
        ):
            raise ctx.error(
                key, f"value {value!r} is not allowed; allowed: a finite number >= 0 (kg)"
            )
        return float(value) + 0.0
    if name == "configuration":
        if not isinstance(value, list) or not value:
            raise ctx.error(
                key,
                f"value {value!r} is not a configuration; allowed: a list of joint angles in "
                "degrees, e.g. [0, 90, 0]",
            )
        angles = [_angle(ctx, f"{key}[{i + 1}]", v) for i, v in enumerate(value)]
        warn_if_radians(angles, source=ctx.source, key=key)
        return angles
    if name == "fidelity":
        return str(parse_fidelity(value, source=ctx.source, key=key))
    if _JOINT.match(name):
        return _angle(ctx, key, value)
    try:
        canonical_json(value)
    except ValueError:
        raise ctx.error(
            key,
            f"value {value!r} is not plain data; allowed: numbers, strings, booleans, lists, tables",
        ) from None
    return value


def _angle(ctx: _Context, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ctx.error(key, f"value {value!r} is not an angle; allowed: a finite number (degrees)")
    return float(value) + 0.0


def _check_override_key(ctx: _Context, key: str, name: str) -> None:
    target, _, rest = name.partition(".")
    if target not in TARGETS:
        hint = difflib.get_close_matches(target, TARGETS, n=1)
        extra = f" (did you mean '{hint[0]}.{rest}'?)" if hint else ""
        raise ctx.error(
            key,
            f"'{target}' is not a file to override{extra}; allowed: {', '.join(t + '.KEY' for t in TARGETS)}",
        )
    if not rest or any(not part for part in rest.split(".")):
        raise ctx.error(
            key, "override key has an empty part; allowed: scene.KEY, controller.KEY, model.KEY"
        )


def _flatten(table: dict, prefix: str = "") -> Iterable[tuple[str, Any]]:
    for name, value in table.items():
        if isinstance(value, dict):
            yield from _flatten(value, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", value


def _unknown_axis(ctx: _Context, key: str, name: str) -> SpecError:
    known = list(SETTINGS) + ["q1", "q2", "q3"]
    hint = difflib.get_close_matches(name, known, n=1)
    extra = f"; did you mean '{hint[0]}'?" if hint else ""
    return ctx.error(
        key,
        f"unknown setting{extra} Allowed: {', '.join(SETTINGS)}, q1..qN (one joint, degrees), "
        "scene.KEY, controller.KEY, model.KEY",
    )


def _string_list(
    r: TableReader, name: str, allowed: Sequence[str] | None = None
) -> tuple[str, ...]:
    value = r.raw(name)
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise r.error(name, f"value {value!r} is not a list of names")
    if len(set(value)) != len(value):
        raise r.error(name, f"value {value!r} names an entry twice")
    if allowed is not None:
        for item in value:
            if item not in allowed:
                hint = difflib.get_close_matches(item, list(allowed), n=1)
                extra = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise r.error(
                    name,
                    f"'{item}' is not allowed{extra}; allowed: {', '.join(allowed) or '(none)'}",
                )
    return tuple(value)


# -- loading ---------------------------------------------------------------------------


def load_study(
    path: str | os.PathLike, overrides: Sequence[str] = (), *, check_executor: bool = True
) -> StudySpec:
    """Load, validate and expand a study file.

    Parameters
    ----------
    path
        The ``studies/*.toml`` file.
    overrides
        ``KEY=VALUE`` strings applied to the study document first (``--set``),
        e.g. ``"seed=2"`` or ``"grid.payload=[0, 1]"``.
    check_executor
        Also run the executor's ``check`` on every run's settings.

    Returns
    -------
    StudySpec
        With every run expanded, in grid order.

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed.
    """
    path = shipped.find(path, "study")
    source = str(path)
    document = nest_dotted_keys(read_toml(path), source)
    document = apply_overrides(
        document, [_spell_like_file(document, o) for o in overrides], source=f"{source} (--set)"
    )
    return study_from_document(
        document,
        source,
        path.resolve().parent,
        file_digest(path),
        path.stem,
        check_executor=check_executor,
    )


def study_from_document(
    document: dict[str, Any],
    source: str,
    base_dir: Path,
    sha256: str,
    default_name: str,
    *,
    check_executor: bool = True,
) -> StudySpec:
    """Validate and expand a parsed study document (:func:`load_study` without the file).

    Parameters
    ----------
    document
        The study's tables (quoted dotted keys already nested, overrides applied).
    source
        Where it came from, for messages (e.g. ``"studies/tune_lqr.toml [scenarios]"``).
    base_dir
        The folder relative paths are resolved against.
    sha256
        Digest recorded as the study's ``sha256``.
    default_name
        The study's name when the document gives none.
    """
    from flexctrl.study.registry import executor_names, get_executor

    ctx = _Context(source, base_dir)
    r = TableReader(document, source)

    name = r.string("name", default_name)
    if not name or "/" in name or "\\" in name or name in (".", ".."):
        raise r.error(
            "name", f"value {name!r} is not allowed; allowed: a non-empty name without slashes"
        )
    executor = r.string("executor", "closed_loop", choices=executor_names())
    seed = r.integer("seed", 0, low=0, high=2**63 - 1)
    replicates = r.integer("replicates", 1, low=1, high=10_000)
    metrics = _string_list(r, "metrics") if r.has("metrics") else None
    if metrics is not None:
        if not metrics:
            raise r.error(
                "metrics",
                "empty list; allowed: metric names, or leave the key out to keep every metric",
            )
        for metric in metrics:
            if metric in RESERVED_COLUMNS:
                raise r.error(
                    "metrics", f"'{metric}' is a column of the table already; allowed: other names"
                )

    # fixed settings, as named settings at the top level and KEY=VALUE in [set]
    fixed: dict[str, Any] = {}
    origin: dict[str, str] = {}
    for setting in SETTINGS:
        if r.has(setting):
            value = r.raw(setting)
            if isinstance(value, dict):
                raise r.error(
                    setting,
                    f"value {value!r} is a table; overrides of the {setting} file go in [set] as "
                    f'"{setting}.KEY" = VALUE',
                )
            fixed[setting] = _setting_value(ctx, setting, setting, value)
            origin[setting] = setting
    s = r.table_of("set", {})
    for name_, value in _flatten(s.table):
        key = f"set.{name_}"
        _check_override_key(ctx, key, name_)
        fixed[name_] = _setting_value(ctx, key, name_, value)
        origin[name_] = key
    for raw_key in s.table:
        s.raw(raw_key)
    s.finish()
    per_controller = _per_controller(ctx, r.table_of("per_controller", {}))

    # axes
    g = r.table_of("grid", {})
    axes: list[Axis] = []
    for name_, values in _flatten(g.table):
        key = f"grid.{name_}"
        if name_ not in SETTINGS and not _JOINT.match(name_):
            if "." not in name_:
                raise _unknown_axis(ctx, key, name_)
            _check_override_key(ctx, key, name_)
        if not isinstance(values, list):
            raise ctx.error(
                key,
                f"value {values!r} is not a list; allowed: a list of values, one per grid point",
            )
        if not values:
            raise ctx.error(
                key,
                "empty list: an axis needs at least one value (an empty axis makes an empty grid)",
            )
        if name_ in fixed:
            raise ctx.error(
                key,
                f"'{name_}' is both a fixed setting ({origin[name_]}) and a grid axis; allowed: "
                "one of the two",
            )
        checked = tuple(
            _setting_value(ctx, f"{key}[{i + 1}]", name_, v) for i, v in enumerate(values)
        )
        if _JOINT.match(name_):
            warn_if_radians(checked, source=ctx.source, key=key)
        seen: dict[str, int] = {}
        for i, v in enumerate(checked):
            text = canonical_json(v)
            if text in seen:
                raise ctx.error(
                    key,
                    f"value {values[i]!r} (entry {i + 1}) repeats entry {seen[text] + 1}; "
                    "allowed: distinct values",
                )
            seen[text] = i
        axes.append(Axis(name_, checked))
        origin[name_] = key
    for raw_key in g.table:
        g.raw(raw_key)
    g.finish()
    if (
        "configuration" in origin
        and origin["configuration"].startswith("grid")
        and any(_JOINT.match(a.key) for a in axes)
    ):
        raise ctx.error(
            origin["configuration"],
            "a configuration axis cannot be combined with single-joint axes (q1..qN); "
            "allowed: a fixed configuration with q<k> axes, or whole configurations",
        )
    needs_model = get_executor(executor, source=source).needs_model
    for required in ("scene", "model") if needs_model else ("scene",):
        if required not in origin:
            raise r.error(
                required,
                f"missing required key; allowed: the {required} file, as a fixed setting or a "
                "grid axis",
            )

    t = r.table_of("trajectories", {})
    keep = t.boolean("keep", True)
    decimation = t.integer("decimation", 1, low=1, high=1_000_000)
    t.finish()

    auto = r.table_of(
        "auto", {}
    )  # grid axes whose values do not change a fidelity choice (study.shared_choice)
    share = _string_list(auto, "share", [axis.key for axis in axes]) if auto.has("share") else ()
    auto.finish()
    report_reader = r.table_of("report", {})
    r.finish()

    n_runs = math.prod(len(a.values) for a in axes) * replicates
    if n_runs > MAX_RUNS:
        raise r.error("grid", f"has {n_runs} runs; allowed: at most {MAX_RUNS}")

    _check_controller_stems(ctx, per_controller, fixed, axes)
    runs, columns = _expand(
        ctx, executor, seed, replicates, fixed, origin, axes, per_controller, share
    )
    report = _read_report(report_reader, columns, metrics)
    spec = StudySpec(
        name=name,
        source=source,
        root=str(ctx.root),
        sha256=sha256,
        executor=executor,
        seed=seed,
        replicates=replicates,
        metrics=metrics,
        keep_trajectories=keep,
        decimation=decimation,
        fixed=tuple(fixed.items()),
        axes=tuple(axes),
        columns=columns,
        report=report,
        runs=runs,
    )
    if check_executor:
        check = get_executor(executor, source=source).check
        if check is not None:
            for run in runs:
                try:
                    check(run.settings)
                except SpecError as exc:
                    coords = ", ".join(f"{k} = {v}" for k, v in run.coords) or "the only run"
                    raise SpecError(
                        f"executor '{executor}' refuses run {run.index + 1} ({coords}): {exc}",
                        source=source,
                    ) from None
    if metrics is not None and check_executor:
        found = get_executor(executor, source=source)
        unavailable = tuple(
            (run.index, metric, reason)
            for run in runs
            for metric, reason in found.unavailable_metrics(run.settings).items()
            if metric in metrics
        )
        spec = dataclasses.replace(spec, unavailable=unavailable)
    return spec


def nest_dotted_keys(document: dict, source: str) -> dict:
    """``[grid]``/``[set]`` keys written quoted (``"scene.dt" = ...``) as nested tables
    (``scene.dt``).

    Both spellings are allowed in a study file; nesting them first gives one
    spelling, so ``--set grid.scene.dt=[...]`` replaces the file's axis instead
    of adding a second ``scene.dt`` beside it.
    """
    for section in ("grid", "set"):
        table = document.get(section)
        if not isinstance(table, dict):
            continue
        nested: dict[str, Any] = {}
        leaves = {
            key for key, value in table.items() if "." not in key and not isinstance(value, dict)
        }
        for key, value in table.items():
            parts = key.split(".")
            if len(parts) > 1 and parts[0] in leaves:
                # a file axis and an override of that file, e.g. grid.scene = [files] with
                # grid."scene.method" = [...]: TOML cannot nest both, so the override stays quoted
                nested[key] = value
                continue
            node = nested
            for part in parts[:-1]:
                child = node.setdefault(part, {})
                if not isinstance(child, dict):
                    raise SpecError(
                        f"'{key}' clashes with the key '{part}'; allowed: one spelling per setting",
                        source=source,
                        key=f"{section}.{key}",
                    )
                node = child
            if parts[-1] in node:
                raise SpecError(
                    f"'{key}' is given twice (quoted and as a nested table); allowed: one "
                    "spelling per setting",
                    source=source,
                    key=f"{section}.{key}",
                )
            node[parts[-1]] = value
        document[section] = nested
    return document


def _spell_like_file(document: dict, assignment: str) -> str:
    """Write a quoted ``--set`` key (``grid."scene.dt"=...``) nested when the file's key is nested.

    A quoted key stays quoted only where :func:`nest_dotted_keys` kept it quoted
    (a file axis beside an override of that file); elsewhere both spellings name the
    same setting.
    """
    key, sep, value = assignment.partition("=")
    if '"' not in key or not sep:
        return assignment
    head, _, rest = key.strip().partition(".")
    table = document.get(head)
    quoted = rest.strip('"')
    if (
        head in ("grid", "set")
        and rest.startswith('"')
        and isinstance(table, dict)
        and quoted not in table
    ):
        return f"{head}.{quoted}={value}"
    return assignment


def _labels(ctx: _Context, axes: Sequence[Axis], fixed: dict[str, Any]) -> dict[str | None, str]:
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


def _per_controller(ctx: _Context, table: TableReader) -> dict[str, dict[str, Any]]:
    """``[per_controller.STEM]`` tables: ``{stem: {controller key: value}}``, values checked as plain data."""
    out: dict[str, dict[str, Any]] = {}
    for stem in list(table.table):
        sub_table = table.table_of(stem)
        out[stem] = {}
        for name, value in _flatten(sub_table.table):
            key = f"per_controller.{stem}.{name}"
            out[stem][name] = _setting_value(ctx, key, f"controller.{name}", value)
        sub_table.accept(*sub_table.table)
        sub_table.finish()
    table.finish()
    return out


def _check_controller_stems(
    ctx: _Context, per_controller: dict, fixed: dict[str, Any], axes: list[Axis]
) -> None:
    """Every ``[per_controller.STEM]`` names a controller file of the study."""
    files = [fixed.get("controller")] + [v for a in axes if a.key == "controller" for v in a.values]
    stems = sorted({Path(f).stem for f in files if f})
    for stem in per_controller:
        if stem not in stems:
            hint = difflib.get_close_matches(stem, stems, n=1)
            extra = f" (did you mean '{hint[0]}'?)" if hint else ""
            raise ctx.error(
                f"per_controller.{stem}",
                f"'{stem}' is not a controller of the study{extra}; allowed: "
                f"the stem of a controller file of the study: {', '.join(stems) or '(none)'}",
            )


def _expand(
    ctx: _Context,
    executor: str,
    seed: int,
    replicates: int,
    fixed: dict[str, Any],
    origin: dict[str, str],
    axes: list[Axis],
    per_controller: dict[str, dict[str, Any]] | None = None,
    share: tuple[str, ...] = (),
) -> tuple[tuple[RunSpec, ...], tuple[str, ...]]:
    from flexctrl.study.shared_choice import choice_settings, representative_combo

    labels = _labels(ctx, axes, fixed)
    all_axes = list(axes) + (
        [Axis("replicate", tuple(range(replicates)))] if replicates > 1 else []
    )
    keys, first = [a.key for a in all_axes], {a.key: a.values[0] for a in all_axes}
    by_combo: dict[str, dict[str, Any]] = {}
    runs: list[RunSpec] = []
    columns: dict[str, None] = {}
    ids: dict[str, int] = {}
    for index, combo in enumerate(itertools.product(*(a.values for a in all_axes))):
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
        if values.get("controller"):
            stem = Path(values["controller"]).stem
            for name, value in (per_controller or {}).get(stem, {}).items():
                values[f"controller.{name}"] = value
                origin.setdefault(f"controller.{name}", f"per_controller.{stem}.{name}")
        overrides = {k: v for k, v in values.items() if "." in k}
        model_overrides = tuple(
            sorted(
                f"{k[len('model.') :]}={toml_literal(v)}"
                for k, v in overrides.items()
                if k.startswith("model.")
            )
        )
        if (
            values.get("model") is None
        ):  # an executor that needs no arm (e.g. the beam over supports)
            for k in values:
                if k.startswith("model.") or _JOINT.match(k):
                    raise ctx.error(
                        origin[k],
                        "needs a model file (joint angles and model overrides refer to an arm); "
                        "allowed: add 'model = ...' or drop this key",
                    )
            payload = values.get("payload")
            config = list(values.get("configuration") or [])
        else:
            model_key = (
                origin["model"]
                if not model_overrides
                else next(origin[k] for k in overrides if k.startswith("model."))
            )
            arm = ctx.arm(model_key, values["model"], model_overrides)
            payload = values.get("payload", arm.payload.mass)
            config = values.get("configuration")
            if config is None:
                config = [math.degrees(a) + 0.0 for a in arm.configuration]
            elif len(config) != arm.n_links:
                raise ctx.error(
                    origin["configuration"],
                    f"configuration {config} has {len(config)} angles; the model '{arm.name}' "
                    f"has {arm.n_links} joints",
                )
            config = list(config)
            for k, v in values.items():
                match = _JOINT.match(k)
                if match:
                    joint = int(match[1])
                    if joint > arm.n_links:
                        raise ctx.error(
                            origin[k],
                            f"joint {joint} does not exist; the model '{arm.name}' has "
                            f"{arm.n_links} joints",
                        )
                    config[joint - 1] = v
        controller = values.get("controller")
        if controller is None and any(k.startswith("controller.") for k in overrides):
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
                ctx.apply(
                    next(origin[k] for k in overrides if k.startswith(target + ".")),
                    values[target],
                    stripped,
                )
        settings: dict[str, Any] = {
            "executor": executor,
            "scene": values["scene"],
            "model": values.get("model"),
            "controller": controller,
            "payload": None if payload is None else float(payload) + 0.0,
            "q0_deg": config,
            "fidelity": values.get("fidelity"),
            "overrides": sorted(f"{k}={toml_literal(v)}" for k, v in overrides.items()),
            "digests": {k: file_digest(values[k]) for k in FILE_SETTINGS if values.get(k)},
        }
        if replicates > 1:
            settings["replicate"] = values["replicate"]
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


def _read_report(
    r: TableReader, columns: Sequence[str], metrics: tuple[str, ...] | None
) -> ReportSpec:
    def column(name: str, default: str | None) -> str | None:
        if not r.has(name):
            return default if default in columns else None
        value = r.string(name)
        if value not in columns:
            raise r.error(
                name,
                f"'{value}' is not a grid column; allowed: {', '.join(columns) or '(the study has no axes)'}",
            )
        return value

    metric = r.string("metric") if r.has("metric") else None
    if metric is not None and metrics is not None and metric not in metrics:
        raise r.error(
            "metric", f"'{metric}' is not one of the study's metrics; allowed: {', '.join(metrics)}"
        )
    map_axes = None
    if r.has("map_axes"):
        map_axes = _string_list(r, "map_axes", columns)
        if len(map_axes) != 2:
            raise r.error(
                "map_axes",
                f"value {list(map_axes)!r} names {len(map_axes)} columns; allowed: exactly 2",
            )
    spec = ReportSpec(
        metric=metric,
        lower_is_better=r.boolean("lower_is_better", True),
        map_axes=map_axes,  # type: ignore[arg-type]
        facet=_string_list(r, "facet", columns) if r.has("facet") else None,
        rank_by=column("rank_by", "controller"),
        group_by=column("group_by", "payload"),
        worst=r.integer("worst", 3, low=0, high=50),
        signals=_string_list(r, "signals") if r.has("signals") else None,
        time=r.string("time", "t"),
        timing=_string_list(r, "timing") if r.has("timing") else None,
        plots=_string_list(r, "plots", PLOTS) if r.has("plots") else PLOTS,
    )
    r.finish()
    return spec
