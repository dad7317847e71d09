"""The probe suite: bad input a new user would try, each run through the real command line.

One table, :data:`PROBES`: a command line (``{lab}`` is a folder of broken files made once, see
:func:`lab`), the exit status it must end with, and the words its message must contain. A user error
exits 2 with a message naming what is wrong and where, never a traceback; a twin run that ends
flagged exits with its flag's status (eelhost.errors). Every row is cheap: it fails before any
long computation. A few rows also run in a separate ``python -m eelhost`` process (no terminal),
where the output must hold no traceback and no escape codes.
"""

from __future__ import annotations

import logging
import os
import pickle
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from eelhost import cli, progress
from eelhost.estimation import cluster
from eelhost.estimation.optimise import Checkpoint
from eelsim.robot import DEFAULT_ROBOT

REPO = Path(__file__).resolve().parents[2]
BUNDLED = REPO / "datasets" / "paper_virtual_tank"
PAPER_ROBOT = (REPO / "sim" / "eelsim" / "data" / DEFAULT_ROBOT).read_text()
WORLD = (REPO / "host" / "eelhost" / "planning" / "examples" / "tank_5_obstacles.toml").read_text()
TRAIN, TEST = "straight_A0.61_w2.7", "straight_A0.61_w3.1"
RUN = "--waypoints 1,0 --gait 0.87,3.9 --duration 1 --out {tmp}/run"
COEFFS = "0.008,0.776,0.618,0.007"


@dataclass(frozen=True)
class Probe:
    """One bad input: the command line, the exit status, the words its message must contain."""

    name: str
    command: str
    status: int
    words: tuple[str, ...]
    stream: str = "err"  # where the words are: "err" (a user error) or "out" (a run's summary)


