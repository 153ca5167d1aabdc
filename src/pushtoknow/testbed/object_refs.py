"""Object references, resolved in one place: ``catalogue:ID`` (`objects.catalogue_object`),
``random:SEED:I`` (`random_shapes`), a JSON/YAML file or inline JSON (`objects.ObjectSpec`)."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from pushtoknow.common.errors import ObjectSpecError, yaml_error_summary
from pushtoknow.common.frozen_config import read_utf8
from pushtoknow.testbed.objects import ObjectSpec, catalogue_object
from pushtoknow.testbed.random_shapes import parse_random_ref


def load_object_spec(source: str | Path) -> ObjectSpec:
    """Object from ``catalogue:ID``, ``random:SEED:I`` (`random_shapes`), a JSON/YAML file
    path, or an inline JSON string."""
    s = str(source)
    if s.startswith("random:"):
        return parse_random_ref(s)
    if s.startswith("catalogue:"):
        key = s.split(":", 1)[1]
        try:
            idx = int(key)
        except ValueError:
            raise ObjectSpecError("catalogue id", key, "must be an integer 0..824") from None
        return catalogue_object(idx)
    if s.lstrip().startswith("{"):
        try:
            return ObjectSpec.from_dict(json.loads(s))
        except json.JSONDecodeError as e:
            raise ObjectSpecError("<inline json>", s[:60], f"not valid JSON: {e}") from None
    path = Path(s)
    if not path.exists():
        raise ObjectSpecError(
            "<file>", s, "no such file (and not of the form catalogue:ID or random:SEED:I)"
        )
    try:
        data = yaml.safe_load(read_utf8(path))  # YAML is a superset of JSON
    except yaml.YAMLError as e:
        raise ObjectSpecError("<file>", s, yaml_error_summary(e)) from None
    except ValueError as e:  # not UTF-8 text
        raise ObjectSpecError("<file>", s, str(e)) from None
    if not isinstance(data, dict):
        found = type(data).__name__
        raise ObjectSpecError("<file>", s, f"not an object spec: holds a {found}, not a mapping")
    return ObjectSpec.from_dict(data)
