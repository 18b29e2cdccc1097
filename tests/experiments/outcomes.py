"""Episode metrics written by hand, for tests of what is computed from them."""

import numpy as np

from safenav.episode import EpisodeMetrics


def metrics(*, collided=False, min_clearance=0.2, distance=1.0, intervention=0.0, goal=None, time_to_goal=None,
            progress=None, stuck=0.0, time=10.0, fallbacks=0, filter_times=(), statuses=None, deadlock_time=0.0,
            longest_deadlock=0.0, escapes=(0, 0), escape_time=0.0, omega_chatter=0.0,
            v_reversals=0.0, nominal_omega_chatter=0.0, escape_omega_chatter=float("nan")) -> EpisodeMetrics:
    """Synthetic metrics of one episode."""
    return EpisodeMetrics(
        steps=int(time / 0.05), time=time, collided=collided, collision_time=5.0 if collided else None,
        min_clearance=min_clearance, distance=distance, mean_intervention=intervention,
        max_intervention=2 * intervention, goal_reached=goal, time_to_goal=time_to_goal, goal_progress=progress,
        stuck_time=stuck, fallbacks=fallbacks, statuses=statuses or {"none": int(time / 0.05)},
        filter_times=np.asarray(filter_times, dtype=float), deadlock_time=deadlock_time,
        longest_deadlock=longest_deadlock, escapes_started=escapes[0], escapes_succeeded=escapes[1],
        escape_time=escape_time, omega_chatter=omega_chatter, v_reversals=v_reversals,
        nominal_omega_chatter=nominal_omega_chatter, escape_omega_chatter=escape_omega_chatter,
    )
