"""SafetyShield: zero collisions for a random agent, on safenav's environments and on a third-party one."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from safenav import preset
from safenav.errors import InvalidConfig, SafeNavError, UnknownName
from safenav.filters import CBFSafetyFilter
from safenav.geometry import Pose2D, unicycle_step
from safenav.synthetic import Scene, box, synthetic_scan
from tests.gym.conftest import SKIP_REASON, check_env_quietly, random_episode

gymnasium = pytest.importorskip("gymnasium", reason=SKIP_REASON)

from safenav.gym import ENV_IDS, SafetyObservation, SafetyShield, UnsupportedEnv  # noqa: E402 - after the importorskip

EPISODES = 20
SHORT_STEPS = 100   # 5 s; `pytest -m slow` runs whole episodes


def _episodes(env_id: str, shielded: bool, steps: int, *, until_collision: bool = False, **make: Any) -> list:
    """The random agent's episodes with seeds 0..EPISODES-1 (up to the first collision with ``until_collision``)."""
    env = gymnasium.make(env_id, info_scan=False, **make)
    env = SafetyShield(env) if shielded else env
    records = []
    for seed in range(EPISODES):
        records.append(random_episode(env, seed, steps))
        if until_collision and records[-1].collided:
            break
    env.close()
    return records


def _shield_never_fails(env_id: str, steps: int, **make: Any) -> None:
    # The same random agent (seeded through reset) in the same worlds: without the shield it
    # must hit something, or the environment is too easy to show what the shield does.
    naive = _episodes(env_id, shielded=False, steps=steps, until_collision=True, **make)
    assert naive[-1].collided, f"{env_id}: the random agent never collided unshielded; the test shows nothing"
    shielded = _episodes(env_id, shielded=True, steps=steps, **make)
    assert len(shielded) == EPISODES and not any(record.collided for record in shielded)
    assert min(record.min_clearance for record in shielded) >= 0.0
    # It had work to do: it changed some of the agent's actions (a binding row changes the command
    # with status "ok"; "recovering", "slack", ... only say more about how).
    assert any(info["shield"]["modified"] for record in shielded for info in record.infos)


@pytest.mark.parametrize("env_id", [env_id if env_id in ("safenav/GoToGoal-v0", "safenav/StopAtWall-v0")
                                    else pytest.param(env_id, marks=pytest.mark.slow) for env_id in ENV_IDS])
def test_random_agent_collides_unshielded_and_never_shielded(env_id: str) -> None:
    _shield_never_fails(env_id, SHORT_STEPS)


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["rosbot", "puzzlebot", "m2wr"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_random_agent_never_collides_shielded_over_whole_episodes(env_id: str, robot: str) -> None:
    _shield_never_fails(env_id, 10_000, robot=robot)


def test_info_reports_the_filter_and_leaves_safe_actions_alone() -> None:
    env = SafetyShield(gymnasium.make("safenav/StopAtWall-v0"))
    env.reset(seed=3)
    _, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))     # stopping is always safe
    shield = info["shield"]
    assert shield["status"] == "ok" and not shield["modified"] and shield["intervention"] == 0.0
    np.testing.assert_array_equal(shield["u"], shield["u_nom"])
    assert env.last_result.status.value == "ok" and env.last_result.filter_time > 0.0
    assert set(shield) == {"u_nom", "u", "status", "message", "escape", "reason", "warnings", "modified",
                           "intervention", "min_barrier", "clearance", "safety_change"}
    assert shield["reason"] == ""
    assert shield["safety_change"] == 0.0
    env.close()


def test_the_shield_brakes_in_front_of_the_wall() -> None:
    env = SafetyShield(gymnasium.make("safenav/StopAtWall-v0"))
    env.reset(seed=0)
    modified, reasons = False, set()
    for _ in range(300):
        _, _, terminated, truncated, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        modified |= info["shield"]["modified"]
        reasons.add(info["shield"]["reason"].partition(":")[0])
        assert not info["collision"]
        assert info["shield"]["u"][0] <= 1.0
        if terminated or truncated:
            break
    env.close()
    assert modified and info["clearance"] > 0.0
    assert reasons & {"barrier", "braking"}          # the wall bound the command, and the info says so


