"""The node's wiring, from the command line's arguments to a running loop and back to an exit
status: kobuki_lane.main() calls these in order. Nothing here parses a command line (the
arguments come parsed) or knows the lecture's settings (its table comes as `lecture`).

    connect_to_ros   the real rospy, or the stand-in for a dry run (exit 2 without a master)
    set_up           settings, calibration, odometry, controller and frame source (exit 2)
    open_outputs     decisions, video, stages, bag, the debug image topic
    started          the log line that says what runs
    drive            the loop run to its end, every output closed, the summary
    finish           the exit status and the run's last words
"""

import os
import sys
import time
from dataclasses import fields

from lanelib.bags import camera_from_bag, odometry_from_bag
from lanelib.camera import describe, load_calibration
from lanelib.cli import calibration_problem, fail
from lanelib.files import is_bag
from lanelib.improved import ImprovedParams
from lanelib.mounting import mounting_settings
from lanelib.outputs import Outputs, Progress, VideoSink, summary
from lanelib.robot import VELOCITY_TOPIC
from lanelib.robots import DEFAULT, load_robot
from lanelib.ros import (
    MasterWatch,
    RosUnavailable,
    connect,
    debug_publisher,
    private_names,
    velocity_topic,
)
from lanelib.safety import Safety, say
from lanelib.settings import resolve, unknown
from lanelib.sources import FrameCheck, Peeked, SourceError, check_first_frame, open_source
from lanelib.topics import TopicError, camera_from_topic, odometry_from, topic_of
from lanelib.tuning import Tuning
from lanelib.watch import EstimateTopics, Health

EXIT_STATUS = {'end of input': 0, 'ROS shutdown': 0, 'q pressed': 0, 'camera lost': 1,
               'pipeline errors': 1, 'SIGINT': 130, 'SIGTERM': 143, 'SIGHUP': 129}


IMPROVED_ONLY = tuple(f.name for f in fields(ImprovedParams)) + ('mounting', 'odom')
OTHER_PARAMETERS = ('controller', 'robot', 'calibration', 'mounting', 'odom', 'debug_image',
                    'robot_preset', 'diagnostic_period')  # in no table


def settings_from(args, get_param, lecture, warn=None):
    """(params, safety, controller name, improved params, robot): the tables (`lecture`: the
    lecture's, kobuki_lane.LaneParams) from a flag > a private ROS parameter > the --mounting
    file > the robot preset (--robot, lanelib/robots.py) > the tables' defaults; and
    args.calibration set the same way (default lecture). The improved controller's flags with
    the lecture's controller are refused (they would be ignored without a word), its private
    parameters said to be ignored; a preset may hold them (a robot's camera is the same under
    either controller)."""
    known = {f.name for table in (lecture, ImprovedParams, Safety) for f in fields(table)}
    loaded = None if args.robot else get_param('~robot_preset', None)  # the launch file's
    robot = load_robot(args.robot or str(get_param('~robot', DEFAULT)), known, loaded)
    preset = (robot.settings, f"the robot preset '{robot.name}' ({robot.path})")
    params = resolve(lecture, args, get_param, [preset])
    safety = resolve(Safety, args, get_param, [preset])
    name = args.controller or str(get_param('~controller', 'lecture'))
    args.calibration = str(args.calibration or get_param('~calibration', None) or
                           robot.settings.get('calibration', 'lecture'))
    improved = None
    if name == 'improved':
        mounting = (args.mounting or get_param('~mounting', '') or
                    robot.settings.get('mounting', ''))
        improved = resolve(ImprovedParams, args, get_param,
                           [(mounting_settings(mounting), f"the mounting file '{mounting}'"),
                            preset])
    else:
        flags = ['--' + n.replace('_', '-') for n in IMPROVED_ONLY if getattr(args, n) is not None]
        if flags:
            raise ValueError(f"{', '.join(flags)} set{'s' if len(flags) == 1 else ''} the "
                             "improved controller, but the controller is the lecture's: add "
                             '--controller improved, or leave '
                             f"{'it' if len(flags) == 1 else 'them'} out")
        given = [n for n in IMPROVED_ONLY if get_param('~' + n, None) is not None]
        if given and warn:
            warn('private parameter(s) %s set the improved controller; the controller is the '
                 "lecture's, so they are ignored (~controller improved uses them)",
                 ', '.join('~' + n for n in given))
    if 1.0 / params.rate >= safety.watchdog:  # its stops would come between the commands
        raise ValueError(f'rate {params.rate:g} Hz sends a command every {1 / params.rate:.2f} s, '
                         f'but the watchdog stops the robot after {safety.watchdog:g} s without '
                         'one: raise the rate or the watchdog')
    return params, safety, name, improved, robot


