"""Controller descriptions (``controllers/*.toml``) read into the typed settings of
:mod:`flexctrl.spec.controller_settings`.

Every file has ``kind = "pd" | "lqr" | "mpc" | "nmpc" | "shaped"``, optional free-text
``name``, ``notes`` and ``source``, the controller's scalar keys and sub-tables
(``[weights]``, ``[sensors]``, ``[estimator]``, ``[schedule]``, ``[osqp]``, ``[pd]``,
``[constraints]``: :mod:`flexctrl.spec.mpc_constraints`).
Angles and angular rates are in **degrees** (deg, deg/s) as everywhere in the files,
and every key that holds one says so in its name (``joint_deg``, ``joint_rate_deg_s``,
``joints_deg``, ``q2_deg``): the settings classes hold the same quantities in radians
under the plain names (``Weights.joint``), so no name means two units.  The old
spellings (``joint``, ``joint_rate``, ``joints``, ``joint_rates``, ``q2``) are refused
with a message naming the new key.  Gains are per radian (N m/rad, N m s/rad).  Errors name the
file, the dotted key, the value and what is allowed; unknown keys are rejected with a "did you
mean".  LQR and MPC files may give raw weight matrices ``Q`` and ``R`` in ``[weights]`` (SI
units, the design model's state order; a list is a diagonal) instead of the Bryson magnitudes
they replace (:mod:`flexctrl.spec.raw_weights`).

>>> from flexctrl.spec.controller_reader import load_controller
>>> load_controller("controllers/lqr.toml").kind
'lqr'
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, get_args

from flexctrl.errors import SpecError, keyword_checked
from flexctrl.spec import shipped
from flexctrl.spec.arrival import ArrivalSettings
from flexctrl.spec.controller_settings import (
    SETTINGS,
    BadMeasurement,
    ControllerSettings,
    EstimatorSettings,
    LQRSettings,
    MPCSettings,
    NMPCSettings,
    OSQPSettings,
    PDSettings,
    ScheduleSettings,
    SensorSettings,
    ShapedSettings,
    Weights,
)
from flexctrl.spec.mpc_constraints import read_constraints
from flexctrl.spec.overrides import apply_overrides
from flexctrl.spec.payload_settings import read_payload
from flexctrl.spec.raw_weights import read_raw_weights
from flexctrl.spec.reader import TableReader, read_toml
from flexctrl.spec.sensors import SENSOR_KINDS

_DEG = math.pi / 180.0


def _build(reader: TableReader, cls: type, values: dict[str, Any]):
    """``cls(**values)``, with the settings' own validation errors given the file and dotted key."""
    reader.finish()
    try:
        return cls(**values)
    except SpecError as exc:
        key = exc.key or ""
        raise reader.error(key, str(exc).split(": ", 1)[1] if exc.key else str(exc)) from None


def _literal(reader: TableReader, name: str, default: str, literal) -> str:
    return reader.string(name, default, choices=[str(a) for a in get_args(literal)])


def _field_type(cls: type, name: str):
    import typing

    return typing.get_type_hints(cls)[name]


def _refuse_renamed(reader: TableReader, renamed: dict[str, str]) -> None:
    """Refuse a key of the old spelling, naming the key that replaced it."""
    for old, new in renamed.items():
        if reader.has(old):
            raise reader.error(
                old,
                f"was renamed '{new}' (value {reader.table[old]!r}): angles in the files are "
                f"degrees and their keys say so; allowed: {new}",
            )


def _on_bad_measurement(reader: TableReader, default: str) -> str:
    return _literal(reader, "on_bad_measurement", default, BadMeasurement)


def _free_text(reader: TableReader) -> None:
    for name in ("name", "notes", "source"):
        if reader.has(name):
            reader.string(name)


