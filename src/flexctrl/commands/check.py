"""``flexctrl check FILE...``: validate descriptions without building or running anything.

Each file is read by the same reader that a run would use, chosen from what the file
holds (:func:`file_kind`; ``--kind`` names it instead):

* ``controller``: ``kind = "pd" | "lqr" | "mpc" | "nmpc" | "shaped"`` (or, its kind missing,
  ``sample_time``, ``[weights]``, ``[sensors]`` ...):
  :func:`flexctrl.spec.controller_reader.load_controller`;
* ``tuning``: ``[[parameters]]`` or ``[scenarios]``: :func:`flexctrl.spec.tuning.load_tuning` and
  its scenario study (:func:`flexctrl.tuning.scenarios.scenario_study`);
* ``model``: ``[[links]]`` or ``[[joints]]`` (:func:`flexctrl.spec.arm.load_arm`);
  ``kind = "rp_arm"`` with ``[link]``/``[housing]``, ``kind = "telescoping"`` with
  ``[outer]``/``[inner]`` (:mod:`flexctrl.spec.fem_models`);
* ``scene``: any other scene ``kind``, or ``model`` with ``dt``/``duration``
  (:func:`flexctrl.spec.scene.load_scene`, and a closed-loop scene's controller file);
* ``study``: ``scene``, ``[grid]``, ``[set]`` or ``executor``
  (:func:`flexctrl.study.study_file.load_study`, every run's settings checked by its executor).

Every file is checked (one failing file does not hide the next); each prints one line,
``FILE: ok (KIND ...)`` on stdout or the error on stderr, and the exit status is 0 when all
are valid, 2 when one is not.  Warnings (a degree field that looks like radians, a link
inertia far from the uniform link's) are printed as one line on stderr and do not fail
the check.  Scenes resolve their model and controller files, which are read too.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from flexctrl.errors import SpecError
from flexctrl.spec import shipped

FILE_KINDS = ("model", "scene", "controller", "study", "tuning")
_CONTROLLER_KEYS = ("sample_time", "weights", "sensors", "estimator", "horizon", "kp", "shaper")
_FEM_MODEL_TABLES = {
    "rp_arm": ("link", "housing", "base", "carriage"),
    "telescoping": ("outer", "inner", "contacts"),
}


def add_parser(subparsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "check",
        help="validate model, scene, controller, study and tuning files without running anything",
        description="Reads every FILE with the reader a run would use (its kind told from its "
        "keys, or --kind) and "
        "prints 'FILE: ok (...)' or its one-line error. Exit status 0 when every file is valid, "
        "2 otherwise. "
        "Warnings are printed as one line on stderr and do not fail the check.",
    )
    parser.add_argument(
        "files", nargs="+", metavar="FILE", help="TOML files, e.g. models/*.toml studies/*.toml"
    )
    parser.add_argument(
        "--kind",
        choices=FILE_KINDS,
        help="read every FILE as this kind (default: told from its keys)",
    )
    return parser


def file_kind(document: dict[str, Any]) -> str | None:
    """The kind of description a parsed TOML document is (see the module docstring), or None."""
    from flexctrl.spec.controller_settings import SETTINGS
    from flexctrl.spec.scene import SCENE_READERS

    kind = document.get("kind")
    if isinstance(kind, str) and kind in SETTINGS:
        return "controller"
    if "parameters" in document or "scenarios" in document:
        return "tuning"
    if "links" in document or "joints" in document:
        return "model"
    if isinstance(kind, str) and any(t in document for t in _FEM_MODEL_TABLES.get(kind, ())):
        return "model"
    if isinstance(kind, str) and kind in SCENE_READERS:
        return "scene"
    if any(k in document for k in ("grid", "set", "executor", "scene")):
        return "study"
    if "model" in document and ("dt" in document or "duration" in document):
        return "scene"
    if any(
        k in document for k in _CONTROLLER_KEYS
    ):  # a controller without its kind: told so by its reader
        return "controller"
    return None


def check_file(path: str | Path, kind: str | None = None) -> str:
    """Validate one file; returns a short description of what it is.

    Raises
    ------
    SpecError
        The file's first error, naming the file, the key, the value and what is allowed.
    """
    from flexctrl.spec.reader import read_toml

    path = shipped.find(path, None)
    source = str(path)
    document = read_toml(path)
    kind = kind or file_kind(document)
    if kind is None:
        raise SpecError(
            "cannot tell what the file describes; allowed: a model ([[links]], [[joints]]), a "
            "scene "
            "(kind, model, dt, duration), a controller (kind = 'pd', 'lqr', 'mpc', 'nmpc' or "
            "'shaped'), "
            "a study (scene, [grid]) or a tuning ([[parameters]], [scenarios]); or name it with "
            "--kind",
            source=source,
        )
    return _CHECKS[kind](path, document)


def _model(path, document) -> str:
    kind = document.get("kind")
    if kind in _FEM_MODEL_TABLES and "links" not in document:
        from flexctrl.spec.fem_models import load_rp_arm, load_telescoping

        spec = (load_rp_arm if kind == "rp_arm" else load_telescoping)(path)
        return f"{kind} model '{spec.name}'"
    from flexctrl.spec.arm import load_arm

    arm = load_arm(path)
    return f"model '{arm.name}', {arm.n_links} link{'s' if arm.n_links != 1 else ''}"


def _scene(path, document) -> str:
    from flexctrl.spec.scene import load_scene

    scene = load_scene(path)
    extra = ""
    if scene.kind == "closed_loop" and scene.controller is not None:
        from flexctrl.spec.controller_reader import load_controller

        extra = f", controller {load_controller(scene.controller).kind}"
    return f"{scene.kind} scene '{scene.name}'{extra}"


def _controller(path, document) -> str:
    from flexctrl.spec.controller_reader import load_controller

    return f"{load_controller(path).kind} controller"


def _study(path, document) -> str:
    from flexctrl.study.study_file import load_study

    spec = load_study(path)
    notes = "".join(f"; {note}" for note in spec.unavailable_notes())
    return f"study '{spec.name}', {len(spec.runs)} runs of '{spec.executor}'{notes}"


def _tuning(path, document) -> str:
    from flexctrl.spec.tuning import load_tuning
    from flexctrl.tuning.scenarios import scenario_study

    spec = load_tuning(path)
    study = scenario_study(spec)
    return (
        f"tuning '{spec.name}', {len(spec.parameters)} parameters over {len(study.runs)} scenarios"
    )


_CHECKS = {
    "model": _model,
    "scene": _scene,
    "controller": _controller,
    "study": _study,
    "tuning": _tuning,
}


def run(args: argparse.Namespace) -> int:
    failed = 0
    for name in args.files:
        try:
            print(f"{name}: ok ({check_file(name, args.kind)})")
        except SpecError as exc:
            failed += 1
            text = str(exc).replace("\n", " ")
            print(
                f"flexctrl check: error: {text if text.startswith(name) else f'{name}: {text}'}",
                file=sys.stderr,
            )
    return 2 if failed else 0
