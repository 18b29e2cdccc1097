"""The README's set-up commands are the ones CI runs."""

import json
import math
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def setup_commands() -> list[str]:
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Set up", 1)[1].split("\n## ", 1)[0]
    return [block.strip() for block in re.findall(r"```bash\n(.*?)```", section, flags=re.S)]


def test_readme_has_exactly_two_setup_commands():
    commands = setup_commands()
    assert len(commands) == 2
    assert all("\n" not in command for command in commands)
    assert commands[0].endswith("safenav demo")
    assert commands[1].endswith("pytest")


def test_ci_runs_exactly_the_readme_test_command():
    ci_lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    assert setup_commands()[1] in ci_lines
    assert "set -euo pipefail" in ci_lines


def python_examples() -> list[str]:
    readme = (ROOT / "README.md").read_text()
    return re.findall(r"```python\n(.*?)```", readme, flags=re.S)


def python_example(containing: str) -> str:
    """The README's one Python example that contains ``containing``."""
    (example,) = [code for code in python_examples() if containing in code]
    return example


def test_readme_filter_example_runs_on_a_ros_like_message():
    import math
    from types import SimpleNamespace

    namespace: dict = {}
    exec(python_example("def control_step"), namespace)
    header = SimpleNamespace(stamp=SimpleNamespace(sec=100, nanosec=0), frame_id="laser")
    message = SimpleNamespace(header=header, angle_min=-math.pi, angle_max=math.pi, angle_increment=2 * math.pi / 719,
                              time_increment=0.0, scan_time=0.1, range_min=0.15, range_max=12.0,
                              ranges=[0.5] * 720, intensities=[])
    u = namespace["control_step"](message, (0.3, 0.0), (1.0, 0.0), 100.02)
    assert 0.0 <= u[0] < 1.0          # a wall 0.5 m all round: the filter slows the robot down
    u = namespace["control_step"](message, (0.3, 0.0), (1.0, 0.0), 101.0)
    assert u[0] < 0.3                 # the same scan a second later is stale: the filter brakes


def test_readme_own_robot_example_builds_a_polygon_filter_for_its_lidar():
    namespace: dict = {}
    exec(python_example("RobotSpec(name="), namespace)
    safety, lidar = namespace["safety"], namespace["lidar"]
    assert safety.robot.lidar == lidar and safety.config.body == "polygon"
    assert safety.robot.radius >= max(math.hypot(x, y) for x, y in safety.robot.footprint)
    # "a robot can live in a file"
    my_robot = namespace["my_robot"]
    assert type(my_robot).from_dict(json.loads(json.dumps(my_robot.to_dict()))) == my_robot


@pytest.mark.sim
def test_readme_gymnasium_example_runs_and_says_what_the_shield_did(capsys):
    pytest.importorskip("gymnasium", reason="the gym extra is not installed")
    exec(python_example("SafetyShield("), {})
    status = capsys.readouterr().out.split()[0]
    assert status in {"ok", "recovering", "slack", "braking"}


@pytest.mark.sim
def test_readme_shield_example_runs_without_collision(capsys):
    exec(python_example("BulletSim"), {})
    assert "collided: False" in capsys.readouterr().out


# ---------------------------------------------------------------- the install fits a robot computer

def test_ci_installs_the_debian_packages_the_ros1_node_names():
    from safenav.ros.apps import ROS1_DEBIAN_PACKAGES

    script = (ROOT / ".ci" / "run").read_text()
    listed = re.search(r'^ROS1_PACKAGES="([^"]*)"', script, flags=re.M)
    assert listed is not None
    assert tuple(listed.group(1).split()) == ROS1_DEBIAN_PACKAGES


def test_readme_main_command_installs_the_simulator_extra_and_tests_install_the_test_extra():
    demo, tests = setup_commands()
    assert 'pip install ".[sim]"' in demo
    assert 'pip install ".[test]"' in tests


def _pyproject() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def _names(requirements: list[str]) -> set[str]:
    return {re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower() for requirement in requirements}


