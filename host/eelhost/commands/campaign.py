"""``eelbot campaign``: run a protocol of takes into a dataset that ``eelbot estimate`` loads.

Each take is an ``eelbot run`` (the same recording, the same clean stop) of one gait and motion of
the plan (:mod:`eelhost.field.campaign`), written into the dataset folder with its name; after each
one the manifest is rewritten with the takes finished so far, split into train and test as the
plan says, beside a copy of the robot file. Rerunning the same command resumes: finished takes are
skipped, a take cut short is run again. Between takes a real robot rests (``rest_s``) and the
operator is asked to put it back at the start; a ``sim://`` robot starts afresh at the plan's
start pose (the URI's ``start=`` is set for each take).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from urllib.parse import parse_qsl, urlencode

from eelhost.commands import COMMANDS
from eelhost.commands.common import NON_NEGATIVE, OptionError
from eelhost.commands.link_options import add_link_options, resolve_link_options
from eelhost.commands.run import add_take_options, current_option, view_opener
from eelhost.data.experiments import manifest_text, write_manifest
from eelhost.field.campaign import CampaignPlan, Take, load_plan, plan_takes, take_done
from eelhost.field.provenance import robot_file_text
from eelhost.field.runloop import RunConfig
from eelhost.field.session import TakeNotes
from eelhost.field.take import TakeRequest, refuse_overwrite, run_take
from eelhost.files import OutputError, atomic_write, check_output_folder
from eelhost.link.uri import parse_link_uri
from eelhost.vision.markerfile import load_marker_file
from eelsim.control import Gait
from eelsim.robot import load_robot


@COMMANDS.add(
    "campaign",
    "run a protocol of takes (the paper's gait grid by default) into a dataset",
)
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "campaign",
        help=COMMANDS.description("campaign"),
        description="Run every take of the plan (default: the paper's 4 x 4 gait grid, straight "
        "and turning, the corner gaits for training) with eelbot run's loop and recording, into "
        "--out, a dataset folder eelbot estimate loads. Resumable: run it again to go on. "
        "Example: eelbot campaign plan.toml --link 'sim://?speed=0' --out lab/campaign",
    )
    p.add_argument("plan", nargs="?", help="plan TOML (default: the paper's protocol; see "
                   "docs/host.md)")
    add_link_options(p, "required unless --write-plan")
    p.add_argument("--out", metavar="FOLDER", help="the dataset folder (required unless "
                   "--write-plan)")
    p.add_argument("--camera", metavar="SOURCE", help="as eelbot run (sim://: synthetic)")
    p.add_argument("--calibration", metavar="FILE", help="calibration JSON")
    p.add_argument("--markers", metavar="FILE", help="markers.json from eelbot markers")
    p.add_argument("--no-prompt", action="store_true", help="real robot: do not ask for a reset "
                   "between takes (it is put back by other means)")
    p.add_argument("--rest", type=NON_NEGATIVE, metavar="S", help="rest between takes, s (the plan's "
                   "rest_s; a sim:// robot does not rest)")
    p.add_argument("--speed", type=NON_NEGATIVE, help="sim:// only: simulated s per wall s (0: as fast "
                   "as possible)")
    p.add_argument("--write-plan", metavar="FILE", help="write the plan (default: the paper's) "
                   "as TOML to edit, and stop (an existing FILE only with --force)")
    p.add_argument("--force", action="store_true", help="with --write-plan: replace FILE (an "
                   "edited plan is not overwritten without it)")
    add_take_options(p)
    p.set_defaults(run=run)


def sim_uri_at(uri: str, start: list[float]) -> str:
    """A ``sim://`` URI whose robot starts at ``start`` (x, y, heading_deg)."""
    base, _, query = uri.partition("?")
    params = [(k, v) for k, v in parse_qsl(query, keep_blank_values=True) if k != "start"]
    params.append(("start", ",".join(f"{v:g}" for v in start)))
    return base + "?" + urlencode(params, safe=",:")


def plan_toml(plan: CampaignPlan) -> str:
    """The plan as a TOML file (every key, for editing)."""
    lines = [f"# eelbot campaign plan: {plan.name} (keys: docs/host.md)"]
    for key, value in plan.model_dump().items():
        if value is None:
            value = [list(g) for g in plan.train_gaits()]
        lines.append(f"{key} = {_toml(value)}")
    return "\n".join(lines) + "\n"


def _toml(value: object) -> str:
    if isinstance(value, str):
        return '"' + value.replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