def open_outputs(prog, args, params, ros, source, controller):
    bag = None
    if args.bag:  # the one output that can still be refused: before any other is opened
        from lanelib.bags import BagError, BagRecorder

        try:
            if args.force and os.path.isfile(args.bag):
                os.remove(args.bag)  # --force: replaced, as the other outputs are
            bag = BagRecorder(args.bag, VELOCITY_TOPIC, images=args.bag_images)
        except BagError as e:
            source.release()
            fail(prog, str(e))
    show_progress = args.progress == 'on' or (args.progress == 'auto' and sys.stderr.isatty())
    if args.stages:
        os.makedirs(args.stages, exist_ok=True)  # made now that the run can go
    decisions = open(args.decisions, 'w', encoding='utf-8') if args.decisions else None
    video = VideoSink(args.video, params.rate) if args.video else None
    debug = watch = None
    if not args.dry_run:  # what a ROS run shows: the debug image, the decision and estimate
        debug = debug_publisher(ros)
        watch = EstimateTopics(ros, lane=controller.name == 'improved')
    return Outputs(params, decisions, video, args.stages, bag, debug, args.show,
                   Progress(source.total, show_progress), getattr(controller, 'draw', None),
                   getattr(controller, 'pictures', None), lambda text: ros.logwarn('%s', text),
                   debug_stage=str(ros.get_param('~debug_image', 'annotated')),
                   watch=[watch.publish] if watch else [])


def connect_to_ros(prog, args, private):
    """(ros, Twist, topic_ros) as lanelib.ros.connect makes them; exit 2 without a master,
    130 on Ctrl-C while one is looked for."""
    topic = topic_of(args.source)
    live = args.realtime or live_source(args.source)
    try:
        return connect(args.dry_run, live, topic and f'--source {topic}', private, args.quiet)
    except RosUnavailable as e:
        fail(prog, str(e))
    except KeyboardInterrupt:
        say(f'{prog}: interrupted while connecting to the ROS master')
        raise SystemExit(130) from None


def live_source(spec):
    """Whether a --source is live (a camera index, a URL, a ROS topic), not files."""
    return spec.isdigit() or '://' in spec or topic_of(spec) is not None


def pipeline_for(args):
    """--pipeline auto: detect() itself (the slides' calls) on a live source, where a frame
    has a whole loop period; the speed-up with the same segments over files."""
    if args.pipeline != 'auto':
        return args.pipeline
    return 'slides' if live_source(args.source) else 'fast'


def set_up(prog, args, ros, topic_ros, lecture, make_controller):
    """(params, safety, controller, source, frame check) from the arguments and the private
    parameters; `lecture`: the lecture's table; make_controller(name, params, camera, improved,
    pipeline, odometry): kobuki_lane's. Exit 2 for what cannot be used."""
    topic = topic_of(args.source)
    if topic and topic_ros is not None:  # a relative name: in the node's namespace, remapped
        topic = topic_ros.resolve_name(topic)
        args.source = 'ros:' + topic
    for unknown_name, guess in unknown(private_names(ros), (lecture, ImprovedParams, Safety),
                                       OTHER_PARAMETERS):
        ros.logwarn('unknown private parameter ~%s, ignored%s', unknown_name,
                    f' (did you mean ~{guess}?)' if guess else '')
    try:
        params, safety, name, improved, robot = settings_from(args, ros.get_param, lecture,
                                                              ros.logwarn)
        if robot.settings:
            ros.loginfo('robot preset %s', robot.describe())
        problem = calibration_problem(args.calibration, args.source)
        if problem:
            raise ValueError(problem)
        camera = None if args.calibration == 'topic' else load_calibration(args.calibration)
        if args.calibration == 'topic' and is_bag(args.source):  # a recorded run, as live
            camera, info = camera_from_bag(args.source, args.image_topic)
            ros.loginfo('calibration from the first camera_info on %s in %s: %s', info,
                        args.source, describe(camera))
        elif args.calibration == 'topic':
            camera = camera_from_topic(topic_ros, topic, args.open_timeout)
            ros.loginfo('calibration from the first camera_info beside %s: %s', topic,
                        describe(camera))

        odometry = None
        if name == 'improved' and topic_ros is None and is_bag(args.source):  # a dry run
            odometry = odometry_from_bag(args.source, args.odom, ros)  # on the bag's clock
        elif name == 'improved':
            odometry = odometry_from(topic_ros, args.odom, clock=ros.get_time)
        controller = make_controller(name, params, camera, improved, pipeline_for(args),
                                     odometry)
        for warning in getattr(controller, 'warnings', list)():
            ros.logwarn('%s', warning)
        source = Peeked(open_source(args.source, warn=ros.logwarn, image_topic=args.image_topic,
                                    rospy=topic_ros, fresh=safety.watchdog,
                                    timeout=args.open_timeout))
        # a calibration measured at a size (a file, the topic) must fit every frame; the
        # lecture's camera has no size on the slides and scales to any frame
        check = FrameCheck(None if args.calibration == 'lecture' else camera, ros.logwarn)
        check_first_frame(source, check)
    except (ValueError, TypeError, SourceError, TopicError) as e:  # CalibrationError too
        fail(prog, str(e))
    except KeyboardInterrupt:  # Ctrl-C while a URL did not answer: OpenCV may still be waiting
        say(f'{prog}: interrupted while opening {args.source}')
        os._exit(130)
    return params, safety, controller, source, check