def test_intervention_penalty_is_the_change_made_for_safety() -> None:
    weight = 2.0
    plain = SafetyShield(gymnasium.make("safenav/ObstacleAvoidance-v0"))
    penalised = SafetyShield(gymnasium.make("safenav/ObstacleAvoidance-v0"), intervention_penalty=weight)
    robot, dt = plain.filter.robot, plain.filter.dt
    changes = []
    _, info = plain.reset(seed=5)
    penalised.reset(seed=5)
    for _ in range(120):
        action = np.array([2.0, 0.3], dtype=np.float32)    # beyond the limits: the base's own clipping is not penalised
        reachable = robot.clip(action, info["velocity"], dt)
        _, reward, terminated, _, info = plain.step(action)
        _, penalised_reward, _, _, _ = penalised.step(action)
        change = float(np.hypot(*(info["shield"]["u"] - reachable)))
        assert info["shield"]["safety_change"] == pytest.approx(change, abs=1e-12)
        assert penalised_reward == pytest.approx(reward - weight * change, abs=1e-9)
        changes.append(change)
        if terminated:
            break
    plain.close()
    penalised.close()
    assert changes[0] < 1e-9                          # accelerating from rest: the base's limit, not the shield
    assert max(changes) > 0.05                        # then the filter steers away from the obstacles


# ---------------------------------------------------------------------------------------------- a third-party env


