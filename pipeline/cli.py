"""Command line: ``python -m pipeline run | check | view | study | sweep | robot init | arm play|verify | export``.

* ``run [--config FILE] [--set key=value ...] [--stages a,b] [--out DIR] [--force] [--accept-poor]``
* ``check`` (same options as ``run``): validate what ``run`` would validate, try a quick sample of
  each stage's poses (:mod:`pipeline.run.preflight`), write nothing, and print which stages would run
  or be reused, and the robot's plausibility warnings
* ``view [RUN_DIR] [--robot NAME] [--configurations NAME] [--trajectory NAME] [--open]``
* ``study [NAME [ARGS...]]`` (no name: list the registered studies)
* ``robot init ARM.urdf [--base LINK] [--tip LINK] [--lock JOINT=VALUE] [--torque-side link|motor] [--out FILE]
  [--force]``: a commented robot.yaml
* ``export RUN_DIR [--to DIR] [--rate-hz R] [--start q1,...] [--bag-format sqlite3|mcap]``: the run's
  designed poses, excitation and plans as files for an arm (:mod:`pipeline.run.export`)
* ``arm play MOTION --out RECORD`` (the stand-in arm, :mod:`pipeline.sim.player`); ``arm verify MOTION RECORD``:
  a recorded execution of an exported motion judged (:mod:`pipeline.run.verify`; exit 3 when a recorded
  effort exceeds its limit)
* ``sweep [--seeds 0-19] [--robots A,B] [--config FILE] [--set k=v] [--vary k=[a,b]] [--scheduler ADDR]``

``run`` ends with the headline table (:mod:`pipeline.run.headline`) and the path of ``report.md``.
A run directory made with another robot is refused (exit 2) unless ``--force``.

Exit codes: 0 done; 2 a :class:`pipeline.core.errors.PipelineError` (bad input, a fault writing
files, the run directory locked by another run), one line on stderr, no traceback; 3 a stage
failed its quality gate (one line naming the figure and the threshold; the result is kept in
``<run>/<stage>.rejected/``); 130 interrupted (SIGINT or SIGTERM; nothing of the stage committed).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import pipeline
from pipeline.core import config as config_mod
from pipeline.core.config import load_config
from pipeline.core.errors import PipelineError, QualityGateError
from pipeline.core.interrupts import handle_termination
from pipeline.exchange.joint_limits import read_joint_limits_yaml
from pipeline.exchange.robot_program import PROGRAM_FORMATS, ProgramFormat
from pipeline.papers import registry as studies
from pipeline.robot.model import RobotModel
from pipeline.robot.plausibility import placeholder_warnings, robot_warnings
from pipeline.robot.yaml_init import StatedJointLimits, parse_locks, write_robot_yaml
from pipeline.run import sweep
from pipeline.run.export import export_run
from pipeline.run.headline import print_headline, read_headline
from pipeline.run.preflight import preflight
from pipeline.run.run_check import check_run
from pipeline.run.runner import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_QUALITY_GATE, run_pipeline
from pipeline.run.stage_plan import stages_line
from pipeline.run.verify import verify_files
from pipeline.sim.player import load_robot, play_file
from pipeline.view.run_view import view_run


def _built_in_robots() -> list[str]:
    robots = config_mod.REPO_ROOT / "robots"
    return sorted(d.name for d in robots.iterdir() if (d / "robot.yaml").is_file()) if robots.is_dir() else []


def _add_run_options(r: argparse.ArgumentParser) -> None:
    r.add_argument("--config", metavar="FILE", help="YAML run configuration (e.g. configs/quick.yaml)")
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a setting, dotted keys, YAML values (repeatable): "
                        "--set seed=3 --set calibration.n_configurations=40")
    r.add_argument("--stages", metavar="A,B", help="stages to run (their upstream stages are added)")
    r.add_argument("--out", metavar="DIR", help="directory holding the runs (default data/runs)")
    r.add_argument("--force", action="store_true",
                   help="re-run the stages even when reusable (and replace a run of another robot)")
    r.add_argument("--accept-poor", action="store_true",
                   help="hand on results that fail a stage's quality gate (the report says so)")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m pipeline", description=__doc__.split("\n\n")[0])
    p.add_argument("--version", action="version", version=f"pipeline {pipeline.__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="{run,check,view,study,sweep,robot,arm,export}")

    stages_robots = (f"stages (in order): {', '.join(config_mod.stage_names())}; "
                     f"built-in robots: {', '.join(_built_in_robots()) or 'none'}")
    r = sub.add_parser("run", help="run the pipeline stages", epilog=stages_robots, description=(
        "Run the stages into DIR/<name>/ (default data/runs/<name>/). A stage whose inputs are "
        "unchanged since its last run (and whose files are intact) is reused. Exit codes: 0 done, "
        "2 bad input or a fault writing files, 3 a quality gate failed, 130 interrupted."))
    _add_run_options(r)
    c = sub.add_parser("check", help="validate config, robot and data files; write nothing",
                       epilog=stages_robots, description=(
                           "Validate exactly what `run` validates before writing (configuration, robot, "
                           "the data files of every stage that would run), try a quick sample of poses for "
                           "each such stage (reflector visible, ISO cube, moves, IK seeds) and print which "
                           "stages would run or be reused. Writes nothing."))
    _add_run_options(c)

    v = sub.add_parser("view", help="show the robot, saved configurations and trajectories in meshcat")
    v.add_argument("run_dir", nargs="?", metavar="RUN_DIR",
                   help="a run directory (default: the most recent under data/runs)")
    v.add_argument("--robot", help="robot name or folder (default: the run's calibrated/nominal robot)")
    v.add_argument("--configurations", metavar="NAME", help="show this configuration set only")
    v.add_argument("--trajectory", metavar="NAME", help="replay this trajectory only")
    v.add_argument("--open", action="store_true", help="open the page in a web browser")
    v.add_argument("--once", action="store_true", help="show everything once and exit (no waiting)")

    s = sub.add_parser("study", help="run a registered study (no name: list them)")
    s.add_argument("name", nargs="?")
    s.add_argument("args", nargs=argparse.REMAINDER, help="arguments passed to the study")

    sweep.add_arguments(sub.add_parser("sweep", help="run a grid of runs (seeds x robots x settings), one table"))

    rb = sub.add_parser("robot", help="robot files: `robot init ARM.urdf` writes a commented robot.yaml")
    rsub = rb.add_subparsers(dest="robot_command", required=True, metavar="{init}")
    ri = rsub.add_parser("init", help="write a commented robot.yaml for a URDF (assumed values to edit)",
                         description="Write robot.yaml beside ARM.urdf (or --out) with the values the URDF "
                                     "lacks (gear ratios, rotor inertia, friction, tool, tracker, capsules) "
                                     "assumed by stated rules, each commented, for you to edit.")
    ri.add_argument("urdf", metavar="ARM.urdf",
                    help="the arm's URDF, or an MJCF model (model.xml: converted to model.urdf beside robot.yaml)")
    ri.add_argument("--base", metavar="LINK", help="first link of the arm chain (default: the URDF's root)")
    ri.add_argument("--tip", metavar="LINK", help="last link of the arm chain (default: found from the joints)")
    ri.add_argument("--out", metavar="FILE", help="where to write (default: robot.yaml beside the URDF)")
    ri.add_argument("--lock", metavar="JOINT=VALUE", action="append", default=[],
                    help="hold a joint off the arm (a linear track, a gripper) at VALUE rad or m; repeatable "
                         "(default: 0 when its limits allow, else mid-range)")
    ri.add_argument("--torque-side", choices=("link", "motor"), default=None,
                    help="where your torque log is measured: link (joint torque sensors, e.g. Franka, iiwa) or "
                         "motor (motor currents); default: detected from the URDF, else motor")
    ri.add_argument("--joint-limits", metavar="joint_limits.yaml",
                    help="a MoveIt joint_limits.yaml: its accelerations (and velocity/effort limits the URDF lacks)")
    ri.add_argument("--force", action="store_true", help="replace an existing robot.yaml")
    _add_arm_parser(sub)
    _add_export_parser(sub)
    return p


def _add_export_parser(sub: argparse._SubParsersAction) -> None:
    """``export RUN_DIR [--to DIR] [--rate-hz R] [--start q1,...] [--bag-format sqlite3|mcap]``."""
    e = sub.add_parser("export", help="write a run's designed poses, excitation and plans as files for an arm",
                       description="Write, for each stage the run holds, the files a controller needs "
                                   "(docs/exchange.md): calibration poses, template, tour and identified parameters, "
                                   "the excitation, the planned trajectories (CSV and ROS 2 bag, q, velocity, "
                                   "acceleration, feedforward torque), servo gains, and the handed-on robot "
                                   "(URDF with the joint friction, robot.yaml, joint_limits.yaml).")
    e.add_argument("run_dir", metavar="RUN_DIR")
    e.add_argument("--to", metavar="DIR", help="folder to write (default RUN_DIR/export; replaced as a whole)")
    e.add_argument("--rate-hz", type=float, default=1000.0, help="sample rate of every motion (default 1000)")
    e.add_argument("--start", type=_floats, default=None, metavar="Q1,...",
                   help="start configuration, rad (default: the robot's ready pose)")
    e.add_argument("--bag-format", choices=("sqlite3", "mcap"), default="sqlite3", help="rosbag2 storage")
    e.add_argument("--program", type=_program_formats, default=(), metavar="FORMAT,...",
                   help="also the calibration tour as a controller program: urscript, krl, rapid (6 axes)")


def _cmd_export(ns: argparse.Namespace) -> int:
    folder, written, notes = export_run(ns.run_dir, ns.to, ns.rate_hz, ns.start, ns.bag_format, ns.program)
    print(f"wrote {folder}: {', '.join(written)}")
    for note in notes:
        print(f"note: {note}")
    return 0


def _program_formats(text: str) -> tuple[ProgramFormat, ...]:
    """``urscript,krl,...`` as program formats (argparse type: an unknown one is a usage error, exit 2)."""
    chosen = [x.strip() for x in text.split(",") if x.strip()]
    formats = tuple(f for f in PROGRAM_FORMATS if f in chosen)
    unknown = [x for x in chosen if x not in PROGRAM_FORMATS]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown program format(s) {unknown}: choose from "
                                         f"{', '.join(PROGRAM_FORMATS)}")
    return formats


def _floats(text: str) -> list[float]:
    """``K1,K2,...`` as numbers (argparse type: a bad one is a usage error, exit 2)."""
    try:
        return [float(x) for x in text.split(",")]
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of numbers: {text!r}") from err


def _add_arm_parser(sub: argparse._SubParsersAction) -> None:
    """``arm play MOTION --engine mujoco|pipeline --out RECORD``: the stand-in arm behind files."""
    arm = sub.add_parser("arm", help="the stand-in arm behind files: `arm play MOTION --out RECORD`")
    asub = arm.add_subparsers(dest="arm_command", required=True, metavar="{play,verify}")
    ap = asub.add_parser("play", help="play an exported motion on the stand-in arm and record its logging",
                         description="Play a JointTrajectory bag or motion CSV on the hidden robot under its drives "
                                     "(400 µs cascade) and write what the arm logs: JointState at the logging rate "
                                     "and, at the motion's dwells, tracker readings: one bag, or CSV when RECORD ends "
                                     "in .csv with the tracker readings in a bag RECORD_tracker beside it.")
    ap.add_argument("motion", metavar="MOTION_BAG_OR_CSV")
    ap.add_argument("--engine", choices=("mujoco", "pipeline"), default="mujoco")
    ap.add_argument("--out", required=True, metavar="RECORD")
    ap.add_argument("--robot", default="rx130l", help="built-in robot, folder, URDF or example arm (panda)")
    ap.add_argument("--seed", type=int, default=1, help="seed of the hidden robot (the run's seed)")
    ap.add_argument("--log-rate-hz", type=float, default=None, help="logging rate (default: every 400 µs sample)")
    ap.add_argument("--hold-s", type=float, default=0.0, help="hold the last pose this long after the motion (s)")
    vp = asub.add_parser("verify", help="judge a recorded execution of an exported motion",
                         description="Compare what the arm logged (JointState bag or joint-state CSV) with the motion "
                                     "it was sent (JointTrajectory bag or motion CSV): time offset, joint tracking "
                                     "error, TCP deviation, effort against the limits and the feedforward, settling. "
                                     "Exit 3 when a recorded effort exceeds its limit.")
    vp.add_argument("motion", metavar="MOTION_BAG_OR_CSV")
    vp.add_argument("record", metavar="RECORD")
    vp.add_argument("--robot", default="rx130l",
                    help="built-in robot, folder (an export's robot/), URDF or example arm")
    vp.add_argument("--effort-scale", type=_floats, default=None, metavar="K1,K2,...",
                    help="joint-side N·m per logged effort unit, per joint (motor currents: k_t x gear ratio)")


def _cmd_arm(ns: argparse.Namespace) -> int:
    if ns.arm_command == "verify":
        result = verify_files(ns.motion, ns.record, load_robot(ns.robot), effort_scale=ns.effort_scale)
        for line in result.lines():
            print(line)
        if not result.limits_kept:
            print(f"verify failed: {result.lines()[0]}", file=sys.stderr)
            return EXIT_QUALITY_GATE
        return 0
    record = play_file(ns.motion, ns.out, robot=ns.robot, engine=ns.engine, seed=ns.seed, log_rate_hz=ns.log_rate_hz,
                       hold_s=ns.hold_s)
    print(f"wrote {', '.join(str(p) for p in record.paths)} ({record.states.n_samples} joint states, "
          f"{record.tracker.n_samples} tracker readings, engine {record.engine})")
    return 0


def _cmd_run(ns: argparse.Namespace) -> int:
    cfg = load_config(ns.config, ns.overrides, ns.stages)
    cfg.accept_poor = ns.accept_poor
    result = run_pipeline(cfg, out_root=ns.out, force=ns.force, warm_up=True)
    print_headline(read_headline(result.run_dir, list(result.outputs)))
    print(result.report)
    return 0


def _cmd_check(ns: argparse.Namespace) -> int:
    cfg = load_config(ns.config, ns.overrides, ns.stages)
    cfg.accept_poor = ns.accept_poor
    prep = check_run(cfg, out_root=ns.out, force=ns.force)
    problems = 0
    for exc in preflight(prep):
        print("error: " + " ".join(exc.one_line().split()), file=sys.stderr, flush=True)
        problems += 1
    if problems:
        return EXIT_BAD_INPUT
    print(f"ok: {cfg.source}, robot {cfg.robot}, run directory {prep.run_dir}")
    for plan in prep.plans:
        reason = prep.reasons[plan.name]
        print(f"  {plan.name}: " + ("reuse" if reason is None else f"run ({reason})")
              + f"; {plan.provenance.sentence()}")
    if prep.second_pass:
        print(f"  {prep.second_pass}")
    for warning in robot_warnings(prep.nominal):      # placeholder data: warnings, not errors
        print(f"warning: robot {prep.nominal.name}: {warning}")
    for warning in placeholder_warnings(prep.nominal, [p.name for p in prep.plans]):
        print(f"warning: robot {prep.nominal.name}: {warning}")
    return 0


def _cmd_robot(ns: argparse.Namespace) -> int:
    stated = None
    if ns.joint_limits:
        table = read_joint_limits_yaml(ns.joint_limits)
        stated = StatedJointLimits(Path(ns.joint_limits).name, *(
            dict(zip(table.joint_names, map(float, values), strict=True))
            for values in (table.velocity_rad_s, table.acceleration_rad_s2, table.effort_Nm)))
    written = write_robot_yaml(ns.urdf, ns.out, base=ns.base, tip=ns.tip, lock=parse_locks(ns.lock), force=ns.force,
                               torque_side=ns.torque_side, joint_limits=stated)
    print(f"wrote {written}: edit the values marked as assumed, then run with --set robot={written.parent}")
    line = stages_line(RobotModel.load(written.parent, yaml_path=written))
    if line:
        print(line)
    return 0


def _cmd_view(ns: argparse.Namespace) -> int:
    view_run(ns.run_dir, robot=ns.robot, configurations=ns.configurations, trajectory=ns.trajectory,
             open_browser=ns.open, wait=not ns.once)
    return 0


def _cmd_study(ns: argparse.Namespace) -> int:
    if not ns.name:
        names = studies.list_studies()
        print("\n".join(names) if names else "no studies registered (see pipeline/papers/registry.py)")
        return 0
    args, results_dir = list(ns.args), None
    if "--results" in args:
        i = args.index("--results")
        if i + 1 >= len(args):
            raise PipelineError("study", "--results", "expected a folder")
        results_dir = args[i + 1]
        del args[i:i + 2]
    return studies.run_study(ns.name, args, results_dir=results_dir)


def main(argv: Sequence[str] | None = None) -> int:
    ns = _parser().parse_args(argv)
    commands = {"run": _cmd_run, "check": _cmd_check, "view": _cmd_view, "study": _cmd_study,
                "sweep": sweep.main, "robot": _cmd_robot, "arm": _cmd_arm,
                "export": _cmd_export}
    try:
        with handle_termination():
            return commands[ns.command](ns)
    except QualityGateError as exc:
        print("quality gate failed: " + " ".join(exc.one_line().split()), file=sys.stderr)
        return EXIT_QUALITY_GATE
    except PipelineError as exc:
        print("error: " + " ".join(exc.one_line().split()), file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted: nothing of the unfinished stage was kept; run again to resume", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    raise SystemExit(main())
