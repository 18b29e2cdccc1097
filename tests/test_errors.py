import pytest

from safenav import errors


@pytest.mark.parametrize(
    ("exception", "builtins"),
    [
        (errors.InvalidScan, (ValueError,)),
        (errors.InvalidScanType, (ValueError, TypeError)),
        (errors.InvalidCommand, (ValueError,)),
        (errors.InvalidCommandType, (ValueError, TypeError)),
        (errors.InvalidConfig, (ValueError,)),
        (errors.UnknownName, (ValueError,)),
        (errors.LidarMismatch, (ValueError,)),
        (errors.MissingDependency, (ImportError,)),
    ],
)
def test_every_error_is_a_safenav_error_and_its_builtin(exception, builtins):
    assert issubclass(exception, errors.SafeNavError)
    for builtin in builtins:
        assert issubclass(exception, builtin)


def test_unknown_name_lists_the_known_names_sorted():
    error = errors.UnknownName("robot preset", "turtlebot", ["rosbot", "m2wr"])
    assert str(error) == "unknown robot preset 'turtlebot'; expected one of: m2wr, rosbot"
    assert error.known == ("m2wr", "rosbot")


def test_missing_dependency_gives_the_pip_line():
    error = errors.MissingDependency("rosbags", "reading ROS bags")
    assert "pip install rosbags" in str(error)


@pytest.mark.parametrize(
    "error",
    [
        errors.UnknownName("filter", "rrt", ["cbf", "mpc"], hint="see make_filter"),
        errors.MissingDependency("rosbags", "reading ROS bags"),
        errors.InvalidScan("ranges is empty; expected at least one beam"),
        errors.LidarMismatch("scan mount (0, 0, 0) contradicts the mount (0, 0, 3.142)"),
    ],
)
def test_errors_survive_pickling_between_processes(error):
    import pickle

    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is type(error) and str(copy) == str(error)


def test_lidar_mismatch_warning_is_a_safenav_user_warning():
    assert issubclass(errors.LidarMismatchWarning, errors.SafeNavWarning)
    assert issubclass(errors.SafeNavWarning, UserWarning)
    assert not issubclass(errors.SafeNavWarning, errors.SafeNavError)   # a warning, never raised by default