class SquareRoom(gymnasium.Env):
    """A third-party environment: a unicycle with an analytic lidar in a 3 x 3 m room.

    It knows nothing of safenav's simulator; it implements only the shield protocol. Its
    action space is narrower than the robot's limits: forward only, slower.
    """

    metadata = {"render_modes": []}  # noqa: RUF012 - Gymnasium's convention
    control_dt = 0.1

    def __init__(self) -> None:
        self.robot = preset("puzzlebot")
        self.action_space = gymnasium.spaces.Box(np.array([0.0, -1.0], np.float32), np.array([0.3, 1.0], np.float32))
        self.observation_space = gymnasium.spaces.Box(0.0, 12.0, (360,), np.float32)
        self._scene = Scene.of(box((0.0, 0.0), (3.0, 3.0)))
        self._pose = Pose2D()
        self._time = 0.0

    def _observe(self) -> np.ndarray:
        self._scan = synthetic_scan(self.robot, self._scene, self._pose, stamp=self._time)
        return np.clip(np.nan_to_num(self._scan.ranges, posinf=12.0, neginf=0.0), 0.0, 12.0).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        start = (options or {}).get("start")
        self._pose = Pose2D(*start) if start is not None else Pose2D(float(self.np_random.uniform(-0.5, 0.5)), 0.0,
                                                                      float(self.np_random.uniform(-3, 3)))
        self._velocity, self._time = np.zeros(2), 0.0
        return self._observe(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        assert action in self.action_space      # the test's check: the shield stays inside the box
        self._velocity = np.asarray(action, dtype=float)
        self._pose = unicycle_step(self._pose, float(action[0]), float(action[1]), self.control_dt)
        self._time += self.control_dt
        clearance = self._scene.clearance(self._pose[:2], self.robot.radius)
        return self._observe(), 0.0, bool(clearance < 0.0), False, {"clearance": clearance}

    def safety_observation(self) -> SafetyObservation:
        return SafetyObservation(scan=self._scan, velocity=self._velocity, time=self._time)


def test_the_shield_guards_a_third_party_environment() -> None:
    env = SafetyShield(SquareRoom())
    check_env_quietly(env)
    for seed in range(3):
        env.reset(seed=seed)
        clearances = []
        for _ in range(100):                                       # full speed at the walls for 10 s
            _, _, terminated, _, info = env.step(np.array([0.3, 0.0], dtype=np.float32))
            clearances.append(info["clearance"])
            assert not terminated
        assert min(clearances) >= 0.0
        assert info["shield"]["u"][0] >= 0.0                      # never reverses: the box forbids it
    assert env.filter.robot.v_max == pytest.approx(0.3) and env.filter.robot.v_min == 0.0
    env.close()


def test_the_escape_leaves_a_deadlock_the_plain_shield_sits_in() -> None:
    # Head-on at a wall, the symmetric case: the barrier holds the robot still in front of it;
    # the escape follows the wall instead, its commands filtered like the agent's.
    finals, escaping = [], []
    for escape in (False, True):
        env = SafetyShield(SquareRoom(), escape=escape)
        env.reset(seed=0, options={"start": (0.0, 0.0, 0.0)})
        steps = []
        for _ in range(300):
            _, _, terminated, _, info = env.step(np.array([0.3, 0.0], dtype=np.float32))
            steps.append(bool(info["shield"]["escape"]))
            assert not terminated and info["clearance"] >= 0.0
        finals.append(env.unwrapped._pose)
        escaping.append(sum(steps))
    assert type(env.filter).__name__ == "Escape" and isinstance(env.filter.inner, CBFSafetyFilter)
    stuck, escaped = finals
    assert escaping[0] == 0 and stuck.x > 0.9 and abs(stuck.y) < 0.01          # sat at the wall, facing it
    assert escaping[1] > 0 and math.dist(stuck[:2], escaped[:2]) > 0.5          # went round instead


def test_without_the_shield_the_third_party_robot_hits_the_wall() -> None:
    env = SquareRoom()
    env.reset(seed=0)
    ends = [env.step(np.array([0.3, 0.0], dtype=np.float32))[2] for _ in range(100)]
    assert any(ends)


class NoProtocol(gymnasium.Env):
    metadata = {"render_modes": []}  # noqa: RUF012

    def __init__(self, action_space: Any = None) -> None:
        self.action_space = action_space or gymnasium.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = gymnasium.spaces.Box(0.0, 1.0, (1,), np.float32)


class WrongShape(SquareRoom):
    def __init__(self, space: Any) -> None:
        super().__init__()
        self.action_space = space


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: SafetyShield(NoProtocol()), UnsupportedEnv, "NoProtocol does not implement the shield protocol"),
    (lambda: SafetyShield(WrongShape(gymnasium.spaces.Discrete(3))), UnsupportedEnv,
     "has action space Discrete.3.; expected a Box of shape .2,."),
    (lambda: SafetyShield(WrongShape(gymnasium.spaces.Box(0.1, 1.0, (2,)))), UnsupportedEnv,
     "does not hold the stop command .0, 0."),
    (lambda: SafetyShield(SquareRoom(), escape="yes"), InvalidConfig, "SafetyShield.escape must be True or False"),
    (lambda: SafetyShield(SquareRoom(), "none"), InvalidConfig, "filter='none' makes no shield"),
    (lambda: SafetyShield(SquareRoom(), "magic"), UnknownName, "unknown filter 'magic'; expected one of: cbf"),
    (lambda: SafetyShield(SquareRoom(), 3), InvalidConfig,
     r"filter must be a name \(zones, cbf, mpc, zones\+escape, cbf\+escape, mpc\+escape\), a SafetyFilter or an "
     r"Escape, got 3"),
    (lambda: SafetyShield(SquareRoom(), intervention_penalty=-1.0), InvalidConfig,
     "SafetyShield.intervention_penalty must be a finite number >= 0, got -1.0"),
    (lambda: SafetyShield(SquareRoom(), CBFSafetyFilter(preset("puzzlebot").replace(v_min=0.0, v_max=0.3,
                                                                                     omega_max=1.0), 0.05)),
     InvalidConfig, "the filter's dt=0.05 differs from the control period 0.1"),
    (lambda: SafetyShield(SquareRoom(), CBFSafetyFilter(preset("puzzlebot"), 0.1)), InvalidConfig,
     "the filter's velocity limits .* exceed the action space"),
    (lambda: SafetyShield(SquareRoom(), CBFSafetyFilter(preset("puzzlebot"), 0.1), margin=0.1), InvalidConfig,
     "settings .'margin'. apply to a filter built by name"),
])
def test_shield_errors_name_what_is_wrong(call, error, message) -> None:
    with pytest.raises(error, match=message) as caught:
        call()
    assert isinstance(caught.value, SafeNavError)


