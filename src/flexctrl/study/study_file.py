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

    [per_controller.mpc]                 # overrides of ONE controller of the study (its
    horizon = 30                         # file's stem, as in the table's controller column):
    "weights.torque" = 0.2               # only the runs with controllers/mpc.toml get them
                                         # (over any [set] value)

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
    lower_is_better = true               # default: the metric's own direction
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
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError, keyword_checked
from flexctrl.spec import shipped
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.reader import TableReader, read_toml
from flexctrl.spec.units import warn_if_radians
from flexctrl.study.grid_expansion import expand_grid
from flexctrl.study.hashing import canonical_json, file_digest
from flexctrl.study.plan import (
    MAX_RUNS,
    PLOTS,
    RESERVED_COLUMNS,
    SETTINGS,
    Axis,
    ReportSpec,
    StudySpec,
)
from flexctrl.study.registry import executor_names, get_executor
from flexctrl.study.study_values import (
    JOINT,
    ReadContext,
    check_override_key,
    flatten,
    nest_dotted_keys,
    setting_value,
    spell_like_file,
    string_list,
    unknown_axis,
)

# -- loading ---------------------------------------------------------------------------


@keyword_checked
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
    path = shipped.find(os.fspath(path), "study")
    source = str(path)
    document = nest_dotted_keys(read_toml(path), source)
    document = apply_overrides(
        document, [spell_like_file(document, o) for o in overrides], source=f"{source} (--set)"
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
    check_executor
        Also run the executor's ``check`` on every run's settings.
    """
    ctx = ReadContext(source, base_dir)
    r = TableReader(document, source)
    name, executor, seed, replicates, metrics = _read_header(r, default_name)
    fixed, origin = _read_fixed(ctx, r)
    per_controller = _per_controller(ctx, r.table_of("per_controller", {}))
    axes = _read_axes(ctx, r.table_of("grid", {}), fixed, origin)
    _check_required(ctx, r, executor, origin, axes)
    t = r.table_of("trajectories", {})
    keep = t.boolean("keep", True)
    decimation = t.integer("decimation", 1, low=1, high=1_000_000)
    t.finish()
    # grid axes whose values do not change a fidelity choice (study.shared_choice)
    auto = r.table_of("auto", {})
    share = string_list(auto, "share", [axis.key for axis in axes]) if auto.has("share") else ()
    auto.finish()
    report_reader = r.table_of("report", {})
    r.finish()
    n_runs = math.prod(len(a.values) for a in axes) * replicates
    if n_runs > MAX_RUNS:
        raise r.error("grid", f"has {n_runs} runs; allowed: at most {MAX_RUNS}")
    _check_controller_stems(ctx, per_controller, fixed, axes)
    runs, columns = expand_grid(
        ctx, executor, seed, replicates, fixed, origin, axes, per_controller, share
    )
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
        report=_read_report(report_reader, columns, metrics),
        runs=runs,
    )
    return _checked_by_executor(spec, source) if check_executor else spec


def _read_header(r: TableReader, default_name: str):
    """The study's name, executor, seed, replicates and metrics."""
    name = r.string("name", default_name)
    if not name or "/" in name or "\\" in name or name in (".", ".."):
        raise r.error(
            "name", f"value {name!r} is not allowed; allowed: a non-empty name without slashes"
        )
    executor = r.string("executor", "closed_loop", choices=executor_names())
    seed = r.integer("seed", 0, low=0, high=2**63 - 1)
    replicates = r.integer("replicates", 1, low=1, high=10_000)
    metrics = string_list(r, "metrics") if r.has("metrics") else None
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
    return name, executor, seed, replicates, metrics


def _read_fixed(ctx: ReadContext, r: TableReader) -> tuple[dict[str, Any], dict[str, str]]:
    """Fixed settings (named at the top level, KEY = VALUE in ``[set]``) and the key of each."""
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
            fixed[setting] = setting_value(ctx, setting, setting, value)
            origin[setting] = setting
    s = r.table_of("set", {})
    for name, value in flatten(s.table):
        key = f"set.{name}"
        check_override_key(ctx, key, name)
        fixed[name] = setting_value(ctx, key, name, value)
        origin[name] = key
    for raw_key in s.table:
        s.raw(raw_key)
    s.finish()
    return fixed, origin


def _read_axes(ctx: ReadContext, g: TableReader, fixed, origin) -> list[Axis]:
    """The ``[grid]`` axes, each value checked, none repeated or also fixed."""
    axes: list[Axis] = []
    for name, values in flatten(g.table):
        key = f"grid.{name}"
        if name not in SETTINGS and not JOINT.match(name):
            if "." not in name:
                raise unknown_axis(ctx, key, name)
            check_override_key(ctx, key, name)
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
        if name in fixed:
            raise ctx.error(
                key,
                f"'{name}' is both a fixed setting ({origin[name]}) and a grid axis; allowed: "
                "one of the two",
            )
        checked = tuple(
            setting_value(ctx, f"{key}[{i + 1}]", name, v) for i, v in enumerate(values)
        )
        if JOINT.match(name):
            warn_if_radians(checked, source=ctx.source, key=key)
        _check_distinct(ctx, key, values, checked)
        axes.append(Axis(name, checked))
        origin[name] = key
    for raw_key in g.table:
        g.raw(raw_key)
    g.finish()
    return axes


def _check_distinct(ctx: ReadContext, key: str, values: list, checked: tuple) -> None:
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


def _check_required(ctx, r: TableReader, executor: str, origin, axes) -> None:
    """A configuration axis is not mixed with joint axes; the files the executor needs are given."""
    if (
        "configuration" in origin
        and origin["configuration"].startswith("grid")
        and any(JOINT.match(a.key) for a in axes)
    ):
        raise ctx.error(
            origin["configuration"],
            "a configuration axis cannot be combined with single-joint axes (q1..qN); "
            "allowed: a fixed configuration with q<k> axes, or whole configurations",
        )
    needs_model = get_executor(executor, source=ctx.source).needs_model
    for required in ("scene", "model") if needs_model else ("scene",):
        if required not in origin:
            raise r.error(
                required,
                f"missing required key; allowed: the {required} file, as a fixed setting or a "
                "grid axis",
            )


def _checked_by_executor(spec: StudySpec, source: str) -> StudySpec:
    """Every run's settings checked by the executor; the metrics it cannot make recorded."""
    executor = get_executor(spec.executor, source=source)
    if executor.check is not None:
        for run in spec.runs:
            try:
                executor.check(run.settings)
            except SpecError as exc:
                coords = ", ".join(f"{k} = {v}" for k, v in run.coords) or "the only run"
                raise SpecError(
                    f"executor '{spec.executor}' refuses run {run.index + 1} ({coords}): {exc}",
                    source=source,
                ) from None
    if spec.metrics is None:
        return spec
    unavailable = tuple(
        (run.index, metric, reason)
        for run in spec.runs
        for metric, reason in executor.unavailable_metrics(run.settings).items()
        if metric in spec.metrics
    )
    return dataclasses.replace(spec, unavailable=unavailable)


def _per_controller(ctx: ReadContext, table: TableReader) -> dict[str, dict[str, Any]]:
    """``[per_controller.STEM]`` tables: ``{stem: {controller key: value}}``, values checked as
    plain data."""
    out: dict[str, dict[str, Any]] = {}
    for stem in list(table.table):
        sub_table = table.table_of(stem)
        out[stem] = {}
        for name, value in flatten(sub_table.table):
            key = f"per_controller.{stem}.{name}"
            out[stem][name] = setting_value(ctx, key, f"controller.{name}", value)
        sub_table.accept(*sub_table.table)
        sub_table.finish()
    table.finish()
    return out


def _check_controller_stems(
    ctx: ReadContext, per_controller: dict, fixed: dict[str, Any], axes: list[Axis]
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
                f"'{value}' is not a grid column; allowed: "
                f"{', '.join(columns) or '(the study has no axes)'}",
            )
        return value

    metric = r.string("metric") if r.has("metric") else None
    if metric is not None and metrics is not None and metric not in metrics:
        raise r.error(
            "metric", f"'{metric}' is not one of the study's metrics; allowed: {', '.join(metrics)}"
        )
    map_axes = None
    if r.has("map_axes"):
        map_axes = string_list(r, "map_axes", columns)
        if len(map_axes) != 2:
            raise r.error(
                "map_axes",
                f"value {list(map_axes)!r} names {len(map_axes)} columns; allowed: exactly 2",
            )
    spec = ReportSpec(
        metric=metric,
        lower_is_better=r.boolean("lower_is_better") if r.has("lower_is_better") else None,
        map_axes=map_axes,  # type: ignore[arg-type]
        facet=string_list(r, "facet", columns) if r.has("facet") else None,
        rank_by=column("rank_by", "controller"),
        group_by=column("group_by", "payload"),
        worst=r.integer("worst", 3, low=0, high=50),
        signals=string_list(r, "signals") if r.has("signals") else None,
        time=r.string("time", "t"),
        timing=string_list(r, "timing") if r.has("timing") else None,
        plots=string_list(r, "plots", PLOTS) if r.has("plots") else PLOTS,
    )
    r.finish()
    return spec
