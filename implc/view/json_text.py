"""JSON that every browser parses: JSON has no NaN or infinity, so a non-finite number is written as null
(Python's json module would write ``NaN``, which ``JSON.parse`` refuses)."""

from __future__ import annotations

import json
import math
from typing import Any


def finite(value: Any) -> Any:
    """``value`` with every non-finite float (at any depth of lists, tuples and dicts) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    if hasattr(value, "item") and hasattr(value, "dtype"):  # a numpy scalar
        return finite(value.item())
    return value


def json_bytes(value: Any) -> bytes:
    """``value`` as strict JSON (UTF-8)."""
    return json.dumps(finite(value), allow_nan=False).encode()
