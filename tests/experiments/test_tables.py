"""Tables: the columns of the outcome table, and unknown columns."""


import pytest

from safenav import UnknownName
from safenav.experiments import Cell, cell_record, outcome_table
from tests.experiments.outcomes import metrics


def test_outcome_table_columns():
    record = cell_record(Cell("stop_at_wall", "stop_at_wall_buggy", "none"), "rosbot",
                         [metrics(collided=True, min_clearance=-0.02), metrics(min_clearance=0.5)])
    table = outcome_table([record], ["scenario", "filter", "collisions", "rate [95% CI]"])
    assert table.splitlines() == ["| scenario | filter | collisions | rate [95% CI] |", "|---|---|---|---|",
                                  "| stop_at_wall | none | 1 | 0.50 [0.09, 0.91] |"]
    with pytest.raises(UnknownName, match="unknown table column 'colour'"):
        outcome_table([record], ["colour"])
