"""A model file read, changed and built: :func:`load_model`, the Python entry point to a model."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

from flexctrl.dynamics.build import build_model
from flexctrl.errors import SpecError, keyword_checked
from flexctrl.spec import shipped
from flexctrl.spec.arm import arm_from_document
from flexctrl.spec.overrides import apply_overrides, apply_values
from flexctrl.spec.reader import read_toml


@keyword_checked
def load_model(
    path: str | Path,
    payload: float | None = None,
    fidelity: str | None = "amm:2",
    *,
    overrides: Mapping[str, Any] | Iterable[str] | None = None,
    modes: Literal["frozen", "scheduled"] = "frozen",
    reference_q: Sequence[float] | None = None,
    damping: Literal["ratio", "paper"] | None = None,
    **keys: Any,
):
    """Read a model file, change what the arguments say, validate it and build it at ``fidelity``.

    Parameters
    ----------
    path : str or Path
        A ``models/*.toml`` file.
    payload : float, optional
        Payload mass (kg) replacing the file's ``payload.mass``.
    fidelity : str, optional
        ``"rigid"``, ``"amm:N"`` (N assumed modes per link) or ``"fem:N"`` (N finite
        elements per link); None takes each link's ``n_modes`` from the file.
    overrides : mapping or sequence of str, optional
        Nested keys of the file, ``{"links[1].damping_ratio": 0.005}`` (values as given), or
        the command line's ``["links[1].damping_ratio=0.005"]`` strings.
    modes : {"frozen", "scheduled"}
        Modal parameters fixed at ``reference_q`` or scheduled with the configuration.
    reference_q : sequence of float, optional
        Joint angles (rad) of the frozen modes; default the file's ``configuration``.
    damping : {"ratio", "paper"}
        Modal damping ``d = 2 zeta omega m`` or Eq 68 of Subedi et al. as printed; default:
        the file's ``damping_form`` (``"ratio"`` when it has none).
    **keys
        Top-level keys of the model file (``gravity=[0.0, 0.0]`` in m/s^2,
        ``configuration=[0, 90, 0]`` in degrees as in the file, ...).

    Returns
    -------
    flexctrl.dynamics.model.Model

    Raises
    ------
    SpecError
        For a key the file does not have or a value it does not allow, on one line naming
        the file, the key, the value and what is allowed, exactly as for the file itself.

    Examples
    --------
    >>> import flexctrl as fc
    >>> model = fc.load_model(
    ...     "models/subedi3link.toml", payload=2.0, fidelity="rigid", gravity=[0.0, 0.0]
    ... )
    >>> model.n_x, model.spec.payload.mass
    (6, 2.0)
    """
    path = shipped.find(path, "model")
    document = read_toml(path)
    source = str(path)
    values: dict[str, Any] = dict(keys)
    if payload is not None:
        values["payload.mass"] = payload
    if overrides is not None and not isinstance(overrides, (str, bytes)):
        if isinstance(overrides, Mapping):
            values.update(overrides)
        else:
            document = apply_overrides(document, list(overrides), source=f"{source} (--set)")
    elif overrides is not None:
        raise SpecError(
            f"value {overrides!r} is not allowed; allowed: a mapping {{'links[1].EI': 2.0}} or a "
            "list of "
            "'KEY=VALUE' strings",
            source=source,
            key="overrides",
        )
    document = apply_values(document, values, source=f"{source} (arguments)")
    arm = arm_from_document(document, f"{source} (arguments)" if values else source)
    return build_model(arm, fidelity, modes=modes, reference_q=reference_q, damping=damping)
