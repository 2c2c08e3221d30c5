"""Plant and design model apart: a controller's coordinates and sensors carried onto the plant."""

from __future__ import annotations

import dataclasses
import re

import casadi as ca
import numpy as np

from flexctrl.errors import SpecError
from flexctrl.linear import Sensors, state_names


def state_projection(plant, design_names) -> np.ndarray:
    """Matrix ``P`` (n_design x plant.n_x), ``x_design = P x_plant``: coordinates matched by name.

    An assumed-modes rung keeps the first ``N`` clamped-mass modes of each link, the same
    functions at every ``N`` (a mode's shape and frequency do not depend on how many are
    kept), so coordinate ``qf<link><mode>`` means the same in every ``amm`` model; a design
    coordinate the plant lacks (a mode above the plant's count) reads zero, and the plant's
    modes above the design's are not seen (spillover).

    Raises
    ------
    SpecError
        When a design coordinate the plant lacks is not an elastic one (different arms or
        a finite-element plant: its coordinates are nodal, not modal).
    """
    plant_names = state_names(plant)
    index = {name: i for i, name in enumerate(plant_names)}
    P = np.zeros((len(design_names), plant.n_x))
    for row, name in enumerate(design_names):
        if name in index:
            P[row, index[name]] = 1.0
        elif not re.match(r"^d?qf\d+$", name) or str(getattr(plant, "fidelity", "")).startswith(
            "fem"
        ):
            raise SpecError(
                f"the full-state controller's coordinate '{name}' has no counterpart in the plant "
                f"'{plant.name}' ({', '.join(plant.coordinate_names)}); allowed: plant and design "
                "models "
                "that are both assumed-modes ('rigid' or 'amm:N') of the same arm",
                key="controller_fidelity",
            )
    return P


def plant_sensors(plant, design_sensors, q_joints):
    """The controller's sensor kinds built on the plant model, with the controller's noise levels.

    A full-state controller on a plant of another fidelity measures the plant's state
    projected on the design model's coordinates (:func:`state_projection`).
    """
    if "state" in design_sensors.kinds:
        if plant.n_x == design_sensors.function.size1_in(0):
            return design_sensors
        P = state_projection(plant, design_sensors.names)
        x = ca.MX.sym("x", plant.n_x)
        u = ca.MX.sym("u", plant.n_u)
        function = ca.Function("sensors", [x, u], [ca.mtimes(ca.DM(P), x)], ["x", "u"], ["y"])
        return dataclasses.replace(design_sensors, function=function)
    built = Sensors.build(plant, design_sensors.kinds, q_joints=q_joints)
    if built.names != design_sensors.names:
        raise SpecError(
            f"the plant's sensors {list(built.names)} differ from the controller's "
            f"{list(design_sensors.names)}; "
            "strain gauges need links with modes in both models",
            key="controller_fidelity",
        )
    return dataclasses.replace(built, noise_std=np.array(design_sensors.noise_std, dtype=float))
