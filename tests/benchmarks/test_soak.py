"""The soak: one long random walk through the CBF, clean and flat (and its one-line usage errors)."""

import pytest

from benchmarks.soak import main, soak

pytestmark = pytest.mark.sim


@pytest.mark.parametrize("steps", [pytest.param(3000, id="ci"),
                                   pytest.param(20_000, id="long", marks=pytest.mark.slow)])
def test_soak_random_walk_through_the_cbf_stays_clean(steps):
    """No collision, no solver failure, flat memory, flat step time (leaks would show as growth). (Calls that
    ran out of the compute budget under the machine's load brake, and are counted apart.)"""

    result = soak(steps)
    assert result["steps"] == steps
    assert not result["collided"] and result["fallbacks"] == 0
    assert result["deadline_fallbacks"] + result["fallbacks"] == result["statuses"].get("fallback", 0)
    assert result["min_clearance"] >= result["margin"] - 0.01
    assert result["rss_end_mb"] - result["rss_start_mb"] < 20.0
    # The windows are 1000 steps apart in the same run; a 3x margin absorbs a noisy machine.
    assert result["last_window_median_us"] <= 3.0 * result["first_window_median_us"]


def test_a_soak_too_short_for_its_windows_is_a_usage_error(capsys):
    assert main(["--steps", "100", "--warmup", "10", "--window", "50"]) == 2
    assert capsys.readouterr().err.strip() == ("soak: error: soak: steps=100 must be at least warmup + 2 x window "
                                               "= 110")
