"""The value checks added for the worlds, the policies and the command lines (angles, vectors, files, argparse)."""

import argparse
import math

import numpy as np
import pytest

from safenav import InvalidConfig
from safenav._checks import (
    angle,
    argument_type,
    choice,
    integer,
    optional_integer,
    positive,
    vector,
    writable_file,
)


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: angle("P.span", 7.0, high=2 * math.pi), InvalidConfig, r"P\.span must be an angle in \(0, 6\.28319\] rad"),
    (lambda: angle("P.span", 0.0, high=1.0), InvalidConfig, r"P\.span must be an angle in \(0, 1\] rad, got 0\.0"),
    (lambda: angle("P.cone", -0.1, high=1.0, allow_zero=True), InvalidConfig, r"must be an angle in \[0, 1\] rad"),
    (lambda: angle("P.cone", math.nan, high=1.0), InvalidConfig, r"P\.cone must be a finite number, got nan"),
    (lambda: vector("W.start", (1.0, 2.0), 3, expected="a pose"), InvalidConfig, r"W\.start must be a pose, got"),
    (lambda: vector("W.goal", "ab", 2), InvalidConfig, r"W\.goal must be a sequence of 2 finite numbers, got 'ab'"),
    (lambda: vector("W.goal", (1.0, math.inf), 2), InvalidConfig, r"W\.goal\[1\] must be a finite number, got inf"),
    (lambda: vector("W.goal", (True, 1.0), 2), InvalidConfig, r"W\.goal\[0\] must be a finite number, got True"),
    (lambda: optional_integer("P.i", -1, low=0), InvalidConfig, r"P\.i must be an integer >= 0 or None, got -1"),
    (lambda: optional_integer("P.index", 2.0), InvalidConfig, r"P\.index must be an integer or None, got 2\.0"),
])
def test_bad_values_name_the_setting_and_what_was_expected(call, error, message):
    with pytest.raises(error, match=message) as info:
        call()
    assert isinstance(info.value, ValueError)


def test_good_values_come_back_converted():
    assert angle("a", 0, high=1.0, allow_zero=True) == 0.0 and isinstance(angle("a", 1, high=2.0), float)
    assert vector("v", np.array([1, 2]), 2) == (1.0, 2.0) and vector("v", [0.5, -1, 2], 3) == (0.5, -1.0, 2.0)
    assert optional_integer("i", None) is None and optional_integer("i", np.int64(3), low=0) == 3


def test_writable_file_creates_the_folders_and_leaves_no_file(tmp_path):
    target = tmp_path / "new" / "deeper" / "out.png"
    assert writable_file("--plot", target) == target
    assert target.parent.is_dir() and not target.exists()
    existing = tmp_path / "kept.txt"
    existing.write_text("data")
    writable_file("--plot", existing)
    assert existing.read_text() == "data"   # appended nothing, removed nothing


def test_writable_file_says_why_it_cannot_write(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(InvalidConfig, match=r"cannot write --plot '.*file/deeper/out\.png': '.*file' is a file, not"):
        writable_file("--plot", blocker / "deeper" / "out.png")
    with pytest.raises(InvalidConfig, match=r"cannot write --plot '/proc/out\.png': No such file or directory"):
        writable_file("--plot", "/proc/out.png")
    with pytest.raises(InvalidConfig, match="is a folder; expected the path of a file to write"):
        writable_file("--plot", tmp_path)


@pytest.mark.parametrize(("parse", "text", "value"), [
    (argument_type(integer, low=1), "3", 3),
    (argument_type(positive), "0.25", 0.25),
    (argument_type(positive), "2", 2.0),
    (argument_type(choice, name="robot", text=True, known=("m2wr", "rosbot")), "m2wr", "m2wr"),
])
def test_argument_types_parse_and_check(parse, text, value):
    result = parse(text)
    assert result == value and type(result) is type(value)


@pytest.mark.parametrize(("parse", "text", "message"), [
    (argument_type(integer, low=1), "0", "must be an integer >= 1, got 0"),
    (argument_type(integer, low=1), "2.5", "must be an integer >= 1, got 2.5 of type float"),
    (argument_type(positive), "-1", "must be a finite number > 0, got -1"),
    (argument_type(positive), "nan", "must be a finite number > 0, got nan"),
    (argument_type(positive), "fast", "must be a finite number > 0, got 'fast' of type str"),
    (argument_type(choice, name="robot", text=True, known=("m2wr", "rosbot")), "r2d2",
     "unknown robot 'r2d2'; expected one of: m2wr, rosbot"),
])
def test_argument_types_give_the_checks_message_to_argparse(parse, text, message):
    with pytest.raises(argparse.ArgumentTypeError) as info:
        parse(text)
    assert str(info.value) == message
