"""Configuration error texts: a suggestion for a misspelt key, no library prefix, no empty reason."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import BaseModel, ValidationError, field_validator

from cldet.config import _describe, load_config
from cldet.errors import ConfigError


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "c.yaml"
    path.write_text(text)
    return path


def test_a_misspelt_key_gets_a_suggestion(tmp_path: Path) -> None:
    with pytest.raises(
        ConfigError,
        match=r"unknown key 'smoothing\.accel_pds' \(did you mean 'smoothing\.accel_psd'\?\)$",
    ):
        load_config(write(tmp_path, "smoothing:\n  accel_pds: 1.0\n"))
    with pytest.raises(ConfigError, match=r"unknown key 'methd' \(did you mean 'method'\?\)$"):
        load_config(write(tmp_path, "methd: track\n"))


def test_an_unknown_key_without_a_close_one_lists_the_known_keys(tmp_path: Path) -> None:
    with pytest.raises(
        ConfigError, match=r"unknown key 'smoothing\.zzz'; known keys here: .*accel_psd"
    ):
        load_config(write(tmp_path, "smoothing:\n  zzz: 1\n"))


class _Sorted(BaseModel):
    values: list[int]

    @field_validator("values")
    @classmethod
    def _check(cls, values: list[int]) -> list[int]:
        if values != sorted(values):
            raise ValueError("must be sorted")
        if not values:
            raise ValueError("")
        return values


@pytest.mark.parametrize(
    ("values", "shown"),
    [([2, 1], "values = [2, 1]: must be sorted"), ([], "values = []: value error")],
)
def test_no_library_prefix_and_no_empty_reason(values: list[int], shown: str) -> None:
    with pytest.raises(ValidationError) as caught:
        _Sorted(values=values)
    text = _describe(caught.value)
    assert text == shown
    assert "Value error," not in text and not text.rstrip().endswith(":")
