"""Tables: the columns of the outcome table, and unknown columns."""


import pytest

from safenav import UnknownName
from safenav.experiments import FILTER_LABELS, Cell, cell_record, outcome_table
from safenav.filters import FILTER_NAMES
from tests.experiments.outcomes import metrics


def test_outcome_table_columns():
    record = cell_record(Cell("stop_at_wall", "stop_at_wall_buggy", "none"), "rosbot",
                         [metrics(collided=True, min_clearance=-0.02), metrics(min_clearance=0.5)])
    table = outcome_table([record], ["scenario", "filter", "collisions", "rate [95% CI]"])
    assert table.splitlines() == ["| scenario | filter | collisions | rate [95% CI] |", "|---|---|---|---|",
                                  "| stop_at_wall | none | 1 | 0.50 [0.09, 0.91] |"]
    with pytest.raises(UnknownName, match="unknown table column 'colour'"):
        outcome_table([record], ["colour"])


def test_outcome_table_liveness_columns():
    record = cell_record(Cell("dead_end_m2wr", "go_to_goal", "mpc+escape"), "m2wr",
                         [metrics(deadlock_time=7.0, longest_deadlock=7.0, escapes=(2, 1), omega_chatter=1.234,
                                  v_reversals=0.5),
                          metrics(deadlock_time=1.6, longest_deadlock=1.6, escapes=(1, 1), omega_chatter=0.766,
                                  v_reversals=0.25)])
    columns = ["filter", "deadlocks > 5 s", "deadlocked [s]", "escapes ok/started", "chatter [rad/s²]",
               "v reversals [1/s]"]
    assert outcome_table([record], columns).splitlines()[2] == "| mpc+escape | 1/2 | 4.3 | 2/3 | 1.00 | 0.38 |"
    assert FILTER_LABELS["cbf+escape"] == "CBF-QP + escape"
    assert set(FILTER_LABELS) == set(FILTER_NAMES)
