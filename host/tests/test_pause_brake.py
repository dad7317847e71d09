"""The brake in the pause (docs/planning.md, "The brake in the pause"): a frozen S, then straight.

The firmware in the loop over lockstep ``sim://`` says where its phase froze and where it resumes;
the twin's braked drift is checked against the straight one it replaces.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from eelhost.field.recorder import Recorder, read_commands_csv
from eelhost.field.runloop import RunConfig, RunLoop
from eelhost.link import open_link
from eelhost.planning.replan import Decision
from eelhost.planning.restart import paused_drift, stopped_gait, stopped_twin, unbrake_time
from eelhost.planning.twin import Twin
from eelhost.planning.uncertainty import default_model
from eelhost.vision.localise import Localiser
from eelhost.vision.synthetic import RenderOptions, SyntheticCamera
from eelhost.wire import protocol
from eelhost.xil.virtual_robot import VirtualCamera
from eelsim.closed_loop import LoopOptions
from eelsim.control import (
    BRAKE_AMPLITUDE_RAD,
    Gait,
    braked_gait,
    gait_reference,
    joint_amplitudes,
)
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

ROBOT = load_robot()
N = ROBOT.n_links
GAIT = Gait(0.87, 3.9, 1.04, 0.37)
MODEL = default_model(ROBOT)


class ScriptedPause:
    """A navigator that brakes at ``t_brake_s``, ends the brake on time and restarts at ``t_restart_s``."""

    replans = 0

    def __init__(self, t_brake_s: float, t_restart_s: float) -> None:
        self.t_brake_s, self.t_restart_s = t_brake_s, t_restart_s
        self.braked: Gait | None = None
        self.t_unbrake_s = math.inf
        self.stage = "swimming"
        self.telemetry: list[tuple[float, protocol.Telemetry]] = []

    def on_frame(self, t_s, loc, pose, target, offset_rad, guide=None):  # noqa: ANN001, ANN201
        d = Decision()
        if self.stage == "swimming" and t_s >= self.t_brake_s:
            self.braked = braked_gait(GAIT, t_s)
            self.t_unbrake_s = unbrake_time(GAIT, t_s)
            self.stage, d.pause, d.pause_gait = "braked", True, self.braked
        elif self.stage == "braked" and t_s >= self.t_unbrake_s - 1e-9:
            self.stage, d.pause, d.pause_gait = "straight", True, stopped_gait(GAIT)
        elif self.stage == "straight" and t_s >= self.t_restart_s:
            self.stage, d.waypoints, d.restart = "swimming again", [(3.0, 0.0)], True
        return d

    def on_telemetry(self, t_s: float, msg: object, t_before_s: float) -> None:
        if isinstance(msg, protocol.Telemetry):
            self.telemetry.append((t_s, msg))

    def pace(self, t_s: float) -> None:
        pass

    def close(self) -> None:
        pass

    def record(self) -> dict:
        return {}


def _reference_error(rows: list[tuple[float, protocol.Telemetry]], gait: Gait) -> float:
    """Largest difference of the firmware's references from ``gait``'s (any time: omega 0)."""
    return max(float(np.max(np.abs(np.asarray(m.alpha_rad) - m.offset_rad
                                   - gait_reference(t, gait, 0.0, N)[0])))
               for t, m in rows)


def _phase_lead_rad(rows: list[tuple[float, protocol.Telemetry]]) -> float:
    """The firmware's gait phase less omega times its own clock: circular mean over ``rows``."""
    lag = np.arange(N - 1) * GAIT.beta_rad
    leads = []
    for _, m in rows:
        a = joint_amplitudes(m.amplitude_rad, N)
        basis = np.stack([a * np.cos(lag), a * np.sin(lag)], axis=1)  # sin psi, cos psi
        coef = np.linalg.lstsq(basis, np.asarray(m.alpha_rad) - m.offset_rad, rcond=None)[0]
        leads.append(math.atan2(coef[0], coef[1]) - GAIT.omega_rad_s * m.time_us * 1e-6)
    return float(np.angle(np.mean(np.exp(1j * np.asarray(leads)))))