PROBES = [
    # transports: the URI of --link
    Probe("serial port missing", "run --link serial:///dev/eelbot-no-such-port " + RUN, 2,
          ("/dev/eelbot-no-such-port", "cannot open")),
    Probe("serial port not a tty", "run --link serial:///dev/null " + RUN, 2,
          ("/dev/null", "cannot open", "not a serial port")),
    Probe("serial relative path", "run --link serial://dev/ttyUSB0 " + RUN, 2,
          ("relative path", "serial:///dev/ttyUSB0")),
    Probe("unknown scheme", "run --link tcp://robot:5760 " + RUN, 2, ("unknown scheme",)),
    Probe("not a URI", "run --link ttyUSB0 " + RUN, 2, ("not a link URI", "serial://")),
    Probe("replay log missing", "run --link replay:///nowhere/run.rx.bin " + RUN, 2,
          ("/nowhere/run.rx.bin", "no such replay log")),
    Probe("sim unknown parameter", "run --link sim://?bogus=1 " + RUN, 2,
          ("unknown parameter", "bogus")),
    Probe("sim speed not a number", "run --link sim://?speed=fast " + RUN, 2, ("speed='fast'",)),
    Probe("sim with a path", "run --link sim://robot " + RUN, 2, ("takes no path",)),
    Probe("video without calibration", "run --link sim:// --camera take1.mp4 " + RUN, 2,
          ("--calibration",)),
    # waypoints
    Probe("run waypoints not numbers", "run --link sim:// --waypoints abc --gait 0.87,3.9 "
          "--out {tmp}/r", 2, ("--waypoints", "comma-separated numbers", "'abc'")),
    Probe("simulate waypoints not numbers", "simulate straight --waypoints abc --out {tmp}/r", 2,
          ("--waypoints", "comma-separated numbers")),
    Probe("simulate waypoints empty", "simulate straight --waypoints '' --out {tmp}/r", 2,
          ("--waypoints", "at least one x,y")),
    Probe("run waypoint with one number", "run --link sim:// --waypoints '1,0;2' --gait 0.87,3.9 "
          "--out {tmp}/r", 2, ("--waypoints", "expected 2 numbers")),
    # timing and durations
    Probe("run control period 0", "run --link sim:// --control-period 0 " + RUN, 2,
          ("--control-period", "greater than 0")),
    Probe("simulate control period 0", "simulate straight --control-period 0 --out {tmp}/r", 2,
          ("--control-period", "greater than 0")),
    Probe("control period off the step grid", "simulate straight --control-period 0.305 "
          "--out {tmp}/r", 2, ("not a whole multiple of the physics step",)),
    Probe("simulate duration negative", "simulate straight --duration -1 --out {tmp}/r", 2,
          ("--duration", "greater than 0")),
    Probe("run duration negative", "run --link sim:// --waypoints 1,0 --gait 0.87,3.9 "
          "--duration -1 --out {tmp}/r", 2, ("--duration", "greater than 0")),
    Probe("physics step not finite", "simulate straight --dt nan --out {tmp}/r", 2,
          ("--dt", "finite")),
    Probe("camera rate 0", "simulate straight --fps 0 --out {tmp}/r", 2,
          ("--fps", "fps must be positive")),
    Probe("gain not finite", "simulate straight --k-theta inf --out {tmp}/r", 2,
          ("--k-theta", "finite")),
    Probe("seed negative", "simulate straight --seed -1 --out {tmp}/r", 2, ("--seed", "at least 0")),
    Probe("speed negative", "run --link sim:// --speed -1 " + RUN, 2, ("--speed", "at least 0")),
    Probe("radius negative", "run --link sim:// --radius -1 " + RUN, 2,
          ("--radius", "greater than 0")),
    # gait, current, coefficients (negative values given unjoined, as users type them)
    Probe("gait not finite", "simulate straight --gait nan,2.7 --out {tmp}/r", 2,
          ("--gait", "finite")),
    Probe("gait frequency absurd", "simulate straight --gait 0.6,1e6 --out {tmp}/r", 2,
          ("--gait", "omega_rad_s", "robot's range")),
    Probe("gait amplitude negative", "simulate straight --gait -0.6,2.7 --out {tmp}/r", 2,
          ("--gait", "amplitude_rad must be positive")),
    Probe("gait frequency negative", "simulate straight --gait 0.8,-4 --out {tmp}/r", 2,
          ("--gait", "omega_rad_s must be positive")),
    Probe("gait amplitude beyond the robot", "run --link sim:// --waypoints 1,0 --gait 2.0,3.9 "
          "--out {tmp}/r", 2, ("--gait", "amplitude_rad", "robot's range")),
    Probe("gait with one number", "simulate straight --gait 0.6 --out {tmp}/r", 2,
          ("--gait", "A,omega")),
    Probe("current absurd", "simulate straight --current 100,0 --out {tmp}/r", 2,
          ("--current", "at most 1 m/s")),
    Probe("current speed negative", "simulate straight --current -0.02,0 --out {tmp}/r", 2,
          ("--current", "0.02,180")),
    Probe("current with one number", "simulate straight --current 0.02 --out {tmp}/r", 2,
          ("--current", "expected 2 numbers")),
    Probe("coefficient negative", "simulate straight --coefficients -1,0.7,0.6,0.01 --out {tmp}/r",
          2, ("--coefficients", "C_f")),
    # robot files
    Probe("robot mass a boolean", "simulate straight --robot {lab}/robot_bool_mass.toml "
          "--out {tmp}/r", 2, ("robot_bool_mass.toml", "link.mass_kg", "valid number")),
    Probe("robot coefficient a string", "simulate straight --robot {lab}/robot_string_cd.toml "
          "--out {tmp}/r", 2, ("robot_string_cd.toml", "hydrodynamics.C_d", "valid number")),
    Probe("robot link count a float", "simulate straight --robot {lab}/robot_float_n.toml "
          "--out {tmp}/r", 2, ("robot_float_n.toml", "n_links", "valid integer")),
    Probe("robot unknown key", "simulate straight --robot {lab}/robot_unknown_key.toml "
          "--out {tmp}/r", 2, ("robot_unknown_key.toml", "colour")),
    Probe("robot one link", "simulate straight --robot {lab}/robot_one_link.toml --out {tmp}/r",
          2, ("robot_one_link.toml", "n_links")),
    Probe("robot mass negative", "simulate straight --robot {lab}/robot_negative_mass.toml "
          "--out {tmp}/r", 2, ("robot_negative_mass.toml", "mass_kg")),
    Probe("robot coefficient nan", "simulate straight --robot {lab}/robot_nan.toml --out {tmp}/r",
          2, ("robot_nan.toml", "C_f")),
    Probe("robot not TOML", "simulate straight --robot {lab}/robot_broken.toml --out {tmp}/r", 2,
          ("robot_broken.toml",)),
    Probe("robot file missing", "simulate straight --robot {lab}/nowhere.toml --out {tmp}/r", 2,
          ("nowhere.toml",)),
    Probe("run robot file bad", "run --link sim:// --robot {lab}/robot_bool_mass.toml "
          + RUN, 2, ("robot_bool_mass.toml", "link.mass_kg")),
    # scenarios
    Probe("scenario unknown", "simulate nowhere --out {tmp}/r", 2,
          ("unknown scenario 'nowhere'", "straight")),
    Probe("scenario file unknown key", "simulate {lab}/scenario_unknown_key.toml --out {tmp}/r",
          2, ("scenario_unknown_key.toml", "colour")),
    Probe("scenario file string number", "simulate {lab}/scenario_string.toml --out {tmp}/r", 2,
          ("scenario_string.toml", "duration_s")),
    # datasets: manifests and experiment CSVs
    Probe("dataset CSV cut mid-number", "validate " + COEFFS + " {lab}/ds_cut", 2,
          (f"{TEST}.csv", "no newline", "cut")),
    Probe("dataset CSV not a number", "validate " + COEFFS + " {lab}/ds_not_number", 2,
          (f"{TEST}.csv:3:2", "x_m is not a number")),
    Probe("dataset CSV time backwards", "validate " + COEFFS + " {lab}/ds_time_back", 2,
          (f"{TEST}.csv:4:1", "time does not increase")),
    Probe("dataset same experiment in train and test", "validate " + COEFFS
          + " {lab}/ds_train_is_test", 2, ("manifest.toml", TRAIN, "motions.straight.train")),
    Probe("dataset names a missing experiment", "validate " + COEFFS + " {lab}/ds_missing", 2,
          ("manifest.toml", "motions.straight.test", "nowhere")),
    Probe("dataset manifest unknown key", "validate " + COEFFS + " {lab}/ds_unknown_key", 2,
          ("manifest.toml", "colour", "unknown key")),
    Probe("dataset manifest not TOML", "validate " + COEFFS + " {lab}/ds_broken", 2,
          ("manifest.toml", "not valid TOML")),
    Probe("dataset folder missing", "estimate {lab}/nowhere --out {tmp}/fit", 2,
          ("nowhere/manifest.toml", "cannot read")),
    Probe("coefficients file missing", "validate nowhere/coefficients.json {lab}/ds_good", 2,
          ("nowhere/coefficients.json",)),
    Probe("coefficients too few", "validate 0.1,0.2 {lab}/ds_good", 2, ("coefficients",)),
    # checkpoints and the cluster
    Probe("checkpoint truncated", "estimate {lab}/ds_good --motion straight --resume "
          "--out {lab}/ck", 2, ("checkpoint_straight_pd_morison_cmaes.npz", "not a readable checkpoint")),
    Probe("checkpoint a planted pickle", "estimate {lab}/ds_good --motion straight --resume "
          "--out {lab}/ck_pickle", 2, ("checkpoint_straight_pd_morison_cmaes.npz",
                                       "pickles are never read")),
    Probe("checkpoint an old pickle", "estimate {lab}/ds_good --motion straight --resume "
          "--out {lab}/ck_old", 2, ("checkpoint_straight_pd_morison_cmaes.pkl", "not read")),
    Probe("scheduler unreachable", "estimate {lab}/ds_good --scheduler tcp://127.0.0.1:1 "
          "--out {tmp}/fit", 2, ("--scheduler tcp://127.0.0.1:1", "no Dask scheduler")),
    Probe("scheduler plain tcp elsewhere", "estimate {lab}/ds_good --scheduler tcp://10.0.0.5:8786 "
          "--out {tmp}/fit", 2, ("--scheduler tcp://10.0.0.5:8786", "plain TCP to another machine",
                                 "--insecure")),
    Probe("scheduler tls without certificates", "estimate {lab}/ds_good --scheduler "
          "tls://10.0.0.5:8786 --out {tmp}/fit", 2, ("tls://10.0.0.5:8786", "--tls-ca-file")),
    Probe("scheduler not an address", "estimate {lab}/ds_good --scheduler foo --out {tmp}/fit",
          2, ("--scheduler foo", "not a scheduler address")),
    # plan worlds
    Probe("world missing", "plan {lab}/nowhere_world.toml", 2, ("nowhere_world.toml",)),
    Probe("world unknown key", "plan {lab}/world_unknown_key.toml --out {tmp}/plan", 2,
          ("world_unknown_key.toml", "colour")),
    Probe("world radius a string", "plan {lab}/world_string.toml --out {tmp}/plan", 2,
          ("world_string.toml", "goal.radius_m")),
    # counts of other commands
    Probe("plan threads 0", "plan tank_5_obstacles --threads 0", 2, ("--threads", "at least 1")),
    Probe("speeds duration 0", "speeds --duration 0", 2, ("--duration", "greater than 0")),
    Probe("dataset workers 0", "dataset {tmp}/tank --workers 0", 2, ("--workers", "at least 1")),
    Probe("dataset joints from a missing file", "dataset {tmp}/tank --joints-from "
          "{lab}/nowhere_robot.toml", 2, ("--joints-from", "nowhere_robot.toml")),
    Probe("dataset truth of the wrong count", "dataset {tmp}/tank --truth 0.01,0.8", 2,
          ("--truth", "expected 4 numbers")),
    Probe("dataset truth of the wrong count for its law", "dataset {tmp}/tank --fluid-law "
          "reynolds --truth 1,1,5,0.6", 2, ("--truth", "C_f_lam", "expected 5 numbers")),
    Probe("estimate-bench unknown tank", "estimate-bench --tanks bundled,nosuch", 2,
          ("unknown tanks", "nosuch")),
    Probe("run with both waypoints and a plan", "run --link sim:// --plan tank_5_obstacles "
          + RUN, 2, ("--waypoints", "--plan")),
    Probe("run waypoints without a gait", "run --link sim:// --waypoints 1,0 --out {tmp}/r", 2,
          ("--gait", "required with --waypoints")),
    Probe("dataset jitter negative", "dataset {tmp}/tank --timestamp-jitter -0.1", 2,
          ("--timestamp-jitter", "at least 0")),
    Probe("report bootstrap negative", "report --bootstrap -1", 2, ("--bootstrap", "at least 0")),
    Probe("report unknown law", "report --laws morison,water", 2,
          ("--laws", "expected fluid laws from", "'morison,water'")),
    Probe("estimate budget 0", "estimate {lab}/ds_good --budget 0", 2, ("--budget", "at least 1")),
    Probe("estimate budget not an integer", "estimate {lab}/ds_good --budget 1.5", 2,
          ("--budget", "expected an integer")),
    Probe("bench runs 0", "bench --runs 0", 2, ("--runs", "at least 1")),
    Probe("vision-bench frames 0", "vision-bench --frames 0", 2, ("--frames", "at least 1")),
    Probe("estimate-bench generations 0", "estimate-bench --ga-generations 0", 2,
          ("--ga-generations", "at least 1")),
    Probe("progress form unknown", "--progress sometimes ports", 2, ("--progress", "invalid choice")),
    Probe("command misspelt", "simulat straight", 2, ("invalid choice", "'simulate'")),
    Probe("option misspelt", "simulate straight --gate 0.6,2.7", 2,
          ("unrecognized arguments", "--gate")),
    # a twin run that ends flagged exits with its flag's status
    Probe("run too slow", "simulate straight --duration 1 --out {tmp}/r", 3, ("TOO_SLOW",), "out"),
    Probe("run diverges", "simulate straight --dt 0.3 --control-period 0.3 --duration 2 "
          "--out {tmp}/r", 4, ("ILL_CONDITIONED",), "out"),
]


