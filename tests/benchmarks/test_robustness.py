"""The robustness benchmark: its episodes (faults, margins read without building a filter) and its usage errors."""

import pytest

from benchmarks.robustness import CELLS, FAULTS, configurations, main, specs_for
from safenav.filters import default_margin
from safenav.scenarios import scenario


def test_every_fault_level_runs_every_filter_and_margin_after_the_nominal_case():
    configs = configurations(["cbf", "mpc"], [0.0, 0.05])
    assert configs[:4] == [{"fault": "nominal", "level": None, "filter": name, "extra_margin": extra}
                           for name in ("cbf", "mpc") for extra in (0.0, 0.05)]
    assert len(configs) == 4 * (1 + sum(len(levels) for levels in FAULTS.values()))
    assert {c["fault"] for c in configurations(["cbf"], [0.0], ["dropout"])} == {"nominal", "dropout"}


def test_specs_put_the_fault_in_the_simulator_and_the_margin_on_top_of_the_default():
    config = {"fault": "scan_latency", "level": 2, "filter": "mpc", "extra_margin": 0.02}
    specs = specs_for(config, range(2), 5.0)
    assert len(specs) == 2 * len(CELLS)
    for spec in specs:
        robot = scenario(spec.scenario).robot
        assert spec.sim_options == (("scan_latency", 2),) and spec.duration == 5.0 and spec.filter == "mpc"
        assert dict(spec.filter_options)["margin"] == pytest.approx(default_margin(robot) + 0.02)


@pytest.mark.parametrize(("argv", "message"), [
    (["--faults", "wind"], "unknown fault 'wind'; expected one of: actuation_noise, dropout"),
    (["--filters", "none"], "unknown filter with a margin 'none'; expected one of: cbf, mpc"),
    (["--scenarios", "stop_at_wall"], "unknown robustness cell 'stop_at_wall'; expected one of: clutter_m2wr"),
])
def test_bad_names_are_one_line_errors(argv, message, capsys):
    assert main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith(f"robustness: error: {message}") and "\n" not in error


def test_bad_numbers_are_argparse_errors(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--margins", "0,-0.1"])
    assert exit_info.value.code == 2
    assert "argument --margins: must be a finite number >= 0, got -0.1" in capsys.readouterr().err
