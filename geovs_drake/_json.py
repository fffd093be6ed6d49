"""Values as JSON takes them, decided here once: what every result's ``summary()`` returns.

numpy scalars and arrays become Python numbers and lists, a complex number ``[re, im]``,
a non-finite float ``None`` (JSON has no NaN), a dataclass the mapping of its fields.
"""

import dataclasses
import math
from typing import Any

import numpy as np

__all__ = ["json_ready"]


def json_ready(value: Any) -> Any:
    """``value`` with every part JSON can hold as itself and the rest converted (module
    docstring); ``json.dumps`` takes the result as it is."""
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, np.generic):
        return json_ready(value.item())
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, complex):
        return [json_ready(value.real), json_ready(value.imag)]
    if isinstance(value, np.ndarray):
        return [json_ready(v) for v in value.tolist()]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: json_ready(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    raise TypeError(f"no JSON form for {type(value).__name__}: {value!r}")
