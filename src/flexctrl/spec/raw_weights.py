"""Raw LQR/MPC weight matrices ``Q`` and ``R``: checked as plain data, read from ``[weights]``.

``Q`` weighs the design model's state ``(q, qd)`` in SI units (rad, m of the modal
coordinates, rad/s, m/s), in the order ``fc.linearize(model, op).state_labels`` and a
designed controller's ``state_names`` give (joints, elastic coordinates link by link, then
their rates); ``R`` weighs the joint torques (N m), one row per joint.  Either is a
square matrix (a list of rows) or a list, its diagonal.  ``Q`` must be symmetric and
positive semidefinite, ``R`` symmetric and positive definite; their sizes are checked
against the model when the controller is designed.  In a controller file they are keys of
``[weights]`` (``Q = [[...], ...]`` or ``Q = [1e4, ...]``), in the same SI units as in
Python, and replace the Bryson magnitudes they stand for (``Q``: ``joint_deg``, ``modal``,
``joint_rate_deg_s``, ``modal_rate``; ``R``: ``torque``), which may then not be given.
"""

from __future__ import annotations

import numpy as np

from flexctrl.errors import SpecError

#: The Bryson magnitudes (file keys of ``[weights]``) each raw matrix replaces.
REPLACES = {
    "Q": ("joint_deg", "modal", "joint_rate_deg_s", "modal_rate"),
    "R": ("torque",),
}

Matrix = tuple[tuple[float, ...], ...]


def weight_matrix(key: str, value) -> Matrix | None:
    """``value`` as a square matrix of floats (a list is its diagonal), checked; None stays None.

    Parameters
    ----------
    key : str
        ``"Q"`` (positive semidefinite) or ``"R"`` (positive definite): the name in errors.
    value : array_like or None
        A square matrix, or a 1-D list of its diagonal.

    Returns
    -------
    tuple of tuple of float or None

    Raises
    ------
    SpecError
        For a value that is not a finite square matrix, not symmetric, or (``Q``) indefinite
        or (``R``) not positive definite, naming ``key`` and the offending entry or
        eigenvalue.
    """
    if value is None:
        return None
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SpecError(
            f"value {value!r} is not allowed; allowed: a square matrix of numbers (a list of "
            "rows) or a list (its diagonal)",
            key=key,
        ) from None
    if array.ndim == 1 and array.size:
        array = np.diag(array)
    if array.ndim != 2 or array.shape[0] != array.shape[1] or not array.size:
        raise SpecError(
            f"has shape {array.shape}; allowed: a square matrix (a list of rows) or a list "
            "(its diagonal)",
            key=key,
        )
    if not np.all(np.isfinite(array)):
        i, j = np.argwhere(~np.isfinite(array))[0]
        raise SpecError(f"entry [{i}][{j}] is {array[i, j]!r}; allowed: finite numbers", key=key)
    _check_definite(key, array)
    return tuple(tuple(float(v) for v in row) for row in array)


def _check_definite(key: str, array: np.ndarray) -> None:
    scale = max(float(np.max(np.abs(array))), np.finfo(float).tiny)
    asym = np.abs(array - array.T)
    if np.max(asym) > 1e-12 * scale:
        i, j = np.unravel_index(int(np.argmax(asym)), asym.shape)
        raise SpecError(
            f"is not symmetric: entry [{i}][{j}] = {array[i, j]!r} but [{j}][{i}] = "
            f"{array[j, i]!r}; allowed: a symmetric matrix",
            key=key,
        )
    low = float(np.min(np.linalg.eigvalsh(0.5 * (array + array.T))))
    if key == "R" and low <= 0.0:
        raise SpecError(
            f"has smallest eigenvalue {low:.6g}; allowed: a positive definite matrix "
            "(every torque costs something)",
            key=key,
        )
    if low < -1e-12 * scale * array.shape[0]:
        raise SpecError(
            f"is indefinite: smallest eigenvalue {low:.6g}; allowed: a positive semidefinite "
            "matrix",
            key=key,
        )


def checked_size(key: str, matrix: Matrix, size: int, what: str) -> np.ndarray:
    """``matrix`` as an array, or :class:`SpecError` unless it is ``size`` by ``size``.

    Parameters
    ----------
    key : str
        ``"Q"`` or ``"R"``.
    matrix : tuple of tuple of float
        From :func:`weight_matrix`.
    size : int
        The size the design model asks for.
    what : str
        What the rows are, for the message (the state or torque names).

    Returns
    -------
    ndarray
    """
    array = np.array(matrix, dtype=float)
    if array.shape != (size, size):
        raise SpecError(
            f"has shape {array.shape}; expected ({size}, {size}) on the design model's {what}",
            key=key,
        )
    return array


def read_raw_weights(reader) -> dict[str, Matrix | None]:
    """``{"Q": ..., "R": ...}`` from a controller file's ``[weights]`` table reader.

    Refuses a raw matrix beside the Bryson magnitudes it replaces (:data:`REPLACES`).
    """
    values: dict[str, Matrix | None] = {}
    for key, replaced in REPLACES.items():
        if not reader.has(key):
            values[key] = None
            continue
        both = [name for name in replaced if reader.has(name)]
        if both:
            raise reader.error(
                key,
                f"replaces {', '.join(map(repr, both))}; allowed: either {key!r} or the "
                "Bryson magnitudes, not both",
            )
        raw = reader.raw(key)
        try:
            values[key] = weight_matrix(key, raw)
        except SpecError as exc:
            raise reader.error(key, str(exc).split(": ", 1)[-1]) from None
    return values


__all__ = ["REPLACES", "weight_matrix", "checked_size", "read_raw_weights"]
