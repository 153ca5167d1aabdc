"""Typed configuration: pydantic models loadable from YAML."""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from pushtoknow.common.errors import ConfigError

T = TypeVar("T", bound="Config")


def read_utf8(path: str | Path) -> str:
    """The text of a YAML or JSON file, which is UTF-8. Raises ValueError "not UTF-8 text (…)"
    for a binary, Latin-1 or UTF-16 file, OSError when it cannot be read."""
    data = Path(path).read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(
            f"not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start}): expected a YAML "
            "or JSON file"
        ) from None


class Config(BaseModel):
    """Base of every config: unknown keys are errors, values are validated."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @classmethod
    def from_yaml(cls: type[T], path: str | Path) -> T:
        """Load and validate. Raises ConfigError naming the file and every bad field (and
        OSError when the file cannot be read)."""
        try:
            text = read_utf8(path)
        except ValueError as e:
            raise ConfigError(path, str(e)) from None
        try:
            data = yaml.safe_load(text) or {}
        except yaml.YAMLError as e:
            where = getattr(e, "problem_mark", None)
            line = f" (line {where.line + 1})" if where is not None else ""
            raise ConfigError(path, f"not valid YAML{line}") from None
        if not isinstance(data, dict):
            raise ConfigError(path, f"expected a mapping of settings, got {type(data).__name__}")
        try:
            return cls.model_validate(data)
        except ValidationError as e:
            problems = "; ".join(
                f"{'.'.join(map(str, err['loc'])) or '(root)'}: {err['msg']}" for err in e.errors()
            )
            raise ConfigError(path, f"invalid {cls.__name__}: {problems}") from None

    def to_yaml(self, path: str | Path) -> None:
        Path(path).write_text(yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False))
