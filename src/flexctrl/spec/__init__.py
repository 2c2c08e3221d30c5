"""Plain-data descriptions (arms, scenes, controllers, studies), loaded from TOML and validated."""

from flexctrl.spec.arm import ArmSpec, JointSpec, LinkSpec, PayloadSpec, SectionSpec, load_arm
from flexctrl.spec.overrides import apply_overrides, parse_value
from flexctrl.spec.reader import TableReader, read_toml

__all__ = [
    "ArmSpec",
    "JointSpec",
    "LinkSpec",
    "PayloadSpec",
    "SectionSpec",
    "load_arm",
    "apply_overrides",
    "parse_value",
    "TableReader",
    "read_toml",
]
