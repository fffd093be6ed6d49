"""geovs_drake._json.json_ready: what every result's summary() hands to json.dumps."""

import json
import math
from dataclasses import dataclass

import numpy as np
import pytest

from geovs_drake._json import json_ready


@dataclass
class _Result:
    name: str
    values: np.ndarray
    ok: np.bool_


def test_values_become_what_json_holds_and_read_back_the_same():
    value = {
        "nan": math.nan,
        "inf": np.float64(np.inf),
        "complex": np.array([1 + 2j, -3.5j]),
        "int": np.int64(7),
        "result": _Result("r", np.arange(3.0), np.bool_(True)),
        "tuple": (1.5, None, "x"),
    }
    out = json_ready(value)
    assert json.loads(json.dumps(out, allow_nan=False)) == {
        "nan": None,
        "inf": None,
        "complex": [[1.0, 2.0], [0.0, -3.5]],
        "int": 7,
        "result": {"name": "r", "values": [0.0, 1.0, 2.0], "ok": True},
        "tuple": [1.5, None, "x"],
    }
    assert type(out["int"]) is int and type(out["result"]["ok"]) is bool


def test_a_value_with_no_json_form_is_named():
    with pytest.raises(TypeError, match="no JSON form for object"):
        json_ready({"x": object()})


def test_every_summary_in_the_package_returns_json_ready():
    """Every ``summary()`` method's every return goes through ``json_ready`` (one place
    decides what JSON takes: NaN to null, numpy to Python), read from the source."""
    import ast
    from pathlib import Path

    import geovs_drake

    bypass = []
    for path in Path(geovs_drake.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and node.name == "summary":
                for ret in (n for n in ast.walk(node) if isinstance(n, ast.Return)):
                    call = ret.value
                    if not (
                        isinstance(call, ast.Call) and getattr(call.func, "id", "") == "json_ready"
                    ):
                        bypass.append(f"{path.name}:{ret.lineno}")
    assert not bypass, bypass
