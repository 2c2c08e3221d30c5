"""Open-loop arm scenes (``kind = "arm"``): what to simulate, validated in one place.

A scene names a model file, how to build it and what to do with it; files are read
by :func:`flexctrl.spec.scene.load_scene`, which dispatches on ``kind``.

``kind = "arm"`` layout (SI units; angles in degrees)::

    kind = "arm"
    name = "free_vibration"           # default: the file's stem
    description = "..."               # free text
    model = "models/subedi3link.toml" # relative to the scene file, the working dir or the repo
    payload = 2.0                     # kg (default: the model file's)
    fidelity = "amm:2"                # 'rigid', 'amm:N', 'fem:N' (the --fidelity spelling), 'auto'
    tolerance = 1e-3                  # m: tip-position tolerance; required by fidelity = "auto"
    fidelity_walk = "estimate"        # how auto walks the ladder for a closed loop: "estimate" or
                                      # "ladder" (flexctrl.scenes.auto_closed_loop)
    fidelity_checks = "full"          # or "tolerance": auto certifies the tolerance only (no rung
                                      # below, no step check)
    modes = "frozen"                  # or "scheduled"
    axial_shortening = true           # a bent link's foreshortening (default: the model file's;
                                      # docs/explanation/assumed-modes.md)
    axial_stretch = true              # axially compliant assumed-modes links (default: the model
                                      # file's)
    gravity = [0.0, -9.81]            # m/s^2 (default: the model file's)
    integrator = "rk4"                # rk4 | cvodes | idas | scipy | euler | newmark
    dt = 1e-3                         # s: step, output interval and torque hold
    duration = 5.0                    # s
    [initial]   q (deg, one per joint), qd (deg/s), [initial.qf] qf31 = 0.1 (m) ...
    [damping]   zeta (every mode, all links), friction (N m s/rad, one value or one per joint),
                form = "ratio" (d = 2 zeta omega m_l, zeta the modal damping ratio) or "paper"
                (Subedi et al. Eq 68 as printed, d = 2 zeta omega: 1/s where kg/s is needed,
                an effective ratio zeta / m_l) or "stiffness" (the finite elements'
                (2 zeta / omega_1) K: mode j has the ratio zeta omega_j / omega_1) or "modal"
                (zeta on every coupled elastic mode at the arm's configuration, the model
                file's damping_zeta replaced); default: the model file's damping_form
    [input]     kind = "none" | "bangbang"; for bangbang: joint (1-based), amplitude (N m),
                t_accel (s), t_decel (s, default t_accel), t_start (s, default 0)
    [solver]    rtol, atol (cvodes, idas, scipy), method (scipy), compile (rk4, euler), chunk,
                alpha (newmark, 0..0.5, default 0.25), delta (newmark, 0.5..1, default 0.5)
    [outputs]   fft_span (s, default 2), fft_peaks (default 2), plots (default true)

"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from flexctrl.errors import SpecError
from flexctrl.spec import shipped
from flexctrl.spec.damping import DAMPING_FORMS, DampingForm
from flexctrl.spec.fidelity import FIDELITY_CHECKS, FIDELITY_WALKS, Fidelity, parse_fidelity
from flexctrl.spec.reader import TableReader

Modes = Literal["frozen", "scheduled"]
InputKind = Literal["none", "bangbang"]
MODES: tuple[Modes, ...] = ("frozen", "scheduled")
INPUT_KINDS: tuple[InputKind, ...] = ("none", "bangbang")
INTEGRATOR_NAMES = ("rk4", "cvodes", "idas", "scipy", "euler", "newmark")
SCIPY_METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
#: Solver keys and the integrators they apply to.
SOLVER_KEYS = {
    "rtol": ("cvodes", "idas", "scipy"),
    "atol": ("cvodes", "idas", "scipy"),
    "method": ("scipy",),
    "compile": ("rk4", "euler"),
    "chunk": INTEGRATOR_NAMES,
    "alpha": ("newmark",),
    "delta": ("newmark",),
}
_QF_NAME = re.compile(r"^qf\d+$")


@dataclass(frozen=True)
class InputSpec:
    """Joint torque input.

    ``kind = "bangbang"``: ``+amplitude`` on joint ``joint`` (1-based) for
    ``t_accel`` seconds from ``t_start``, then ``-amplitude`` for ``t_decel``
    seconds, then zero.
    """

    kind: InputKind = "none"
    joint: int = 1
    amplitude: float = 0.0
    t_accel: float = 0.0
    t_decel: float = 0.0
    t_start: float = 0.0

    def torque(self, t: np.ndarray, n_joints: int) -> np.ndarray:
        """Torques (N m) at times ``t`` (s), shape (len(t), n_joints)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.zeros((t.size, n_joints))
        if self.kind == "bangbang":
            s = t - self.t_start
            accel = (s >= 0) & (s < self.t_accel)
            decel = (s >= self.t_accel) & (s < self.t_accel + self.t_decel)
            out[:, self.joint - 1] = self.amplitude * (accel.astype(float) - decel.astype(float))
        return out

    def samples(self, n_steps: int, dt: float, n_joints: int) -> np.ndarray:
        """Held torques for ``n_steps`` steps of ``dt``: the torque at each step's midpoint."""
        return self.torque((np.arange(n_steps) + 0.5) * dt, n_joints)


