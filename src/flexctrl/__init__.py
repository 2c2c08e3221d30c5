"""flexctrl: control design for robot arms with flexible links.

Units are SI throughout the Python API (m, kg, s, N, N m) and angles are in radians;
model, scene, controller and study files and the command line take angles in degrees.

The public names are re-exported here lazily: ``import flexctrl`` loads neither CasADi
nor python-control until a name that needs them is used.

>>> import numpy as np
>>> import flexctrl as fc
>>> model = fc.load_model("subedi3link", payload=2.0, fidelity="amm:1", gravity=[0.0, 0.0])
>>> op = fc.equilibrium(model, np.radians([30.0, 0.0, 0.0]))
>>> sys = fc.linearize(model, op)
>>> sys.nstates, sys.ninputs, sys.input_labels
(12, 3, ['tau1', 'tau2', 'tau3'])
"""

import importlib as _importlib

#: Public name -> the module that defines it.
_EXPORTS: dict[str, str] = {
    # models and linearisation
    "load_model": "flexctrl.scenes.model_files",
    "build_model": "flexctrl.dynamics.build",
    "load_arm": "flexctrl.spec.arm",
    "ArmSpec": "flexctrl.spec.arm",
    "LinkSpec": "flexctrl.spec.arm",
    "JointSpec": "flexctrl.spec.arm",
    "PayloadSpec": "flexctrl.spec.arm",
    "SectionSpec": "flexctrl.spec.arm",
    "equilibrium": "flexctrl.linear",
    "linearize": "flexctrl.linear",
    "discretize": "flexctrl.linear",
    "modal_summary": "flexctrl.linear",
    "locked_frequencies": "flexctrl.linear",
    "arm_modes": "flexctrl.modal.arm_modes",
    "link_modes": "flexctrl.modal.arm_modes",
    "OperatingPoint": "flexctrl.linear",
    "Sensors": "flexctrl.linear",
    "simulate": "flexctrl.sim",
    "Trajectory": "flexctrl.sim.trajectory",
    # controllers
    "load_controller": "flexctrl.spec.controller_reader",
    "design": "flexctrl.control",
    "Controller": "flexctrl.control.controller",
    "PDController": "flexctrl.control.pd",
    "LQRController": "flexctrl.control.lqr",
    "MPCController": "flexctrl.control.mpc.controller",
    "NMPCController": "flexctrl.control.nmpc.controller",
    "ShapedController": "flexctrl.control.shaping",
    "PayloadLQRController": "flexctrl.control.payload.lqr_payload",
    "PayloadMPCController": "flexctrl.control.payload.mpc_payload",
    "PayloadEstimate": "flexctrl.control.payload.bank",
    "PayloadSettings": "flexctrl.spec.payload_settings",
    "PDSettings": "flexctrl.spec.controller_settings",
    "LQRSettings": "flexctrl.spec.controller_settings",
    "MPCSettings": "flexctrl.spec.controller_settings",
    "NMPCSettings": "flexctrl.spec.controller_settings",
    "ShapedSettings": "flexctrl.spec.controller_settings",
    "SensorSettings": "flexctrl.spec.controller_settings",
    "EstimatorSettings": "flexctrl.spec.controller_settings",
    "Weights": "flexctrl.spec.controller_settings",
    "StepRecorder": "flexctrl.control.cexport",
    "Bound": "flexctrl.spec.mpc_constraints",
    # closed loop
    "Move": "flexctrl.spec.reference",
    "MoveSequence": "flexctrl.spec.reference",
    "MetricSettings": "flexctrl.spec.closed_loop_scene",
    "closed_loop": "flexctrl.loop.closed_loop",
    "Plant": "flexctrl.loop.plant",
    "ClosedLoopResult": "flexctrl.loop.result",
    "compare": "flexctrl.loop.compare_figure",
    # scenes and studies
    "load_scene": "flexctrl.spec.scene",
    "run_scene": "flexctrl.scenes",
    "SceneCache": "flexctrl.scenes.cache",
    "load_study": "flexctrl.study.study_file",
    "run_study": "flexctrl.study.runner",
    "write_report": "flexctrl.study.report",
    "load_tuning": "flexctrl.spec.tuning",
    "tune": "flexctrl.tuning.tuner",
    # the seed papers
    "reproduce_paper": "flexctrl.reproduce.reproduction",
    # errors
    "FlexctrlError": "flexctrl.errors",
    "SpecError": "flexctrl.errors",
    "DesignWarning": "flexctrl.errors",
    "MeasurementError": "flexctrl.errors",
    "SimulationError": "flexctrl.errors",
    "SolverError": "flexctrl.errors",
}
__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> object:
    if name == "__version__":
        # one place for the version: pyproject.toml, read from the installed distribution
        from importlib.metadata import version

        value: object = version("flexctrl")
    else:
        module = _EXPORTS.get(name)
        if module is None:
            raise AttributeError(f"module 'flexctrl' has no attribute {name!r}")
        value = getattr(_importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return list(__all__)