def _write_lab(lab: Path) -> None:
    """The broken files the probes point at (each a small change to a good one)."""
    robots = {
        "robot_bool_mass": ("mass_kg = 0.25", "mass_kg = true"),
        "robot_string_cd": ("C_d = 0.776", 'C_d = "0.776"'),
        "robot_float_n": ("n_links = 6", "n_links = 6.0"),
        "robot_unknown_key": ("n_links = 6", "n_links = 6\ncolour = 1"),
        "robot_one_link": ("n_links = 6", "n_links = 1"),
        "robot_negative_mass": ("mass_kg = 0.25", "mass_kg = -0.25"),
        "robot_nan": ("C_f = 0.008", "C_f = nan"),
        "robot_broken": ("n_links = 6", "n_links = "),
    }
    for name, (old, new) in robots.items():
        assert old in PAPER_ROBOT
        (lab / f"{name}.toml").write_text(PAPER_ROBOT.replace(old, new, 1))
    scenario = 'amplitude_rad = 0.61\nomega_rad_s = 2.7\nk_theta = 0.5\nwaypoints_m = [[1.0, 0.0]]\n'
    (lab / "scenario_unknown_key.toml").write_text(scenario + "colour = 1\n")
    (lab / "scenario_string.toml").write_text(scenario + 'duration_s = "10"\n')
    (lab / "world_unknown_key.toml").write_text("colour = 1\n" + WORLD)
    assert "radius_m = 0.2" in WORLD
    (lab / "world_string.toml").write_text(WORLD.replace("radius_m = 0.2", 'radius_m = "0.2"', 1))

    def dataset(name: str, train: str = TRAIN, test: str = TEST, extra: str = "",
                fmt: str = '"eelbot-dataset/1"') -> Path:
        folder = lab / name
        folder.mkdir()
        for exp in (TRAIN, TEST):
            for ext in (".csv", ".json"):
                (folder / (exp + ext)).write_bytes((BUNDLED / (exp + ext)).read_bytes())
        (folder / "robot.toml").write_bytes((BUNDLED / "robot.toml").read_bytes())
        (folder / "manifest.toml").write_text(
            f'format = {fmt}\nrobot = "robot.toml"\n{extra}\n[motions.straight]\n'
            f'train = ["{train}"]\ntest = ["{test}"]\n'
        )
        return folder

    dataset("ds_good")
    cut = dataset("ds_cut") / f"{TEST}.csv"
    text = cut.read_text()
    cut.write_text(text[: text.index("\n", len(text) // 2) + 5])  # cut inside a line, no newline
    bad = dataset("ds_not_number") / f"{TEST}.csv"
    lines = bad.read_text().splitlines(keepends=True)
    cells = lines[2].split(",")
    lines[2] = ",".join([cells[0], "abc", *cells[2:]])
    bad.write_text("".join(lines))
    back = dataset("ds_time_back") / f"{TEST}.csv"
    lines = back.read_text().splitlines(keepends=True)
    lines[3] = ",".join(["0", *lines[3].split(",")[1:]])
    back.write_text("".join(lines))
    dataset("ds_train_is_test", test=TRAIN)
    dataset("ds_missing", test="nowhere")
    dataset("ds_unknown_key", extra="colour = 1")
    dataset("ds_broken", fmt="")
    ck = Checkpoint(lab / "ck" / "checkpoint_straight_pd_morison_cmaes.npz", {"x": 1})
    ck.save({"history": [], "payload": list(range(1000))}, force=True)
    whole = ck.path.read_bytes()
    ck.path.write_bytes(whole[: len(whole) // 2])  # a checkpoint cut by a full disk or a kill
    # a colleague's fit folder holding a crafted pickle: reading it would create lab/ran
    planted = pickle.dumps(_RunsAShellCommand(lab / "ran"))
    for folder, name in (("ck_pickle", "cmaes.npz"), ("ck_old", "cmaes.pkl")):
        (lab / folder).mkdir()
        (lab / folder / f"checkpoint_straight_pd_morison_{name}").write_bytes(planted)


class _RunsAShellCommand:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("lab")
    _write_lab(folder)
    return folder


@pytest.fixture(autouse=True)
def quick_and_quiet(monkeypatch):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 0.5)  # the refusal, without the wait
    level = logging.getLogger().level
    yield
    logging.getLogger().setLevel(level)
    progress.set_mode("auto")


def argv_of(probe: Probe, lab: Path, tmp: Path) -> list[str]:
    return shlex.split(probe.command.format(lab=lab, tmp=tmp))


@pytest.mark.parametrize("probe", PROBES, ids=[p.name for p in PROBES])
def test_probe_ends_with_its_status_and_a_message_naming_what_is_wrong(probe, lab, tmp_path, capsys):
    status = cli.main(argv_of(probe, lab, tmp_path))
    out, err = capsys.readouterr()
    assert status == probe.status, (out, err)
    assert "Traceback" not in out + err
    text = err if probe.stream == "err" else out
    for word in probe.words:
        assert word in text, text
    if probe.status == 2:  # a user error: one message, on a line of its own, naming the command
        first = err.strip().splitlines()[0]
        assert first.startswith("eelbot") and "error:" in first, err
        assert "usage:" not in err  # the message, not argparse's usage block
    assert not (lab / "ran").exists()  # nothing a planted file holds has run


def test_the_table_covers_every_kind_of_input():
    kinds = {"--link", "--waypoints", "--gait", "--current", "--duration", "--control-period",
             "--robot {lab}/robot", "{lab}/ds_", "--scheduler", "plan ", "--resume"}
    for kind in kinds:
        assert any(kind in p.command for p in PROBES), kind
    assert len({p.name for p in PROBES}) == len(PROBES)


SUBPROCESS_ROWS = ["serial relative path", "simulate waypoints not numbers", "robot mass a boolean",
                   "checkpoint truncated", "gait amplitude negative", "run too slow"]


@pytest.mark.parametrize("name", SUBPROCESS_ROWS)
def test_probe_in_a_process_of_its_own_writes_a_clean_log(name, lab, tmp_path):
    probe = next(p for p in PROBES if p.name == name)
    proc = subprocess.run(
        [sys.executable, "-m", "eelhost", *argv_of(probe, lab, tmp_path)],
        capture_output=True, text=True, check=False, timeout=300,
    )
    assert proc.returncode == probe.status, proc.stderr
    log = proc.stdout + proc.stderr
    assert "Traceback" not in log
    assert "\x1b" not in log and "\r" not in log  # no bar redrawing in a log
    for word in probe.words:
        assert word in (proc.stderr if probe.stream == "err" else proc.stdout)


def test_debug_shows_the_traceback_of_a_user_error(lab, tmp_path):
    probe = next(p for p in PROBES if p.name == "serial relative path")
    proc = subprocess.run(
        [sys.executable, "-m", "eelhost", "--debug", *argv_of(probe, lab, tmp_path)],
        capture_output=True, text=True, check=False, timeout=300,
    )
    assert proc.returncode != 0
    assert "Traceback" in proc.stderr and "LinkURIError" in proc.stderr


def test_an_error_during_a_bar_starts_a_line_of_its_own(lab, tmp_path, capsys):
    probe = next(p for p in PROBES if p.name == "checkpoint truncated")
    assert cli.main(["--progress", "bar", *argv_of(probe, lab, tmp_path)]) == 2
    err = capsys.readouterr().err
    assert any(line.startswith("eelbot estimate: error:") for line in err.splitlines()), err