def _sensors(reader: TableReader, default: SensorSettings) -> SensorSettings:
    if not reader.has("sensors"):
        return default
    r = reader.table_of("sensors")
    _free_text(r)
    values: dict[str, Any] = {}
    if r.has("outputs"):
        outputs = r.raw("outputs")
        if not isinstance(outputs, list) or not all(isinstance(o, str) for o in outputs):
            raise r.error(
                "outputs",
                f"value {outputs!r} is not a list of strings; allowed: a list of "
                f"{', '.join(map(repr, SENSOR_KINDS))}",
            )
        for i, o in enumerate(outputs):
            if o not in SENSOR_KINDS:
                import difflib

                hint = difflib.get_close_matches(o, SENSOR_KINDS, n=1)
                extra = f" (did you mean '{hint[0]}'?)" if hint else ""
                raise r.error(
                    f"outputs[{i}]",
                    f"value {o!r} is not a sensor; allowed: "
                    f"{', '.join(map(repr, SENSOR_KINDS))}{extra}",
                )
        values["outputs"] = tuple(outputs)
    else:
        values["outputs"] = default.outputs
    units = {
        "joints": ("joints_deg", "deg", _DEG),
        "joint_rates": ("joint_rates_deg_s", "deg/s", _DEG),
        "strain": ("strain", "1/m", 1.0),
        "tip": ("tip", "m", 1.0),
        "tip_acc": ("tip_acc", "m/s^2", 1.0),
        "deflection": ("deflection", "m", 1.0),
    }
    noise = r.table_of("noise", {})
    _refuse_renamed(noise, {"joints": "joints_deg", "joint_rates": "joint_rates_deg_s"})
    for kind, (key, unit, factor) in units.items():
        values[kind] = noise.nonnegative(key, getattr(default, kind) / factor, unit=unit) * factor
    noise.finish()
    return _build(r, SensorSettings, values)


def _weights(reader: TableReader, raw: dict[str, Any] | None = None) -> Weights:
    """``[weights]``: the Bryson magnitudes; with ``raw`` (a dict filled here) also ``Q``, ``R``."""
    r = reader.table_of("weights", {})
    if raw is not None:
        raw.update(read_raw_weights(r))
    _refuse_renamed(r, {"joint": "joint_deg", "joint_rate": "joint_rate_deg_s"})
    d = Weights()
    values = {
        "joint": r.positive("joint_deg", math.degrees(d.joint), unit="deg") * _DEG,
        "modal": r.positive("modal", d.modal, unit="m"),
        "joint_rate": r.positive("joint_rate_deg_s", math.degrees(d.joint_rate), unit="deg/s")
        * _DEG,
        "modal_rate": r.positive("modal_rate", d.modal_rate, unit="m/s"),
        "torque": r.positive("torque", d.torque, unit="fraction of the torque limit"),
    }
    return _build(r, Weights, values)


def _estimator(reader: TableReader) -> EstimatorSettings:
    r = reader.table_of("estimator", {})
    _free_text(r)
    d = EstimatorSettings()
    values = {
        "kind": r.string("kind", d.kind, choices=["kalman"]),
        "torque_noise": r.nonnegative("torque_noise", d.torque_noise, unit="N m"),
        "modal_force_noise": r.nonnegative("modal_force_noise", d.modal_force_noise, unit="N"),
    }
    return _build(r, EstimatorSettings, values)


def _schedule(reader: TableReader) -> ScheduleSettings | None:
    if not reader.has("schedule"):
        return None
    r = reader.table_of("schedule")
    _free_text(r)
    joints, grid = [], []
    for key in list(r.table):
        if key in ("name", "notes", "source"):
            continue
        number = key[1:-4] if key.endswith("_deg") else key[1:]
        if not (key.startswith("q") and number.isdigit() and int(number) >= 1):
            r.raw(key)
            raise r.error(
                key,
                f"unknown key (value {r.table[key]!r}); allowed: joints 'q1_deg', 'q2_deg', ... "
                "each "
                "with a list of angles (deg)",
            )
        if not key.endswith("_deg"):
            _refuse_renamed(r, {key: f"{key}_deg"})
        joints.append(int(number))
        grid.append(tuple(v * _DEG for v in r.degrees(key)))
    order = sorted(range(len(joints)), key=lambda i: joints[i])
    try:
        return _build(
            r,
            ScheduleSettings,
            {"joints": tuple(joints[i] for i in order), "grid": tuple(grid[i] for i in order)},
        )
    except SpecError as exc:  # the settings name a joint's grid q2 (rad); the file's key is q2_deg
        name = (exc.key or "").rsplit(".", 1)[-1]
        if name.startswith("q") and name[1:].isdigit():
            raise r.error(f"{name}_deg", str(exc).split(": ", 2)[-1]) from None
        raise