def test_the_firmware_freezes_its_phase_where_the_twin_says_and_resumes_it_at_omega_t(tmp_path):
    link = open_link("sim://?speed=0&seed=5", robot=ROBOT)
    robot = link.transport.robot
    cam = SyntheticCamera(ROBOT, options=RenderOptions(noise_sigma=0.0, jpeg_quality=0))
    nav = ScriptedPause(t_brake_s=2.0, t_restart_s=5.8)
    config = RunConfig(GAIT, [(3.0, 0.0)], duration_s=8.0)
    rec = Recorder(tmp_path / "pause", load_scenario("path1").model_copy(
        update={"waypoints_m": [(3.0, 0.0)]}), N)
    out = RunLoop(link, VirtualCamera(robot, cam, keep_truth=False),
                  Localiser(cam.calibration(), ROBOT), ROBOT, config, rec, navigator=nav).run()
    assert out.reason == "duration" and out.failsafe_reports == 0
    assert nav.stage == "swimming again" and nav.braked is not None
    # two gait periods of 1.61 s: the least whole number of them that holds the brake 2 s
    assert nav.t_unbrake_s - 2.0 == pytest.approx(2 * 2 * math.pi / GAIT.omega_rad_s, abs=0.04)
    events = read_commands_csv(tmp_path / "pause.commands.csv")
    assert not [r for r in events if r["event"].startswith("refused")]  # omega 0, A 1.5: taken
    tel = nav.telemetry
    # braked: the references hold the S of the phase the brake froze (the link's latency apart)
    held = [(t, m) for t, m in tel if nav.t_brake_s + 0.2 < t < nav.t_unbrake_s
            and m.amplitude_rad > BRAKE_AMPLITUDE_RAD - 1e-3]
    assert len(held) > 20
    assert _reference_error(held, nav.braked) < 0.1
    # swimming again: the phase ran on from the frozen one and is omega t again, as the twin's,
    # whose plans from the restart on assume the phase of an uninterrupted gait: the phase's
    # lead over omega times the robot's clock is the one it had before the brake
    swimming = [(t, m) for t, m in tel if 0.5 < t < nav.t_brake_s
                and abs(m.amplitude_rad - GAIT.amplitude_rad) < 1e-3]
    again = [(t, m) for t, m in tel if t > nav.t_restart_s + 0.3
             and abs(m.amplitude_rad - GAIT.amplitude_rad) < 1e-3]
    assert len(swimming) > 8 and len(again) > 8
    change = math.remainder(_phase_lead_rad(again) - _phase_lead_rad(swimming), 2 * math.pi)
    assert abs(change) < 0.06  # one frame's rounding of the brake's end: omega / 30 s = 0.13


def test_a_braked_pause_glides_far_less_than_a_straight_one_and_straightens_after_its_end():
    twin = Twin(ROBOT, MODEL.sets, GAIT, LoopOptions(), (0.0, 0.0))
    n = N
    # a straight body coasting along +x at 0.08 m/s at t = 2 s
    state = np.zeros(2 * n + 4)
    state[n : n + 2] = (1.0, 1.0)
    state[2 * n + 2] = 0.08
    t_b = 2.0
    t_u = unbrake_time(GAIT, t_b)
    braked = stopped_twin(twin, braked_gait(GAIT, t_b))
    straight = stopped_twin(twin)
    dt = twin.dt_s
    paused = paused_drift(braked, straight, state, t_b, t_u, 6.0, 1)
    glided = paused_drift(braked, straight, state, t_b, t_b, 6.0, 1)  # no brake: straight at once
    assert len(paused) == len(glided) >= round(6.0 / dt) + 1
    travel = [float(np.hypot(*(s[-1, n : n + 2] - s[0, n : n + 2]))) for s in (paused, glided)]
    assert travel[0] < 0.5 * travel[1]
    # the brake's S while braked, and straight joints by the end
    at = round((t_u - t_b) / dt) - 1
    joints = np.diff(paused[at, :n])
    want = gait_reference(t_u, braked_gait(GAIT, t_b), 0.0, n)[0]
    assert np.max(np.abs(joints - want)) < 0.15
    assert np.max(np.abs(np.diff(paused[-1, :n]))) < 0.05
    # continuous across the brake's end: no jump in the body's position
    steps = np.hypot(*np.diff(paused[:, n : n + 2], axis=0).T)
    assert steps.max() < 0.12 * dt


def test_the_frozen_phase_resumes_as_omega_t_a_whole_number_of_periods_later():
    for t_b in (0.0, 1.234, 7.77):
        t_u = unbrake_time(GAIT, t_b, 2.0)
        assert t_u - t_b >= 2.0 - 1e-9
        frozen = braked_gait(GAIT, t_b).phase_rad
        assert math.remainder(GAIT.omega_rad_s * t_u - frozen, 2 * math.pi) == pytest.approx(
            0.0, abs=1e-9)
