"""Argument helpers the commands share (no command module imports another)."""
from __future__ import annotations

from collections.abc import Iterable, Sequence

from ..errors import IdentificationError
from ..workflows.identify import check_payload

__all__ = ["parse_payload", "payload_values"]


def parse_payload(items: Iterable[str] | None) -> dict[str, float]:
    """``--payload NAME=VALUE ...`` as a mapping (the message names the item at fault)."""
    out: dict[str, float] = {}
    for it in items or ():
        if "=" not in it:
            raise IdentificationError(f"--payload {it!r}: expected NAME=VALUE, e.g. M8=4.6136")
        k, v = it.split("=", 1)
        k = k.strip()
        try:
            out[k] = float(v)
        except ValueError:
            raise IdentificationError(f"--payload {k}={v!r}: value is not a number") from None
    return out


def payload_values(items: Iterable[str] | None, names: Sequence[str]) -> dict[str, float]:
    """``--payload NAME=VALUE ...`` parsed and each name checked against the robot's payload parameters."""
    return check_payload(parse_payload(items), names)
