import numpy as np
import pytest

from eelhost.planning.geometry import segments_cross
from eelhost.planning.world import WorldError, load_world, parse_world
from eelsim.flags import segments_intersect

BASE = {
    "tank": {"size_m": [3.0, 2.0]},
    "start": {"position_m": [0.4, 1.0]},
    "goal": {"position_m": [2.6, 1.0], "radius_m": 0.2},
    "obstacles": [
        {"kind": "circle", "centre_m": [1.5, 1.0], "radius_m": 0.2},
        {"kind": "polygon", "vertices_m": [[2.0, 0.2], [2.4, 0.2], [2.4, 0.6], [2.0, 0.6]]},
    ],
}


def square(cx, cy, half):
    return np.array([[cx - half, cy - half], [cx + half, cy - half],
                     [cx + half, cy + half], [cx - half, cy + half]])


def test_world_file_with_unknown_key_is_refused_naming_file_and_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[tank]\nsize_m = [3.0, 2.0]\ncolour = "blue"\n'
                    '[start]\nposition_m = [0.4, 1.0]\n[goal]\nposition_m = [2.0, 1.0]\n')
    with pytest.raises(WorldError) as err:
        load_world(path)
    assert str(path) in str(err.value) and "tank.colour: unknown key" in str(err.value)


def test_goal_outside_the_tank_is_refused():
    data = {**BASE, "goal": {"position_m": [3.5, 1.0]}}
    with pytest.raises(WorldError, match="goal.position_m"):
        parse_world(data, "w.toml")


def test_bundled_example_has_a_3_by_2_m_tank_with_five_obstacles_and_a_current():
    world = load_world("tank_5_obstacles")
    assert world.tank.size_m == (3.0, 2.0)
    assert len(world.obstacles) == 5
    assert world.current.speed_m_s > 0


def test_hulls_touching_circles_polygons_or_walls_are_not_free():
    world = parse_world(BASE)
    hulls = np.stack([
        square(0.8, 1.0, 0.1),      # open water
        square(1.5, 1.0, 0.05),     # inside the circle
        square(1.75, 1.0, 0.1),     # overlaps the circle's edge
        square(2.2, 0.4, 0.05),     # inside the polygon
        square(2.2, 0.65, 0.1),     # overlaps the polygon's top edge
        square(0.05, 1.0, 0.1),     # through the left wall
        square(2.2, 0.4, 0.5),      # swallows the polygon whole
    ])
    assert world.hulls_free(hulls, 0.0).tolist() == [True, False, False, False, False, False,
                                                      False]


def test_margin_makes_a_near_miss_a_collision():
    world = parse_world(BASE)
    near = square(1.5, 1.35, 0.1)  # 0.05 m above the circle
    assert world.hull_is_free(near, 0.02)
    assert not world.hull_is_free(near, 0.08)


def test_segment_clearance_measures_distance_to_nearest_obstacle():
    world = parse_world(BASE)
    a = np.array([[1.0, 1.5]])
    b = np.array([[1.0, 1.7]])
    # nearest: the circle (centre 1.5,1.0 r 0.2) and the top wall at y = 2 (0.3 m)
    expected = min(np.hypot(0.5, 0.5) - 0.2, 0.3)
    assert world.segments_clearance(a, b) == pytest.approx(expected)


def test_vectorised_segment_crossing_agrees_with_the_twins_segment_intersection():
    # random segments (general position) and touching ones: a T, shared end points, a near miss
    rng = np.random.default_rng(4)
    a1, a2, b1, b2 = (rng.uniform(0, 1, (40, 2)) for _ in range(4))
    touching = np.array([[[0, 0], [1, 0], [0.5, 0], [0.5, 1]],
                         [[0, 0], [1, 1], [1, 1], [2, 0]],
                         [[0, 0], [1, 0], [0.5, 1e-9], [0.5, 1]]], dtype=float)
    a1, a2 = np.r_[a1, touching[:, 0]], np.r_[a2, touching[:, 1]]
    b1, b2 = np.r_[b1, touching[:, 2]], np.r_[b2, touching[:, 3]]
    crossed = segments_cross(a1, a2, b1, b2)
    expected = np.array([[segments_intersect(a1[i], a2[i], b1[j], b2[j]) for j in range(len(b1))]
                         for i in range(len(a1))])
    assert crossed.any() and not crossed.all()
    np.testing.assert_array_equal(crossed, expected)
