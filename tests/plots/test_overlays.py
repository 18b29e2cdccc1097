"""Figures of experiments: trajectories overlaid per filter, collision-rate bars, the clearance histogram."""

import pytest

from safenav import InvalidConfig
from safenav.experiments import Cell, cell_records, episode_specs, run_specs
from safenav.plots import clearance_figure, collision_rate_figure, draw_overlay, new_figure, overlay_figure
from safenav.plots.overlays import FILTER_COLORS


@pytest.fixture(scope="module")
def outcomes():
    """The published stop-at-wall controller (it drives into the wall) without and with the CBF, two seeds."""
    cells = [Cell("stop_at_wall", "stop_at_wall_buggy", name) for name in ("none", "cbf")]
    return run_specs(episode_specs(cells, range(2), duration=7.0, record_seeds=[0]), workers=1, progress=False)


@pytest.mark.sim
def test_an_overlay_marks_the_collision_and_names_each_filter(outcomes):
    recorded = [o for o in outcomes if o.trajectory is not None]
    ax = draw_overlay(new_figure((5.0, 5.0)).add_subplot(), recorded, title="seed 0")
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert labels[0].startswith("naive (no filter): collided at 5.") and labels[1].startswith("CBF-QP: min clearance")
    hits = [line for line in ax.lines if line.get_marker() == "X"]
    assert len(hits) == 1 and hits[0].get_color() == FILTER_COLORS["none"]
    assert tuple(hits[0].get_xydata()[0]) == pytest.approx(tuple(recorded[0].collision_point()))


@pytest.mark.sim
def test_an_overlay_figure_has_one_panel_per_group_and_rejects_mixed_panels(outcomes):
    recorded = [o for o in outcomes if o.trajectory is not None]
    figure = overlay_figure([recorded, recorded[:1]], title="two panels")
    assert len([ax for ax in figure.axes if ax.get_title()]) == 2 and figure.get_suptitle() == "two panels"
    with pytest.raises(InvalidConfig, match="mixes scenarios, robots or seeds"):
        overlay_figure([[o for o in outcomes if o.spec.filter == "none"]])   # seeds 0 and 1
    with pytest.raises(InvalidConfig, match="was not recorded"):
        draw_overlay(new_figure((5.0, 5.0)).add_subplot(), [o for o in outcomes if o.trajectory is None])


@pytest.mark.sim
def test_rate_bars_and_clearance_histogram_have_one_series_per_filter(outcomes):
    records = cell_records(outcomes)
    bars = collision_rate_figure(records).axes[0]
    assert [text.get_text() for text in bars.get_legend().get_texts()] == ["naive (no filter)", "CBF-QP"]
    heights = [patch.get_height() for patch in bars.patches]
    assert heights == [1.0, 0.0]   # both naive episodes collide, no filtered one does
    histogram = clearance_figure(outcomes).axes[0]
    assert [text.get_text() for text in histogram.get_legend().get_texts()] == ["naive (no filter) (2 episodes)",
                                                                                "CBF-QP (2 episodes)"]
