"""Stamps: file-name strings <-> integer nanoseconds, exactly, never through a float."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cldet.errors import DatasetError
from cldet.stamps import format_stamp, parse_stamp

seconds_st = st.integers(min_value=0, max_value=10**10 - 1)
micros_st = st.integers(min_value=0, max_value=10**6 - 1)


@given(seconds=seconds_st, micros=micros_st)
def test_name_to_ns_to_name_round_trip(seconds: int, micros: int) -> None:
    name = f"{seconds}.{micros:06d}"
    ns = parse_stamp(name)
    assert ns == seconds * 1_000_000_000 + micros * 1_000
    assert format_stamp(ns) == name


@given(seconds=seconds_st, micros=micros_st)
def test_ns_to_name_to_ns_round_trip(seconds: int, micros: int) -> None:
    ns = seconds * 1_000_000_000 + micros * 1_000
    name = format_stamp(ns)
    assert len(name.split(".")[1]) == 6
    assert parse_stamp(name) == ns


@given(seconds=seconds_st, micros=micros_st, sub_us=st.integers(min_value=0, max_value=999))
def test_format_truncates_below_the_microsecond(seconds: int, micros: int, sub_us: int) -> None:
    ns = seconds * 1_000_000_000 + micros * 1_000
    assert format_stamp(ns + sub_us) == format_stamp(ns)


@given(seconds=seconds_st, micros=micros_st)
def test_float_printed_names_parse_to_the_same_ns(seconds: int, micros: int) -> None:
    # A float print drops trailing zeros of the fraction: .714190 -> .71419, .000000 -> .0
    fraction = f"{micros:06d}".rstrip("0") or "0"
    assert parse_stamp(f"{seconds}.{fraction}") == parse_stamp(f"{seconds}.{micros:06d}")


@given(text=st.text(max_size=30))
def test_any_text_parses_to_ns_or_raises_dataset_error(text: str) -> None:
    try:
        ns = parse_stamp(text)
    except DatasetError as err:
        assert "is not a timestamp" in str(err)
    else:
        assert isinstance(ns, int)
        assert ns >= 0


def test_known_stamps() -> None:
    assert parse_stamp("1706255621.600227") == 1_706_255_621_600_227_000
    assert parse_stamp("1706255621.71419") == 1_706_255_621_714_190_000
    assert parse_stamp("1706255630.30025") == 1_706_255_630_300_250_000
    assert parse_stamp("0.000001") == 1_000
    # Through a float the last digit is gone: the reason stamps are parsed as strings.
    assert int(float("1706255621.600227") * 1e9) != 1_706_255_621_600_227_000
    assert format_stamp(1_706_255_621_714_190_000) == "1706255621.714190"


@pytest.mark.parametrize(
    "bad",
    [
        "",
        "1706255621",
        "1706255621.",
        ".600227",
        "1706255621.6002271",  # 7 decimals
        "-1706255621.600227",
        "+1706255621.600227",
        "1706255621,600227",
        " 1706255621.600227",
        "1706255621.600227 ",
        "1706255621.600227\n",
        "1.7e9",
        "1706255621.600227.npy",
        "abc.def",
        "\u0661\u0667\u0660\u0666.\u0665",  # Arabic-Indic digits are not stamps
        "1234567890123.5",  # 13 digits of seconds
    ],
)
def test_bad_strings_are_rejected(bad: str) -> None:
    with pytest.raises(
        DatasetError, match="is not a timestamp: expected Unix seconds with 1-6 decimals"
    ):
        parse_stamp(bad)


def test_format_rejects_negative() -> None:
    with pytest.raises(ValueError, match="must be non-negative, got -1 ns"):
        format_stamp(-1)
