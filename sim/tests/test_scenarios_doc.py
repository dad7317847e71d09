"""docs/scenarios.md, which eelsim.scenario cites, describes the scenario file the code reads."""

from __future__ import annotations

import re
from pathlib import Path

from eelsim.scenario import Scenario, load_scenario, named_scenarios

DOC = Path(__file__).resolve().parents[2] / "docs" / "scenarios.md"


def test_every_scenario_key_is_in_the_docs_table_and_no_other():
    section = DOC.read_text().split("## A scenario file", 1)[1]
    keys = set(re.findall(r"^\| `(\w+)` \|", section, flags=re.MULTILINE))
    assert keys == set(Scenario.model_fields)


def test_the_docs_example_file_loads_as_written(tmp_path):
    example = re.search(r"```toml\n(.*?)```", DOC.read_text(), flags=re.DOTALL)
    assert example is not None
    path = tmp_path / "my_task.toml"
    path.write_text(example.group(1))
    s = load_scenario(path)
    assert s.name == "my_task" and s.waypoints_m == [(0.5, 0.0), (1.0, 0.3)]
    assert s.acceptance_radius_m == 0.15 and s.beta_rad == 1.04  # the defaults the table states


def test_the_named_paths_are_those_the_docs_list():
    text = DOC.read_text()
    for name in ("path1", "path2"):
        row = next(line for line in text.splitlines() if line.startswith(f"| `{name}` |"))
        for x, y in named_scenarios()[name].waypoints_m:
            assert f"({x:.2f}, {y:.2f})" in row


def test_a_task_swum_with_a_gait_carries_the_gait_and_its_own_fields():
    from eelsim.control import Gait

    gait = Gait(0.7, 3.1, 0.9, 0.2)
    task = Scenario.swimming(gait, name="t", waypoints_m=[(1.0, 0.5)], duration_s=7.0,
                             current_speed_m_s=0.01, current_direction_deg=45.0)
    assert task.gait == gait
    assert (task.name, task.waypoints_m, task.duration_s) == ("t", [(1.0, 0.5)], 7.0)
    assert (task.current_speed_m_s, task.current_direction_deg) == (0.01, 45.0)
    path1 = named_scenarios()["path1"]
    assert Scenario.swimming(path1.gait, **path1.model_dump(exclude={
        "amplitude_rad", "omega_rad_s", "beta_rad", "k_theta"})) == path1