def test_core_dependencies_are_only_what_the_filters_need_with_lower_bounds_only():
    project = _pyproject()["project"]
    assert _names(project["dependencies"]) == {"numpy", "scipy", "qpsolvers", "daqp", "osqp", "casadi"}
    extras = project["optional-dependencies"]
    assert {"sim", "ros", "ros2", "gym", "rl", "test", "all"} <= set(extras)
    assert "pybullet" in _names(extras["sim"])
    every = [r for group in (project["dependencies"], *extras.values()) for r in group]
    assert not [r for r in every if "<" in r or "==" in r], "lower bounds only"
    assert {"safenav"} <= _names(extras["test"]) and "sim" in extras["test"][0] and "ros2" in extras["test"][0]


def test_every_extra_the_code_names_exists():
    """``require(..., extra="X")`` tells users to ``pip install "safenav[X]"``: X must be an extra."""
    extras = set(_pyproject()["project"]["optional-dependencies"])
    named = {(path.relative_to(ROOT).as_posix(), extra) for path in (ROOT / "safenav").rglob("*.py")
             for extra in re.findall(r'extra="([^"]+)"', path.read_text())}
    assert named and {(path, extra) for path, extra in named if extra not in extras} == set()


# The optional packages: with every one of them unimportable, the filters must still import and run.
EXTRAS_ONLY = ("pybullet", "matplotlib", "PIL", "tqdm", "rclpy", "rospy", "gymnasium", "stable_baselines3",
               "rosbags", "quadprog")

CORE_ONLY = f"""
import importlib.abc, sys

class NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {EXTRAS_ONLY!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)

sys.meta_path.insert(0, NotInstalled())
from safenav import preset
from safenav.filters import make_filter
from safenav.synthetic import Scene, synthetic_scan, wall

robot = preset("rosbot")
scan = synthetic_scan(robot, Scene.of(wall(distance=0.5)))
for name in ("cbf", "mpc"):
    result = make_filter(name, robot, 0.05).filter((0.5, 0.0), scan)
    print(name, result.status.value, round(float(result.u[0]), 4))
import safenav.sim_bullet   # imports without PyBullet; building a simulator needs it
try:
    safenav.sim_bullet.import_pybullet()
except ImportError as error:
    print(type(error).__name__, error)
"""


def _fresh_process(script: str, *args: str) -> list[str]:
    """The lines ``script`` prints in a fresh Python process run from the checkout (it must succeed)."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", script, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


def _core_only_output() -> list[str]:
    return _fresh_process(CORE_ONLY)


def test_the_filters_import_and_run_without_any_extra():
    lines = _core_only_output()
    for name, line in zip(("cbf", "mpc"), lines[:2], strict=True):
        filter_name, status, v = line.split()
        assert filter_name == name and status == "ok"
        assert 0.0 <= float(v) < 0.5        # a wall 0.5 m ahead: both slow the robot down


def test_the_simulator_without_its_extra_names_the_pip_line():
    assert _core_only_output()[2] == ('MissingDependency the PyBullet simulator needs the optional package '
                                      '\'pybullet\': pip install "safenav[sim]"')


def test_the_core_wheel_resolves_for_a_robot_computer(tmp_path):
    """The wheel installs on aarch64 (Jetson, Raspberry Pi) from binary wheels only: no simulator in the core."""
    import subprocess
    import sys

    pip = [sys.executable, "-m", "pip"]
    built = subprocess.run([*pip, "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(ROOT)],
                           capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stderr
    wheel, = (tmp_path / "dist").glob("safenav-*.whl")
    resolved = subprocess.run([*pip, "install", "--dry-run", "--only-binary=:all:", "--platform",
                               "manylinux_2_28_aarch64", "--python-version", "3.11", "--target", str(tmp_path / "x"),
                               str(wheel)], capture_output=True, text=True, timeout=300)
    assert resolved.returncode == 0, resolved.stdout[-2000:] + resolved.stderr[-2000:]
    assert "Would install" in resolved.stdout and "casadi" in resolved.stdout and "pybullet" not in resolved.stdout


# What a robot's control process loads: importing and running the filters with their default back-end must not
# pull in the modules only other back-ends, a lagging base's model or nothing use: scipy.signal alone took 1.2 s of a
# 2 s import, qpsolvers with scipy.sparse and scipy.stats 0.5 s more (benchmarks.filter_latency --startup). And no
# control call imports anything: a first call that loads a module stalls the loop for as long as the import takes.
UNUSED_MODULES = ("scipy.signal", "scipy.sparse", "scipy.stats", "qpsolvers", "osqp", "pybullet", "matplotlib")

LOADED = """
import json, math, sys
from safenav import preset
from safenav.filters import MPCConfig, make_filter
from safenav.synthetic import Scene, synthetic_scan, wall