def _arrival(reader: TableReader) -> ArrivalSettings:
    r = reader.table_of("arrival", {})
    d = ArrivalSettings()
    values = {
        "kind": _literal(r, "kind", d.kind, _field_type(ArrivalSettings, "kind")),
        "band": r.positive("band", d.band, unit="m"),
        "margin": r.nonnegative("margin", d.margin, unit="s"),
    }
    return _build(r, ArrivalSettings, values)


def _osqp(reader: TableReader) -> OSQPSettings:
    r = reader.table_of("osqp", {})
    d = OSQPSettings()
    values = {
        "eps_abs": r.nonnegative("eps_abs", d.eps_abs),
        "eps_rel": r.nonnegative("eps_rel", d.eps_rel),
        "rho": r.positive("rho", d.rho),
        "sigma": r.positive("sigma", d.sigma),
        "alpha": r.number("alpha", d.alpha, low=0.0, high=2.0, low_open=True),
        "adaptive_rho": r.boolean("adaptive_rho", d.adaptive_rho),
        "adaptive_rho_interval": r.integer("adaptive_rho_interval", d.adaptive_rho_interval, low=0),
        "adaptive_rho_tolerance": r.number(
            "adaptive_rho_tolerance", d.adaptive_rho_tolerance, low=1.0
        ),
        "polishing": r.boolean("polishing", d.polishing),
        "max_iter": r.integer("max_iter", d.max_iter, low=1),
        "time_limit": r.nonnegative("time_limit", d.time_limit, unit="s"),
        "check_termination": r.integer("check_termination", d.check_termination, low=0),
        "scaling": r.integer("scaling", d.scaling, low=0),
    }
    return _build(r, OSQPSettings, values)


def _pd_values(r: TableReader, d: PDSettings) -> dict[str, Any]:
    return {
        "sample_time": r.positive("sample_time", d.sample_time, unit="s"),
        "kp": r.numbers("kp", d.kp, low=0.0, unit="N m/rad"),
        "kd": r.numbers("kd", d.kd, low=0.0, unit="N m s/rad"),
        "bandwidth": r.positive("bandwidth", d.bandwidth, unit="Hz"),
        "damping": r.positive("damping", d.damping),
        "torque_filter": r.nonnegative("torque_filter", d.torque_filter, unit="Hz"),
        "gravity": _literal(r, "gravity", d.gravity, _field_type(PDSettings, "gravity")),
        "saturate": r.boolean("saturate", d.saturate),
        "feedforward": r.boolean("feedforward", d.feedforward),
        "strain_rate_gain": r.numbers(
            "strain_rate_gain", d.strain_rate_gain, unit="N m per 1/(m s)"
        ),
        "strain_rate_filter": r.nonnegative("strain_rate_filter", d.strain_rate_filter, unit="Hz"),
        "sensors": _sensors(r, d.sensors),
        "on_bad_measurement": _on_bad_measurement(r, d.on_bad_measurement),
    }


def _read_pd(r: TableReader) -> PDSettings:
    return _build(r, PDSettings, {"kind": "pd", **_pd_values(r, PDSettings())})


