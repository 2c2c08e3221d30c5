"""The one spelling of model fidelity, shared by the CLI and study files.

``rigid``      no elastic coordinates;
``amm:N``      assumed modes, N per link (0..6; ``amm:0`` is the rigid arm built by the
               assumed-modes code);
``fem:N``      floating-frame finite elements, N elements per link (1..64);
``auto``       chosen per scene from an accuracy tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from flexctrl.errors import SpecError

KINDS = ("rigid", "amm", "fem", "auto")
#: How ``fidelity = "auto"`` walks the ladder for a closed loop (``fidelity_walk``;
#: :mod:`flexctrl.scenes.auto_closed_loop`): ``estimate`` (the default: linear estimates of the
#: rungs first, or the nonlinear walk from the top rung down for a controller stepped in
#: Python; the reference model at its own step, its step error estimated linearly) or
#: ``ladder`` (nonlinear runs only, from the bandwidth rule's start; the reference at a small
#: step and half of it: no linear assumption, at several times the cost).
FIDELITY_WALKS = ("estimate", "ladder")
#: What ``fidelity = "auto"`` checks beyond the tolerance (``fidelity_checks``;
#: flexctrl.fidelity.ladder.walk_and_judge): ``full`` (the rung below a rung that meets the
#: tolerance is tried, so the choice is the lowest that meets it; the reference's step is checked)
#: or ``tolerance`` (only the runs that certify the tolerance: the chosen rung, the rungs its
#: estimate needs and the reference; the choice may be higher than needed, the reference's step is
#: not checked).
FIDELITY_CHECKS = ("full", "tolerance")
_LIMITS = {"amm": (0, 6), "fem": (1, 64)}
SPELLINGS = (
    "'rigid', 'amm:N' (N = 0..6 modes per link), 'fem:N' (N = 1..64 elements per link) or 'auto'"
)


@dataclass(frozen=True)
class Fidelity:
    """A parsed fidelity: ``kind`` and, for ``amm``/``fem``, the count per link."""

    kind: Literal["rigid", "amm", "fem", "auto"]
    count: int | None = None

    def __str__(self) -> str:
        return self.kind if self.count is None else f"{self.kind}:{self.count}"

    @property
    def modes_per_link(self) -> int | None:
        """Assumed modes per link (0 for rigid), or None for other kinds."""
        if self.kind == "rigid":
            return 0
        return self.count if self.kind == "amm" else None


def parse_fidelity(
    text: str, *, source: str | None = None, key: str | None = "fidelity"
) -> Fidelity:
    """Parse a fidelity spelling.

    Parameters
    ----------
    text
        E.g. ``"amm:2"``, ``"fem:8"``, ``"rigid"``, ``"auto"``.
    source, key
        Used in the error message.

    Raises
    ------
    SpecError
        For any other spelling, naming what is allowed.
    """
    if isinstance(text, Fidelity):
        return text
    if not isinstance(text, str):
        raise SpecError(
            f"value {text!r} is not a string; allowed: {SPELLINGS}", source=source, key=key
        )
    raw = text.strip().lower()
    if raw in ("rigid", "auto"):
        return Fidelity(raw)  # type: ignore[arg-type]
    kind, sep, count = raw.partition(":")
    if kind in _LIMITS and sep and count.isdigit():
        low, high = _LIMITS[kind]
        n = int(count)
        if low <= n <= high:
            return Fidelity(kind, n)  # type: ignore[arg-type]
    raise SpecError(
        f"value {text!r} is not a fidelity; allowed: {SPELLINGS}", source=source, key=key
    )