@dataclass(frozen=True)
class ArmScene:
    """A validated ``kind = "arm"`` scene (see module docstring); angles in radians."""

    name: str
    model: Path
    fidelity: Fidelity
    dt: float
    duration: float
    integrator: str = "rk4"
    modes: Modes = "frozen"
    payload: float | None = None
    gravity: tuple[float, float] | None = None
    q0: tuple[float, ...] | None = None
    qd0: tuple[float, ...] | None = None
    qf0: dict[str, float] = field(default_factory=dict)
    zeta: float | None = None
    friction: tuple[float, ...] | None = None
    damping_form: DampingForm | None = None
    input: InputSpec = InputSpec()
    solver: dict[str, Any] = field(default_factory=dict)
    fft_span: float = 2.0
    fft_peaks: int = 2
    plots: bool = True
    description: str = ""
    source: str = ""
    kind: str = "arm"
    tolerance: float | None = None
    #: How ``fidelity = "auto"`` walks the ladder for a closed loop: one of ``FIDELITY_WALKS``
    #: (:mod:`flexctrl.spec.fidelity`): ``estimate`` or ``ladder``.
    fidelity_walk: str = "estimate"
    #: What ``fidelity = "auto"`` checks beyond the tolerance: one of ``FIDELITY_CHECKS``: ``full``
    #: or ``tolerance``.
    fidelity_checks: str = "full"
    axial_shortening: bool | None = None
    axial_stretch: bool | None = None

    def settings(self) -> dict[str, Any]:
        """The scene as plain, JSON-ready data (angles in degrees, as in the file)."""
        return {
            "kind": self.kind,
            "name": self.name,
            "source": self.source,
            "model": str(self.model),
            "fidelity": str(self.fidelity),
            "modes": self.modes,
            "axial_shortening": self.axial_shortening,
            "axial_stretch": self.axial_stretch,
            "payload_kg": self.payload,
            "gravity": list(self.gravity) if self.gravity else None,
            "q0_deg": [math.degrees(a) for a in self.q0] if self.q0 else None,
            "qd0_deg_s": [math.degrees(a) for a in self.qd0] if self.qd0 else None,
            "qf0_m": dict(self.qf0),
            "zeta": self.zeta,
            "damping_form": self.damping_form,
            "friction": list(self.friction) if self.friction else None,
            "input": {
                "kind": self.input.kind,
                "joint": self.input.joint,
                "amplitude": self.input.amplitude,
                "t_accel": self.input.t_accel,
                "t_decel": self.input.t_decel,
                "t_start": self.input.t_start,
            },
            "integrator": self.integrator,
            "dt": self.dt,
            "duration": self.duration,
            "solver": dict(self.solver),
            "fft_span": self.fft_span,
            "fft_peaks": self.fft_peaks,
            "tolerance_m": self.tolerance,
            "fidelity_walk": self.fidelity_walk,
            "fidelity_checks": self.fidelity_checks,
        }


