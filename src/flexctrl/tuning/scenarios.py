"""A tuning file's scenarios as a study of the closed-loop executor, and the candidates' runs."""

from __future__ import annotations

import copy
import re

from flexctrl.errors import SpecError
from flexctrl.loop.metrics import JOINT_METRICS, METRICS
from flexctrl.spec.tuning import ParameterSpec, TuningSpec
from flexctrl.study.hashing import canonical_json, file_digest, run_id
from flexctrl.study.plan import RunSpec, StudySpec, toml_literal
from flexctrl.study.study_file import nest_dotted_keys, study_from_document

_JOINT_METRIC = re.compile(rf"^({'|'.join(JOINT_METRICS)})_[1-9][0-9]?$")


def scenario_study(spec: TuningSpec) -> StudySpec:
    """The ``[scenarios]`` table as a closed-loop study whose controller is the tuned file.

    Raises
    ------
    SpecError
        Naming the tuning file: a scenario table that names its own controller or another
        executor, an objective metric no closed loop produces, or a set with no scenario.
    """
    source = f"{spec.source} [scenarios]"
    document = nest_dotted_keys(copy.deepcopy(spec.scenarios), source)
    for key, allowed in (
        ("controller", "no key: the controller is the tuning's 'controller'"),
        ("executor", "no key, or 'closed_loop'"),
    ):
        value = document.get(key)
        if value is not None and not (key == "executor" and value == "closed_loop"):
            raise SpecError(
                f"value {value!r} is not allowed; allowed: {allowed}",
                source=spec.source,
                key=f"scenarios.{key}",
            )
    grid = document.get("grid", {})
    if isinstance(grid, dict) and "controller" in grid:
        raise SpecError(
            "a controller axis is not allowed; allowed: one controller, the tuning's 'controller'",
            source=spec.source,
            key="scenarios.grid.controller",
        )
    metric = spec.objective.metric
    if metric not in METRICS and not _JOINT_METRIC.match(metric):
        import difflib

        hint = difflib.get_close_matches(metric, METRICS, n=1)
        extra = f" (did you mean '{hint[0]}'?)" if hint else ""
        raise SpecError(
            f"value {metric!r} is not a closed-loop metric; allowed: {', '.join(METRICS)}, or "
            f"{'/'.join(JOINT_METRICS)}_<joint>{extra}",
            source=spec.source,
            key="objective.metric",
        )
    document["executor"] = "closed_loop"
    document["controller"] = str(spec.controller)
    document.setdefault("trajectories", {"keep": False})
    study = study_from_document(
        document, source, spec.base_dir, file_digest(spec.source), spec.name
    )
    if not study.runs:
        raise SpecError(
            "the scenario set is empty; allowed: at least one scenario",
            source=spec.source,
            key="scenarios",
        )
    return study


def candidate_overrides(
    parameters: tuple[ParameterSpec, ...], values: dict[str, float]
) -> list[str]:
    """The ``controller.KEY=VALUE`` overrides that make a candidate (integers written as
    integers)."""
    out = []
    for p in parameters:
        value = values[p.key]
        out.append(f"controller.{p.key}={toml_literal(int(value) if p.integer else float(value))}")
    return out


def candidate_runs(study: StudySpec, overrides: list[str]) -> list[RunSpec]:
    """The study's runs with the candidate's overrides added (each run keeps its scenario's seed).

    A scenario's own override of a tuned key gives way to the candidate's value.
    """
    tuned = {item.split("=", 1)[0] for item in overrides}
    runs = []
    for run in study.runs:
        settings = run.settings
        kept = [
            item for item in settings.get("overrides", []) if item.split("=", 1)[0] not in tuned
        ]
        settings["overrides"] = sorted(set(kept) | set(overrides))
        runs.append(
            RunSpec(run.index, run_id(settings, study.root), run.coords, canonical_json(settings))
        )
    return runs
