"""Figures a researcher would publish: units on every axis, labelled current, clean legends."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest

from eelhost import plots
from eelsim.scenario import load_scenario


@pytest.fixture
def captured(monkeypatch):
    figures = []

    def keep(fig, path, dpi=110):
        figures.append(fig)
        return path

    monkeypatch.setattr(plots, "save_figure", keep)
    yield figures
    plt.close("all")


def fake_straight_run(name: str, drift_m: float):
    scenario = load_scenario("straight")
    t = np.linspace(0.0, 10.0, 21)
    exp = np.column_stack([0.1 * t, np.zeros_like(t)])
    sim = exp + np.column_stack([np.full_like(t, 0.01), drift_m * t])  # ahead, drifting left
    experiment = SimpleNamespace(name=name, t_s=t, position_m=exp, scenario=scenario)
    return SimpleNamespace(experiment=experiment, times_s=t, exp_positions_m=exp,
                           sim_positions_m=sim)


def test_track_frame_splits_an_error_along_and_across_the_track():
    along, across = plots.track_frame((0.0, 0.0), (1.0, 1.0))
    error = np.array([1.0, 0.0])
    assert np.isclose(error @ along, np.sqrt(0.5)) and np.isclose(error @ across, -np.sqrt(0.5))


def test_straight_runs_show_both_errors_against_time_with_units(captured, tmp_path):
    plots.plot_track_errors([fake_straight_run("a", 0.001), fake_straight_run("b", -0.002)],
                            tmp_path / "s.png")
    (fig,) = captured
    tracks, along, cross = fig.axes[:3]
    assert "(mm)" in tracks.get_ylabel() and "(m)" in tracks.get_xlabel()
    for ax in (along, cross):
        assert "(mm)" in ax.get_ylabel()
    assert cross.get_xlabel() == "t (s)"
    assert np.allclose(along.lines[1].get_ydata(), 10.0)  # the 1 cm ahead, constant
    assert np.isclose(cross.lines[1].get_ydata()[-1], -20.0)  # run b drifts 2 cm right by 10 s
    assert any("of the waypoint" in t.get_text() for t in tracks.get_legend().get_texts())


def test_the_tracks_panel_shows_the_drift_across_the_track_not_a_flat_line(captured, tmp_path):
    plots.plot_track_errors([fake_straight_run("b", -0.002)], tmp_path / "s.png")
    tracks = captured[0].axes[0]
    simulated = tracks.lines[1].get_ydata()  # the twin's track, mm across
    assert simulated.min() < -10.0  # 2 mm/s for 10 s, a beat averaged out: clearly off zero
    low, high = tracks.get_ylim()
    assert high - low < 40.0  # the axis is scaled to the drift, not to the tank


def test_legend_lists_each_label_once():
    fig, ax = plt.subplots()
    for k in range(3):
        ax.plot([0, k], label="hull")
    ax.plot([1, 2], label="path")
    plots.legend_once(ax)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["hull", "path"]
    plt.close(fig)


def test_current_arrow_says_its_speed_and_direction():
    fig, ax = plt.subplots()
    plots.draw_current(ax, 0.03, 180.0)
    texts = [t.get_text() for t in ax.texts]
    assert any("current 0.03 m/s" in t and "180 deg" in t for t in texts)
    plots.draw_current(ax, 0.0, 90.0)  # no current, no arrow
    assert len(ax.texts) == len(texts)
    plt.close(fig)