lagging = {"config": MPCConfig(time_constant=0.1), "kernels": "numpy"}   # numpy's plan check runs the lag's model
filters = {"default": [("rosbot", "cbf", {}), ("rosbot", "mpc", {}), ("rosbot", "mpc", {"kernels": "numpy"})],
           "lagging": [("rosbot", "mpc", lagging)],
           "every": [(robot, name, options) for robot in ("rosbot", "m2wr")
                     for name, options in (("zones", {}), ("cbf+escape", {}), ("mpc+escape", {}),
                                           ("cbf", {"body": "polygon"}), ("cbf", {"body": "cover"}),
                                           ("mpc", {"body": "cover"}), ("cbf", {"kernels": "numpy"}))]}
unbudgeted = {"cbf": {"budget": math.inf}, "mpc": {"budget": math.inf}}     # (the zones have no budget)
built = [(preset(robot), make_filter(name, preset(robot), 0.05, **unbudgeted.get(name.split("+")[0], {}), **options))
         for robot, name, options in filters[sys.argv[1]]]
report = {"built": sorted(sys.modules)}
before = set(sys.modules)
report["statuses"] = []
for robot, safety in built:     # the first call, then a wall coming nearer, the odometry pose given
    for step, distance in enumerate((0.5, 2.0, 0.4, 0.3, 0.25)):
        scan = synthetic_scan(robot, Scene.of(wall(distance=distance)))
        status = safety.filter((0.5, 0.3), scan, velocity=(0.1, 0.0), pose=(0.01 * step, 0.0, 0.0)).status.value
    report["statuses"].append(status if step else "")
report["by_the_calls"] = sorted(set(sys.modules) - before)
print(json.dumps(report))
"""


def _loaded(which: str) -> dict:
    return json.loads(_fresh_process(LOADED, which)[-1])


def test_the_filters_load_only_the_modules_they_use_and_their_calls_none():
    report = _loaded("default")
    assert len(report["statuses"]) == 3 and "" not in report["statuses"]
    assert [name for name in report["built"] if name.startswith(UNUSED_MODULES)] == []
    assert report["by_the_calls"] == []


def test_a_lagging_bases_mpc_loads_its_filter_when_built_not_in_a_call():
    report = _loaded("lagging")
    assert len(report["statuses"]) == 1
    assert "scipy.signal" in report["built"] and report["by_the_calls"] == []


def test_no_call_of_any_filter_escape_or_body_imports_a_module():
    """Zones, both filters with the escape, the polygon and the cover, numpy's kernels; the ROSbot and the m2wr, whose
    blind sides bring in the memory and the space seen free."""
    report = _loaded("every")
    assert len(report["statuses"]) == 14
    assert report["by_the_calls"] == []


def test_another_back_end_still_loads_what_it_needs():
    from safenav.filters import CBFSafetyFilter
    from safenav.filters.qp import available_solvers, make_backend

    assert {"daqp", "osqp"} <= set(available_solvers())
    assert type(make_backend("qpsolvers:daqp")).__name__ == "QpsolversBackend"
    assert CBFSafetyFilter(__import__("safenav").preset("rosbot"), 0.05, solver="osqp").backend.name == "osqp"


@pytest.mark.slow
def test_the_core_install_runs_both_filters_in_a_fresh_venv(tmp_path):
    """The real thing behind the import check above: ``pip install .`` with no extra, then the filters."""
    import subprocess
    import sys

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = str(venv / "bin" / "python")
    installed = subprocess.run([python, "-m", "pip", "install", "-q", str(ROOT)], capture_output=True, text=True,
                               timeout=900)
    assert installed.returncode == 0, installed.stderr[-3000:]
    run = subprocess.run([python, "-c", CORE_ONLY.split("sys.meta_path.insert(0, NotInstalled())", 1)[1]],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert [line.split()[0] for line in lines[:2]] == ["cbf", "mpc"]
    assert lines[2].startswith(("MissingDependency", "ModuleNotFoundError")) and "pybullet" in lines[2]
