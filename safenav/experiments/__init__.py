"""Experiments: many seeded episodes run in parallel, aggregated per cell, as tables.

=============  =========================================================================
module         holds
=============  =========================================================================
``specs``      :class:`Cell`, :class:`EpisodeSpec` (checked on construction), :func:`matrix`,
               :func:`episode_specs`
``runner``     :func:`run_spec`, :func:`run_specs` (a pool of processes or Ray, progress),
               :class:`EpisodeOutcome`, :class:`JobRunner` (batches on one pool or Ray, resume)
``results``    :class:`~safenav.experiments.results.ResultsFile`: finished jobs streamed to a JSON-lines
               file, so an interrupted sweep resumes (``docs/distributed.md``)
``stats``      :func:`wilson_interval`, :func:`cell_record`, :func:`cell_records`
``tables``     :func:`outcome_table`, :func:`timing_table`, :func:`markdown`, :data:`FILTER_LABELS`
=============  =========================================================================

An experiment is a list of :class:`EpisodeSpec` (plain names and a seed, so a spec can be
sent to another process), run by :func:`run_specs` on a pool of processes. The outcomes come
back in the order of the specs, whatever the number of workers, so the same specs give the
same numbers. :func:`cell_records` aggregates the episodes of each :class:`Cell` (scenario,
policy, filter) into one record: collision rate with a Wilson interval, clearance,
intervention, progress, stuck time, fallbacks and filter times::

    from safenav.experiments import cell_records, episode_specs, matrix, outcome_table, run_specs

    cells = matrix(scenarios=["stop_at_wall"], filters=["none", "cbf"])
    outcomes = run_specs(episode_specs(cells, seeds=range(5)), workers=2)
    print(outcome_table(cell_records(outcomes)))

Figures of outcomes and records are in :mod:`safenav.plots` (experiments import no plotting).
``safenav demo`` and ``safenav bench collisions`` (``benchmarks/collision_rates.py``) are
built on it.
"""

from safenav.experiments.runner import EpisodeOutcome, JobRunner, Progress, reproducible_specs, run_spec, run_specs
from safenav.experiments.specs import Cell, EpisodeSpec, episode_specs, matrix
from safenav.experiments.stats import DEADLOCK_LIMIT, cell_record, cell_records, pooled_records, wilson_interval
from safenav.experiments.tables import (
    FILTER_LABELS,
    LIVENESS_COLUMNS,
    SAFETY_COLUMNS,
    markdown,
    outcome_table,
    summary_table,
    timing_table,
)
from safenav.scenarios import scenario_for

__all__ = [
    "DEADLOCK_LIMIT",
    "FILTER_LABELS",
    "LIVENESS_COLUMNS",
    "SAFETY_COLUMNS",
    "Cell",
    "EpisodeOutcome",
    "EpisodeSpec",
    "JobRunner",
    "Progress",
    "cell_record",
    "cell_records",
    "episode_specs",
    "markdown",
    "matrix",
    "outcome_table",
    "pooled_records",
    "reproducible_specs",
    "run_spec",
    "run_specs",
    "scenario_for",
    "summary_table",
    "timing_table",
    "wilson_interval",
]