def _read_lqr(r: TableReader) -> LQRSettings:
    d = LQRSettings()
    raw: dict[str, Any] = {}
    values = {
        "kind": "lqr",
        "sample_time": r.positive("sample_time", d.sample_time, unit="s"),
        "weights": _weights(r, raw),
        "sensors": _sensors(r, d.sensors),
        "estimator": _estimator(r),
        "schedule": _schedule(r),
        "saturate": r.boolean("saturate", d.saturate),
        "on_bad_measurement": _on_bad_measurement(r, d.on_bad_measurement),
        "payload": read_payload(r),
    }
    return _build(r, LQRSettings, {**values, **raw})


def _soft_values(r: TableReader, cls: type, d) -> dict[str, Any]:
    return {
        "soft": _literal(r, "soft", d.soft, _field_type(cls, "soft")),
        "deflection_limit": r.nonnegative("deflection_limit", d.deflection_limit, unit="m"),
        "tip_limit": r.nonnegative("tip_limit", d.tip_limit, unit="m"),
        "slack_l1": r.nonnegative("slack_l1", d.slack_l1),
        "slack_l2": r.positive("slack_l2", d.slack_l2),
    }


def _whole_numbers(r: TableReader, name: str, default: tuple[int, ...]) -> tuple[int, ...]:
    values = r.numbers(name, default, low=1.0, unit="samples")
    if any(v != int(v) for v in values):
        raise r.error(
            name, f"value {list(values)!r} is not allowed; allowed: whole numbers >= 1 (samples)"
        )
    return tuple(int(v) for v in values)


def _read_mpc(r: TableReader) -> MPCSettings:
    d = MPCSettings()
    raw: dict[str, Any] = {}
    values = {
        "kind": "mpc",
        "sample_time": r.positive("sample_time", d.sample_time, unit="s"),
        "horizon": r.integer("horizon", d.horizon, low=1, high=1000),
        "weights": _weights(r, raw),
        "constraints": read_constraints(r),
        "terminal": _literal(r, "terminal", d.terminal, _field_type(MPCSettings, "terminal")),
        **_soft_values(r, MPCSettings, d),
        "formulation": _literal(
            r, "formulation", d.formulation, _field_type(MPCSettings, "formulation")
        ),
        "backend": _literal(r, "backend", d.backend, _field_type(MPCSettings, "backend")),
        "scaling": _literal(r, "scaling", d.scaling, _field_type(MPCSettings, "scaling")),
        "warm_start": _literal(
            r, "warm_start", d.warm_start, _field_type(MPCSettings, "warm_start")
        ),
        "fallback": _literal(r, "fallback", d.fallback, _field_type(MPCSettings, "fallback")),
        "accept_inaccurate": r.boolean("accept_inaccurate", d.accept_inaccurate),
        "blocks": _whole_numbers(r, "blocks", d.blocks),
        "constraint_stride": r.integer("constraint_stride", d.constraint_stride, low=1, high=1000),
        "arrival": _arrival(r),
        "osqp": _osqp(r),
        "sensors": _sensors(r, d.sensors),
        "estimator": _estimator(r),
        "on_bad_measurement": _on_bad_measurement(r, d.on_bad_measurement),
        "payload": read_payload(r),
    }
    return _build(r, MPCSettings, {**values, **raw})


