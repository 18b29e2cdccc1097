"""The README's set-up commands are the ones CI runs."""

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


def test_readme_filter_example_runs_on_a_ros_like_message():
    import math
    from types import SimpleNamespace

    namespace: dict = {}
    exec(python_examples()[0], namespace)
    message = SimpleNamespace(angle_min=-math.pi, angle_max=math.pi, angle_increment=2 * math.pi / 719,
                              time_increment=0.0, scan_time=0.1, range_min=0.15, range_max=12.0,
                              ranges=[0.5] * 720, intensities=[])
    u = namespace["on_scan"](message, (0.3, 0.0), (1.0, 0.0))
    assert 0.0 <= u[0] < 1.0          # a wall 0.5 m all round: the filter slows the robot down


@pytest.mark.sim
def test_readme_shield_example_runs_without_collision(capsys):
    exec(python_examples()[1], {})
    assert "collided: False" in capsys.readouterr().out
