"""The option converters and the one-line error messages of ``cli/_options.py``."""

import argparse

import pytest

from lidarstat.cli import build_parser
from lidarstat.cli import _options as opt
from lidarstat.errors import InsufficientNeighborsError, InvalidParameterError


@pytest.mark.parametrize("convert,text,value", [
    (opt.positive_float, "0.5", 0.5),
    (opt.nonnegative_float, "0", 0.0),
    (opt.probability, "0.05", 0.05),
    (opt.probability_or_zero, "0", 0.0),
    (opt.finite_float, "-3e5", -3e5),
    (opt.int_at_least(1), " 4 ", 4),
    (opt.int_range(1, 3), "3", 3),
    (opt.angle_degrees(0, 180), "180", 180.0),
    (opt.codes_list, "2, 8,9", (2, 8, 9)),
    (opt.codes_list, "0,255,", (0, 255)),
    (opt.one_of_or(("auto",), opt.int_range(1, 3), "1, 2, 3 or 'auto'"), "auto", "auto"),
    (opt.seed, "0", 0),
])
def test_converters_accept(convert, text, value):
    assert convert(text) == value


@pytest.mark.parametrize("convert,text,words", [
    (opt.positive_float, "0", "must be a number > 0"),
    (opt.positive_float, "nan", "must be a finite number > 0"),
    (opt.positive_float, "-inf", "must be a finite number > 0"),
    (opt.positive_float, "1e999", "must be a finite number > 0"),
    (opt.positive_float, "abc", "must be a number > 0"),
    (opt.nonnegative_float, "-0.1", "must be a number >= 0"),
    (opt.probability, "1", "must be a probability in (0, 1)"),
    (opt.probability_or_zero, "-0.5", "must be a probability in [0, 1)"),
    (opt.finite_float, "inf", "must be a finite number"),
    (opt.int_at_least(1), "0", "must be an integer >= 1"),
    (opt.int_at_least(1), "2.5", "must be an integer >= 1"),
    (opt.int_range(1, 6), "7", "must be an integer from 1 to 6"),
    (opt.angle_degrees(0, 180), "720", "must be an angle in degrees in (0, 180]"),
    (opt.codes_list, "", "class codes from 0 to 255"),
    (opt.codes_list, " , ", "class codes from 0 to 255"),
    (opt.codes_list, "2,abc", "class codes from 0 to 255"),
    (opt.codes_list, "256", "class codes from 0 to 255"),
])
def test_converters_refuse_with_the_value(convert, text, words):
    with pytest.raises(argparse.ArgumentTypeError) as err:
        convert(text)
    assert str(err.value) == f"invalid value {text!r}: {words}" or words in str(err.value)
    assert str(err.value).startswith(f"invalid value {text!r}: ")


def test_every_option_of_every_command_has_a_checked_domain():
    """No option takes a number through a bare int or float."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    seen = 0
    for name, command in sub.choices.items():
        for action in command._actions:
            if action.type is not None:
                seen += 1
                assert action.type not in (int, float), (name, action.option_strings)
    assert seen >= 79


def test_usage_error_is_one_line(capsys):
    assert build_parser  # the parser of main()
    from lidarstat.cli import main

    assert main(["covariance", "a.las", "b.las", "--k", "0"]) == 2
    err = capsys.readouterr().err
    assert err == ("lidarstat covariance: error: argument --k: invalid value '0': must be an "
                   "integer >= 3\n")


def _args(argv):
    return build_parser().parse_args(argv)


def test_error_line_names_the_input_and_the_option():
    args = _args(["covariance", "in/scan.las", "out.las", "--k", "8"])
    exc = InvalidParameterError("The 'k' parameter of covariance_features must be an int in "
                                "the range [3, 2]. Got 8 instead.")
    assert opt.error_line(exc, args) == ("in/scan.las: --k must be an int in the range [3, 2]. "
                                         "Got 8 instead.")
    exc = InsufficientNeighborsError("jets: no point has 16 neighbours\nsecond line")
    assert opt.error_line(exc, args) == "in/scan.las: jets: no point has 16 neighbours"
    exc = InvalidParameterError("the estimated noise is 0; give `sigma` (`points` exact)")
    assert opt.error_line(exc, args) == ("in/scan.las: the estimated noise is 0; give --sigma "
                                         "(`points` exact)")


def test_error_line_keeps_a_message_that_starts_with_a_path():
    args = _args(["ridges", "scan.las", "out.las", "--radius", "1"])
    for msg in ("scan.las: the file holds no points", "out.las: refusing to overwrite",
                "/tmp/x/other.laz: unreadable"):
        assert opt.error_line(InvalidParameterError(msg), args) == msg


def test_error_line_without_an_input():
    args = _args(["bandwidth", "--K0", "0", "--H0", "1", "--sigma", "0.1", "--density", "9"])
    exc = InvalidParameterError("no radius detects these curvatures")
    assert opt.error_line(exc, args) == "no radius detects these curvatures"


def test_cross_check_tile_against_radius(capsys):
    from lidarstat.cli import main

    assert main(["curvature", "a.las", "b.las", "--radius", "0.5", "2", "--tile", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lidarstat curvature: error: argument --tile: invalid value '2': "
                          "must be larger than the largest --radius (2)")