def _read_nmpc(r: TableReader) -> NMPCSettings:
    d = NMPCSettings()
    values = {
        "kind": "nmpc",
        "sample_time": r.positive("sample_time", d.sample_time, unit="s"),
        "horizon": r.integer("horizon", d.horizon, low=1, high=1000),
        "substeps": r.integer("substeps", d.substeps, low=0, high=200),
        "sensitivities": _literal(
            r, "sensitivities", d.sensitivities, _field_type(NMPCSettings, "sensitivities")
        ),
        "weights": _weights(r),
        "mode": _literal(r, "mode", d.mode, _field_type(NMPCSettings, "mode")),
        "nlp_solver": _literal(
            r, "nlp_solver", d.nlp_solver, _field_type(NMPCSettings, "nlp_solver")
        ),
        "qp_solver": _literal(r, "qp_solver", d.qp_solver, _field_type(NMPCSettings, "qp_solver")),
        "max_iter": r.integer("max_iter", d.max_iter, low=1),
        "init_iter": r.integer("init_iter", d.init_iter, low=0),
        **_soft_values(r, NMPCSettings, d),
        "compile": r.boolean("compile", d.compile),
        "prediction_modes": r.integer("prediction_modes", d.prediction_modes, low=0, high=6),
        "prediction_basis": _literal(
            r, "prediction_basis", d.prediction_basis, _field_type(NMPCSettings, "prediction_basis")
        ),
        "prediction_map": _literal(
            r, "prediction_map", d.prediction_map, _field_type(NMPCSettings, "prediction_map")
        ),
        "jacobian_every": r.integer("jacobian_every", d.jacobian_every, low=1, high=200),
        "stages_per_jacobian": r.integer(
            "stages_per_jacobian", d.stages_per_jacobian, low=1, high=1000
        ),
        "qp_warm_start": r.boolean("qp_warm_start", d.qp_warm_start),
        "sensors": _sensors(r, d.sensors),
        "estimator": _estimator(r),
        "on_bad_measurement": _on_bad_measurement(r, d.on_bad_measurement),
    }
    return _build(r, NMPCSettings, values)


def _read_shaped(r: TableReader) -> ShapedSettings:
    d = ShapedSettings()
    pd_reader = r.table_of("pd", {})
    _free_text(pd_reader)
    pd = _build(pd_reader, PDSettings, {"kind": "pd", **_pd_values(pd_reader, d.pd)})
    values = {
        "kind": "shaped",
        "shaper": _literal(r, "shaper", d.shaper, _field_type(ShapedSettings, "shaper")),
        "modes": r.integer("modes", d.modes, low=1, high=12),
        "frequency_source": _literal(
            r,
            "frequency_source",
            d.frequency_source,
            _field_type(ShapedSettings, "frequency_source"),
        ),
        "move_time": r.nonnegative("move_time", d.move_time, unit="s"),
        "pd": pd,
    }
    return _build(r, ShapedSettings, values)


_READERS: dict[str, Callable[[TableReader], ControllerSettings]] = {
    "pd": _read_pd,
    "lqr": _read_lqr,
    "mpc": _read_mpc,
    "nmpc": _read_nmpc,
    "shaped": _read_shaped,
}


def controller_from_document(document: dict[str, Any], source: str) -> ControllerSettings:
    """Validate a parsed controller document and return its settings.

    Parameters
    ----------
    document : dict
        The parsed TOML (angles in degrees).
    source : str
        Where it came from, for the messages.

    Returns
    -------
    PDSettings, LQRSettings, MPCSettings, NMPCSettings or ShapedSettings
        The settings (angles in radians).

    Raises
    ------
    SpecError
        Naming the source, the key, the value and what is allowed.
    """
    r = TableReader(document, source)
    kind = r.string("kind", choices=list(SETTINGS))
    _free_text(r)
    return _READERS[kind](r)


@keyword_checked
def load_controller(path: str | Path, overrides: Iterable[str] = ()) -> ControllerSettings:
    """Read ``controllers/*.toml`` (with ``KEY=VALUE`` overrides) into its settings dataclass.

    Parameters
    ----------
    path : str or Path
        A controller file; its ``kind`` picks the settings class.
    overrides : iterable of str
        ``KEY=VALUE`` strings (``weights.joint_deg=0.1``), applied before validation.

    Returns
    -------
    PDSettings, LQRSettings, MPCSettings, NMPCSettings or ShapedSettings
        Angles converted to radians; give it to :func:`flexctrl.design`.

    Raises
    ------
    SpecError
        Naming the file, the key, the value and what is allowed.
    """
    path = shipped.find(path, "controller")
    document = read_toml(path)
    overrides = list(overrides)
    if overrides:
        document = apply_overrides(document, overrides)
    return controller_from_document(document, str(path))


__all__ = ["load_controller", "controller_from_document"]