def resolve_model_path(name: str, base_dir: Path, r: TableReader) -> Path:
    """A model file relative to the scene's folder, the working folder or the shipped files."""
    try:
        return shipped.find(name, "model", base_dir).resolve()
    except SpecError as exc:
        raise r.error("model", f"file {name!r} not found ({exc.message})") from None


def read_arm_scene(
    document: dict[str, Any],
    source: str,
    base_dir: Path,
    *,
    kind: str = "arm",
    accept: tuple[str, ...] = (),
) -> ArmScene:
    """Validate a ``kind = "arm"`` scene document (see module docstring).

    ``kind`` and ``accept`` serve scenes built on this one (``kind = "closed_loop"``): the
    kind their file names, and the keys of their own that another reader validates (so an
    unknown key is told the keys of the file's own kind).
    """
    r = TableReader(document, source)
    r.string("kind", "arm", choices=(kind,))
    r.accept(*accept)
    model = resolve_model_path(r.string("model"), base_dir, r)
    fidelity = parse_fidelity(r.raw("fidelity", "amm:2"), source=source, key="fidelity")
    tolerance = _read_tolerance(r, fidelity)
    integrator = r.string("integrator", "rk4", choices=INTEGRATOR_NAMES)
    gravity = r.numbers("gravity", length=2, unit="m/s^2") if r.has("gravity") else None
    q0, qd0, qf0 = _read_initial(r.table_of("initial", {}))
    zeta, friction, damping_form = _read_damping(r.table_of("damping", {}))
    spec = _read_input(r.table_of("input", {}))
    solver = _read_solver(r.table_of("solver", {}), integrator)
    fft_span, fft_peaks, plots = _read_outputs(r.table_of("outputs", {}))
    dt, duration = _read_times(r)
    scene = ArmScene(
        name=r.string("name", Path(source).stem),
        description=r.string("description", ""),
        model=model,
        payload=r.nonnegative("payload", unit="kg") if r.has("payload") else None,
        fidelity=fidelity,
        modes=r.choice("modes", MODES, "frozen"),
        gravity=(gravity[0], gravity[1]) if gravity else None,
        integrator=integrator,
        dt=dt,
        duration=duration,
        q0=q0,
        qd0=qd0,
        qf0=qf0,
        zeta=zeta,
        friction=friction,
        damping_form=damping_form,
        input=spec,
        solver=solver,
        fft_span=fft_span,
        fft_peaks=fft_peaks,
        plots=plots,
        source=source,
        tolerance=tolerance,
        fidelity_walk=r.string("fidelity_walk", "estimate", choices=FIDELITY_WALKS),
        fidelity_checks=r.string("fidelity_checks", "full", choices=FIDELITY_CHECKS),
        axial_shortening=r.boolean("axial_shortening") if r.has("axial_shortening") else None,
        axial_stretch=r.boolean("axial_stretch") if r.has("axial_stretch") else None,
    )
    r.finish()
    return scene


def _read_tolerance(r: TableReader, fidelity: Fidelity) -> float | None:
    """``tolerance`` (m): required by ``fidelity = "auto"``."""
    tolerance = (
        r.number("tolerance", low=0.0, low_open=True, high=1.0, unit="m")
        if r.has("tolerance")
        else None
    )
    if fidelity.kind == "auto" and tolerance is None:
        raise r.error(
            "tolerance",
            "is missing; fidelity = 'auto' needs it; allowed: a number > 0 (m, tip-position "
            "tolerance), e.g. tolerance = 1e-3",
        )
    return tolerance


def _read_initial(ini: TableReader):
    """``[initial]``: joint angles (rad), rates (rad/s) and elastic coordinates (m)."""
    q0 = tuple(math.radians(a) for a in ini.degrees("q")) if ini.has("q") else None
    qd0 = (
        tuple(math.radians(a) for a in ini.numbers("qd", unit="degrees/s"))
        if ini.has("qd")
        else None
    )
    qf0: dict[str, float] = {}
    if ini.has("qf"):
        qf = ini.table_of("qf")
        for name in list(qf.table):
            if not _QF_NAME.match(name):
                raise qf.error(
                    name, "is not an elastic coordinate name; allowed: qf<link><mode>, e.g. qf31"
                )
            qf0[name] = qf.number(name, unit="m")
        qf.finish()
    ini.finish()
    return q0, qd0, qf0