def base_topic(args, ros):
    """The velocity topic: the lecture's for a dry run's record, else as ros.velocity_topic."""
    return VELOCITY_TOPIC if args.dry_run else velocity_topic(ros)


def started(ros, args, follower, params):
    """The log line at start: what runs, on what, how fast."""
    controller, lane = follower.controller, getattr(follower.controller, 'profile', None)
    detail = f' ({controller.runs})' if hasattr(controller, 'runs') else ''
    if lane:
        p = controller.p
        detail = (f' (lane {lane.name}, {p.lane_width:g} m; camera {p.camera_height:g} m up, '
                  f'pitched {p.camera_pitch:g} deg)')
    ros.loginfo('kobuki_lane: source %s, %s controller%s, algorithm %s, calibration %s, %.1f Hz '
                'on %s%s', follower.source.name, controller.name, detail, params.algorithm,
                args.calibration, params.rate, follower.base.topic,
                ' (dry run)' if args.dry_run else '')


def drive(prog, args, follower, topic_ros):
    """Run the loop (kobuki_lane.LaneFollower) to its end, with the ROS master watched; close
    the source and every output whatever happened; the exit status and the summary."""
    ros, base, source, outputs = follower.ros, follower.base, follower.source, follower.outputs
    watch = health = None
    if not args.dry_run:
        watch = MasterWatch(base, ros).start()
        health = Health(ros, follower, watch).start()
        outputs.watch.append(health.frame)
        follower.tuning = Tuning(ros, follower.controller)
    start = time.monotonic()
    try:
        ended = follower.run(0.0 if args.dry_run else args.wait_for_base)
    finally:
        for thread in (watch, health):
            if thread is not None:
                thread.stop()
        source.release()
        outputs.close()
        if topic_ros is not None:
            time.sleep(0.0 if args.dry_run else 0.3)  # deliver the final zero Twist
            topic_ros.signal_shutdown(follower.ended or 'exception')
    status = finish(prog, ended, follower, source, outputs)  # its words first, the summary last
    if args.stages:
        say(f'--stages: {outputs.stage_files} pictures, {outputs.stage_bytes / 1e6:.1f} MB in '
            f'{args.stages}')
    say(summary(follower.frames, source.skipped, follower.counts, time.monotonic() - start,
                ended))
    return status


def finish(prog, ended, follower, source, outputs):
    """The exit status, and a last word where the run did not end well."""
    status = EXIT_STATUS.get(ended, 0)
    if ended == 'camera lost':
        why = f': {source.silence()}' if hasattr(source, 'silence') else ''
        say(f"{prog}: error: camera lost: no frame from '{source.name}'{why}")
    if ended == 'pipeline errors':
        say(f'{prog}: error: {follower.errors} frames in a row could not be used (the last: '
            f'{follower.last_error}); see the log above')
    read = follower.frames + source.skipped
    short = source.total and read < source.total - 1
    if ended == 'end of input' and (short or getattr(source, 'cut_short', False)):
        say(f"{prog}: error: '{source.name}' is truncated: "
            f"{f'it ended after {read} of its {source.total} frames' if short else 'cut short'}"
            f', {follower.frames} acted on')
        status = 1
    elif ended == 'end of input' and follower.failed:
        say(f'{prog}: error: {follower.failed} of {follower.frames} frames could not be used '
            f'(the last: {follower.last_error}); the robot was stopped for each')
        status = 1
    for name, why in outputs.failures.items():
        say(f'{prog}: error: {name} was not written in full: {why}')
    if outputs.failures and status == 0:
        status = 1
    return status