def test_unsupported_env_is_a_type_error() -> None:
    assert issubclass(UnsupportedEnv, TypeError)


def test_a_filter_instance_and_settings_by_name_are_used() -> None:
    robot = preset("puzzlebot").replace(v_min=0.0, v_max=0.3, omega_max=1.0)
    own = CBFSafetyFilter(robot, 0.1, margin=0.2)
    assert SafetyShield(SquareRoom(), own).filter is own
    named = SafetyShield(SquareRoom(), "cbf", margin=0.2)
    assert named.filter.config.margin == pytest.approx(0.2)


def test_the_mpc_inside_the_shields_escape_tracks_the_cbf_unless_told_otherwise() -> None:
    # The escape's preset (ESCAPE_PRESETS) applies however the escape is asked for: escape=True or "mpc+escape".
    for shield in (SafetyShield(SquareRoom(), "mpc", escape=True), SafetyShield(SquareRoom(), "mpc+escape")):
        assert shield.filter.inner.config.reference == "cbf"
    assert SafetyShield(SquareRoom(), "mpc", escape=True, reference="nominal").filter.inner.reference is None
    assert SafetyShield(SquareRoom(), "mpc", escape=False).filter.config.reference == "nominal"


# ---------------------------------------------------------------------------------------------- README

README_EXAMPLE = '''
import gymnasium
from safenav.gym import SafetyShield  # registers safenav/GoToGoal-v0 and the other environments

env = SafetyShield(gymnasium.make("safenav/GoToGoal-v0", robot="puzzlebot"))  # the CBF filter guards every action
observation, info = env.reset(seed=0)
observation, reward, terminated, truncated, info = env.step(env.action_space.sample())  # your agent's action here
'''


def test_the_readme_example_runs_as_written() -> None:
    code = [line for line in README_EXAMPLE.strip().splitlines() if line.strip()]
    assert len(code) == 5
    namespace: dict = {}
    exec(README_EXAMPLE, namespace)
    assert namespace["info"]["shield"]["status"] == "ok"
    assert math.isfinite(namespace["reward"])
    namespace["env"].close()


@pytest.mark.parametrize(("kwargs", "error", "message"), [
    ({"scan": [1.0, 2.0]}, TypeError, "SafetyObservation.scan must be a safenav LaserScan"),
    ({"velocity": (1.0, 2.0, 3.0)}, ValueError, "SafetyObservation.velocity must have shape .2,."),
    ({"pose": (0.0, 1.0)}, ValueError, r"SafetyObservation.pose must be a pose \(x \[m\], y \[m\], yaw \[rad\]\)"),
    ({"pose": (0.0, 1.0, math.nan)}, ValueError, r"SafetyObservation.pose\[2\] must be a finite number, got nan"),
    ({"time": math.inf}, ValueError, "SafetyObservation.time must be a finite number, got inf"),
])
def test_safety_observation_errors_name_the_field(kwargs: dict, error: type, message: str) -> None:
    fields = {"scan": preset("puzzlebot").scan(), **kwargs}
    with pytest.raises(error, match=message) as caught:
        SafetyObservation(**fields)
    assert isinstance(caught.value, SafeNavError)
