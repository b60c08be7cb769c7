"""Sidecar validation with jsonschema-rs: the same verdicts as fastjsonschema's (which still
checks what jsonschema-rs does not take), each naming the field at fault."""

from __future__ import annotations

import copy
import json
import math
import random
from typing import Any

import fastjsonschema
import numpy as np
import pytest

from tests.unit.recorder.test_data_standard import ICD_EXAMPLE
from thermcap.recorder.exceptions import SidecarError
from thermcap.recorder.icd.sidecar import SIDECAR_SCHEMA, SidecarEncoder, dumps_sidecar, validate_sidecar

_REFERENCE = fastjsonschema.compile(SIDECAR_SCHEMA)
_BLOCKS = ("capture", "environment", "thermal_analysis", "slew_to_cue", "targets")


def _reference(doc: dict[str, Any]) -> str | None:
    """fastjsonschema's verdict: None, or the field it names."""
    try:
        _REFERENCE(doc)
    except fastjsonschema.JsonSchemaValueException as exc:
        return (exc.name or "data").removeprefix("data").lstrip(".") or "<root>"
    return None


def _ours(doc: dict[str, Any]) -> str | None:
    try:
        validate_sidecar(doc)
    except SidecarError as exc:
        return exc.field
    return None


def _leaves(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else None
    if items is None:
        return [path]
    out = [path] if path else []
    for k, v in items:
        out += _leaves(v, (*path, k))
    return out


_ODD = [None, True, False, 0, -1, 2, 1.5, -7.25, 1e300, "", "x", "2026-01-11T15:30:45Z", [], [1, 2], {}, {"a": 1},
        [1, 2, 3, 4], 101, 0.999, "idle", "detector"]


def test_one_change_anywhere_gets_the_reference_verdict_and_field() -> None:
    rng = random.Random(3)
    base = copy.deepcopy(ICD_EXAMPLE)
    base["targets"].append(copy.deepcopy(base["targets"][0]) | {"target_id": "TGT002"})
    paths = _leaves(base)
    checked = invalid = 0
    for _ in range(3000):
        doc = copy.deepcopy(base)
        path = rng.choice(paths)
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        if rng.random() < 0.15 and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = copy.deepcopy(rng.choice(_ODD))
        theirs, ours = _reference(doc), _ours(doc)
        assert (theirs is None) == (ours is None), (path, theirs, ours)
        if theirs is not None:  # a missing property: fastjsonschema names its object, we name it
            assert ours == theirs or (ours or "").startswith("" if theirs == "<root>" else theirs + "."), \
                (path, theirs, ours)
            invalid += 1
        checked += 1
    assert invalid > 500 and checked - invalid > 300  # both verdicts were exercised


@pytest.mark.parametrize("path,value,field,problem", [
    (("targets", 0, "confidence"), 1.5, "targets[0].confidence", "maximum"),
    (("capture", "timestamp"), "yesterday", "capture.timestamp", "yesterday"),
    (("thermal_analysis", "thermal_contrast_grade"), math.nan, "thermal_analysis.thermal_contrast_grade", "finite"),
    (("targets", 0, "target_id"), math.inf, "targets[0].target_id", "inf"),
])
def test_a_frame_s_blocks_name_the_field(path, value, field, problem) -> None:
    enc = SidecarEncoder(ICD_EXAMPLE["sensor"], ICD_EXAMPLE["radiometric"])
    blocks = copy.deepcopy({k: ICD_EXAMPLE[k] for k in _BLOCKS})
    node = blocks
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    with pytest.raises(SidecarError) as err:
        enc.encode(blocks)
    assert err.value.field == field and problem in err.value.problem


def test_a_missing_block_or_field_is_named() -> None:
    enc = SidecarEncoder(ICD_EXAMPLE["sensor"], ICD_EXAMPLE["radiometric"])
    blocks = copy.deepcopy({k: ICD_EXAMPLE[k] for k in _BLOCKS})
    del blocks["slew_to_cue"]
    with pytest.raises(SidecarError) as err:
        enc.encode(blocks)
    assert (err.value.field, err.value.problem) == ("slew_to_cue", "is required")
    blocks = copy.deepcopy({k: ICD_EXAMPLE[k] for k in _BLOCKS})
    del blocks["thermal_analysis"]["snr_db"]
    with pytest.raises(SidecarError) as err:
        enc.encode(blocks)
    assert err.value.field == "thermal_analysis.snr_db"


def test_nan_where_null_is_allowed_is_refused_when_written() -> None:
    doc = copy.deepcopy(ICD_EXAMPLE)
    doc["thermal_analysis"]["snr_db"] = math.nan  # the schema takes null here, JSON has no NaN
    with pytest.raises(SidecarError) as err:
        dumps_sidecar(doc)
    assert err.value.field == "thermal_analysis.snr_db" and "finite" in err.value.problem


def test_numpy_values_are_checked_as_before() -> None:
    """jsonschema-rs refuses numpy scalars outright; fastjsonschema takes a float64 (a float) and
    refuses an int64 where an integer must be, naming it, as it always did."""
    enc = SidecarEncoder(ICD_EXAMPLE["sensor"], ICD_EXAMPLE["radiometric"])
    blocks = copy.deepcopy({k: ICD_EXAMPLE[k] for k in _BLOCKS})
    blocks["thermal_analysis"]["snr_db"] = np.float64(28.5)
    assert json.loads(enc.encode(blocks))["thermal_analysis"]["snr_db"] == 28.5
    blocks["targets"][0]["bbox"] = [np.int64(245), 180, 280, 215]
    with pytest.raises(SidecarError) as err:
        enc.encode(blocks)
    assert err.value.field.startswith("targets[0].bbox")


def test_a_document_that_contains_itself_is_a_sidecar_error() -> None:
    enc = SidecarEncoder(ICD_EXAMPLE["sensor"], ICD_EXAMPLE["radiometric"])
    blocks = copy.deepcopy({k: ICD_EXAMPLE[k] for k in _BLOCKS})
    blocks["capture"]["again"] = blocks["capture"]  # extra fields are allowed, so the schema passes it
    with pytest.raises(SidecarError, match="contains itself"):
        enc.encode(blocks)