def write_dataset_manifest(folder: Path, plan: CampaignPlan, takes: list[Take]) -> Path:
    """Rewrite the manifest with the finished takes, per motion and split."""
    motions: dict[str, dict[str, list[str]]] = {}
    for take in takes:
        if take_done(folder, take.name):
            split = motions.setdefault(take.motion, {"train": [], "test": []})
            split[take.split].append(take.name)
    return write_manifest(folder, manifest_text("robot.toml", motions, [],
                                                description=f"eelbot campaign: {plan.name}"))


def _wait_rest(seconds: float, stopped: list[str]) -> None:
    end = time.monotonic() + seconds
    while not stopped and time.monotonic() < end:
        time.sleep(min(0.2, end - time.monotonic()))


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    resolve_link_options(args)
    plan = load_plan(args.plan)
    if args.write_plan:
        target = Path(args.write_plan)
        if target.is_dir():
            raise OutputError(f"--write-plan: {target} is a folder; give a file name such as "
                              f"{target / 'plan.toml'}")
        if target.exists() and not args.force:
            raise OutputError(f"--write-plan: {target} exists (an edited plan?); choose another "
                              "file or add --force to replace it")
        atomic_write(target, plan_toml(plan))
        print(f"wrote {args.write_plan}")
        return 0
    for option, value in (("--link", args.link), ("--out", args.out)):
        if not value:
            raise OptionError(f"{option}: required to run a campaign (only --write-plan does "
                              "without)")
    parse_link_uri(args.link)
    virtual = args.link.startswith("sim:")
    if args.speed is not None and not virtual:
        raise OptionError("--speed: only a sim:// robot can run faster than real time")
    robot = load_robot(args.robot_file)
    markers = load_marker_file(args.markers)
    current = current_option(args.current, virtual)
    folder = check_output_folder(args.out)  # read-only or a file: said before the first take
    atomic_write(folder / "robot.toml", robot_file_text(args.robot_file))
    if args.plan and Path(args.plan).resolve() != (folder / "plan.toml").resolve():
        atomic_write(folder / "plan.toml", Path(args.plan).read_bytes())
    takes = plan_takes(plan)
    rest = plan.rest_s if args.rest is None else args.rest
    stopped: list[str] = []
    ran = 0
    print(f"campaign {plan.name!r}: {len(takes)} takes into {folder}", flush=True)
    for i, take in enumerate(takes, start=1):
        label = f"[{i:>{len(str(len(takes)))}}/{len(takes)}] {take.name}"
        if take_done(folder, take.name):
            print(f"{label}: done earlier, skipped", flush=True)
            continue
        if ran and not virtual:
            _wait_rest(rest, stopped)
            if not args.no_prompt and not stopped:
                x, y, h = plan.start
                try:
                    input(f"put the robot at x {x:g} m, y {y:g} m, heading {h:g} deg, still, "
                          "then press Enter: ")
                except EOFError:
                    raise OptionError("the campaign needs the operator to put the robot back "
                                      "between takes: run it in a terminal, or --no-prompt") from None
        if stopped:
            break
        uri = sim_uri_at(args.link, plan.start) if virtual else args.link
        gait = Gait(take.amplitude_rad, take.omega_rad_s, take.beta_rad, take.k_theta)
        config = RunConfig(gait, [take.waypoint_m], acceptance_radius_m=plan.radius_m,
                           control_period_s=plan.control_period_s, duration_s=plan.duration_s)
        notes = TakeNotes(uri, args.robot_file, take.motion, current, args.note,
                          extra={"campaign": {"plan": plan.name, "take": take.name,
                                              "split": take.split, "repeat": take.repeat}})
        stem = str(folder / take.name)
        refuse_overwrite(stem, force=True)  # not done: a partial take is run again
        request = TakeRequest(robot, config, stem, notes, args.camera, args.calibration,
                              markers.layout, args.speed)
        result = run_take(request, view_opener(args, current=current), announce=lambda msg: print(msg, flush=True),
                          stop_flag=stopped)
        ran += 1
        out = result.outcome
        clock = (f", simulated {out.t_end_s:.1f} s in {result.wall_s:.1f} s" if result.virtual
                 else f" in {result.wall_s:.1f} s")
        print(f"{label}: {out.reason} at {out.t_end_s:.1f} s ({take.split}){clock}, "
              f"{out.frames_with_pose}/{out.frames} frames with a pose, Stop {out.stop_outcome}",
              flush=True)
        write_dataset_manifest(folder, plan, takes)
        if stopped:
            break
    write_dataset_manifest(folder, plan, takes)
    done = sum(take_done(folder, t.name) for t in takes)
    print(f"{done}/{len(takes)} takes done; dataset {folder} (manifest.toml)"
          + (f"; stopped by {stopped[0]}: run the same command to go on" if stopped else ""))
    return 0 if done == len(takes) else 1
