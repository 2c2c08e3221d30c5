"""Which joints a model family builds: the rigid, assumed-modes and finite-element arms model
revolute joints only (prismatic ones are the ``rp_arm`` and ``telescoping`` model kinds)."""

from __future__ import annotations

from flexctrl.errors import SpecError
from flexctrl.spec.arm import ArmSpec


def require_revolute(arm: ArmSpec, builder: str, instead: str) -> None:
    """Refuse a joint other than revolute: ``builder`` (a model family) models no other.

    Raises
    ------
    SpecError
        Naming the file, ``joints[i].type``, the value and ``instead`` (where such a joint is
        modelled).
    """
    for i, joint in enumerate(arm.joints):
        if joint.type != "revolute":
            raise SpecError(
                f"value {joint.type!r} is not supported by {builder}; allowed: 'revolute' "
                f"({instead})",
                source=arm.source,
                key=f"joints[{i + 1}].type",
            )


__all__ = ["require_revolute"]
