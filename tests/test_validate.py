"""The validators of values that come from outside (flags, files)."""

from __future__ import annotations

import pytest

from relaxgrip.errors import InputError
from relaxgrip.validate import (
    MAX_JOBS,
    check_jobs,
    parse_floats,
    parse_integer,
    parse_names,
    parse_number,
    parse_seeds,
)


@pytest.mark.parametrize(("text", "seeds"), [("10-15", [10, 11, 12, 13, 14, 15]),
                                             ("3,5,8", [3, 5, 8]), ("0-2, 7", [0, 1, 2, 7]),
                                             ("4", [4])])
def test_seed_lists(text: str, seeds: list[int]) -> None:
    assert parse_seeds(text) == seeds


def test_ten_thousand_seeds_are_the_most() -> None:
    assert len(parse_seeds("0-9999")) == 10_000


@pytest.mark.parametrize("text", ["", "a-b", "3-1", "-2", "1,1", "2-4,3", "0-100000000",
                                  "0-9999,20000", "\uff15", "1-\uff19", "\u0663", "1_0", "+3",
                                  "1,,2"])
def test_bad_seed_lists_are_refused(text: str) -> None:
    with pytest.raises(InputError, match="seed"):
        parse_seeds(text)


@pytest.mark.parametrize(("text", "values"), [("1,3,5,8", [1.0, 3.0, 5.0, 8.0]),
                                              (" 2.5 , 40", [2.5, 40.0]), ("7", [7.0])])
def test_number_lists(text: str, values: list[float]) -> None:
    assert parse_floats(text, "--targets") == values


@pytest.mark.parametrize(("text", "match"), [("", "numbers like"), ("1,x", "numbers like"),
                                             ("1,,2", "numbers like"), ("nan", "finite"),
                                             ("1,inf", "finite"), ("5,5.0", "repeats")])
def test_bad_number_lists_are_refused(text: str, match: str) -> None:
    with pytest.raises(InputError, match=match) as info:
        parse_floats(text, "--temps")
    assert str(info.value).startswith("--temps")


@pytest.mark.parametrize(("text", "names"), [("standard,ramp", ["standard", "ramp"]),
                                             (" step ", ["step"])])
def test_name_lists(text: str, names: list[str]) -> None:
    assert parse_names(text, "--scenarios") == names


@pytest.mark.parametrize(("text", "match"), [("", "empty item"), ("standard,,ramp", "empty item"),
                                             ("ramp,", "empty item"),
                                             ("standard,standard", "repeats a name")])
def test_bad_name_lists_are_refused(text: str, match: str) -> None:
    with pytest.raises(InputError, match=match) as info:
        parse_names(text, "--scenarios")
    assert str(info.value).startswith("--scenarios")


@pytest.mark.parametrize(("text", "value"), [
    ("5", 5.0), ("-1.5", -1.5), (" 2. ", 2.0), (".5", 0.5), ("1e-3", 1e-3), ("+2.5E+04", 2.5e4),
    ("inf", float("inf")), ("-Infinity", float("-inf")),
])
def test_numbers_as_people_write_them(text: str, value: float) -> None:
    assert parse_number(text) == value


@pytest.mark.parametrize("text", ["0_5", "1_000", "\u0663", "\uff15", "1,5", "", ".", "1e",
                                  "e3", "0x10", "5N", "1.2.3"])
def test_what_float_takes_but_no_one_means_is_not_a_number(text: str) -> None:
    with pytest.raises(ValueError, match="not a number"):
        parse_number(text)


def test_integers_are_ascii_digits() -> None:
    assert parse_integer(" -12 ") == -12
    for text in ("1_0", "\u0663", "1.0", "", "+"):
        with pytest.raises(ValueError, match="not an integer"):
            parse_integer(text)


def test_a_worker_count_is_from_one_to_the_most_processes() -> None:
    assert check_jobs(1) == 1
    assert check_jobs(MAX_JOBS) == MAX_JOBS
    for bad, message in ((0, ">= 1"), (-3, ">= 1"), (MAX_JOBS + 1, "at most"),
                         (10**20, "at most")):
        with pytest.raises(InputError, match=message):
            check_jobs(bad)