def _read_damping(dmp: TableReader):
    """``[damping]``: ``zeta``, ``friction`` (N m s/rad, one or one per joint), ``form``."""
    zeta = dmp.number("zeta", low=0.0, high=10.0) if dmp.has("zeta") else None
    friction = None
    if dmp.has("friction"):
        raw = dmp.raw("friction")
        friction = (
            dmp.numbers("friction", low=0.0, unit="N m s/rad")
            if isinstance(raw, list)
            else (dmp.nonnegative("friction", unit="N m s/rad"),)
        )
    damping_form = dmp.choice("form", DAMPING_FORMS) if dmp.has("form") else None
    dmp.finish()
    return zeta, friction, damping_form


def _read_input(inp: TableReader) -> InputSpec:
    """``[input]``: none, or a bang-bang torque on one joint."""
    kind = inp.choice("kind", INPUT_KINDS, "none")
    if kind == "bangbang":
        t_accel = inp.positive("t_accel", unit="s")
        spec = InputSpec(
            kind,
            joint=inp.integer("joint", low=1),
            amplitude=inp.number("amplitude", unit="N m"),
            t_accel=t_accel,
            t_decel=inp.nonnegative("t_decel", t_accel, unit="s"),
            t_start=inp.nonnegative("t_start", 0.0, unit="s"),
        )
    else:
        spec = InputSpec("none")
    inp.finish()
    return spec


def _read_solver(sol: TableReader, integrator: str) -> dict[str, Any]:
    """``[solver]``: the options that apply to ``integrator`` (:data:`SOLVER_KEYS`)."""
    for key in list(sol.table):
        if key in SOLVER_KEYS and integrator not in SOLVER_KEYS[key]:
            raise sol.error(
                key,
                f"does not apply to integrator '{integrator}'; it applies to: "
                f"{', '.join(SOLVER_KEYS[key])}",
            )
    solver: dict[str, Any] = {}
    if sol.has("rtol"):
        solver["rtol"] = sol.number("rtol", low=0.0, low_open=True, high=0.1)
    if sol.has("atol"):
        solver["atol"] = sol.number("atol", low=0.0, low_open=True, high=0.1)
    if sol.has("method"):
        solver["method"] = sol.string("method", choices=SCIPY_METHODS)
    if sol.has("compile"):
        solver["compile"] = sol.boolean("compile")
    if sol.has("chunk"):
        solver["chunk"] = sol.integer("chunk", low=1, high=1_000_000)
    if sol.has("alpha"):
        solver["alpha"] = sol.number("alpha", low=0.0, high=0.5)
    if sol.has("delta"):
        solver["delta"] = sol.number("delta", low=0.5, high=1.0)
    sol.finish()
    return solver


def _read_outputs(out: TableReader) -> tuple[float, int, bool]:
    """``[outputs]``: ``fft_span`` (s), ``fft_peaks``, ``plots``."""
    fft_span = out.positive("fft_span", 2.0, unit="s")
    fft_peaks = out.integer("fft_peaks", 2, low=1, high=20)
    plots = out.boolean("plots", True)
    out.finish()
    return fft_span, fft_peaks, plots


def _read_times(r: TableReader) -> tuple[float, float]:
    """``dt`` and ``duration`` (s): a step no longer than the run, at most 5e7 steps."""
    dt = r.positive("dt", unit="s")
    duration = r.positive("duration", unit="s")
    if dt > duration:
        raise r.error(
            "dt",
            f"value {dt!r} is longer than the duration {duration!r}; allowed: 0 < dt <= duration",
        )
    if duration / dt > 5e7:
        raise r.error(
            "duration",
            f"value {duration!r} needs {duration / dt:.3g} steps of {dt!r} s; allowed: at most "
            "5e7 steps",
        )
    return dt, duration
