"""The command lines' shared conventions: a mistake the user can fix is one line on stderr,
'PROG: error: what was wrong and what to do', and exit status 2, never a traceback."""

import os
import sys

import cv2

from lanelib.files import is_bag, output_problem
from lanelib.topics import topic_of, topic_problem


def fail(prog, message):
    """Say what was wrong and exit with status 2."""
    print(f'{prog}: error: {message}', file=sys.stderr)
    raise SystemExit(2)


def warning(message):
    """A warning on stderr: what a source says when it was given no logger of its own."""
    print(f'warning: {message}', file=sys.stderr)


def check_output(prog, path, what):
    """Refuse an output path whose folder is missing or read-only, before the run starts."""
    problem = output_problem(path)
    if problem:
        fail(prog, f"{what} '{path}': {problem}")


def check_outputs_apart(prog, inputs, outputs, force, stages=None):
    """Refuse an output that would destroy an input or another output, for every program:
    one that is an input file (inputs: (path, what) of everything the run reads), lies in an
    input folder (its files are read as frames), is named twice, or exists already (unless
    `force`); and a --stages folder that is an input folder."""
    read = [(os.path.realpath(path), what) for path, what in inputs
            if path and os.path.exists(path)]
    seen = {}
    for path, what in outputs:
        real = os.path.realpath(path)
        for where, source in read:
            if real == where:
                fail(prog, f"{what} '{path}' is the {source} itself: writing it would destroy "
                           'it')
            if os.path.isdir(where) and os.path.dirname(real) == where:
                fail(prog, f"{what} '{path}' is inside the {source} folder, where it would be "
                           'read as a frame; write it elsewhere')
        if real in seen:
            fail(prog, f"{what} and {seen[real]} are the same file '{path}'")
        seen[real] = what
        if os.path.isdir(real):
            fail(prog, f"{what} '{path}' is a folder; give a file name")
        if os.path.exists(real) and not force:
            fail(prog, f"{what} '{path}' exists already; remove it, choose another name, or "
                       'add --force to replace it')
        if what == '--video' and os.path.splitext(path)[1].lower() not in ('.avi', '.mp4'):
            fail(prog, f"--video '{path}': give a name ending in .avi or .mp4")
        existed = os.path.exists(real)
        try:  # opened for appending, so nothing in it is lost; made now, removed again
            with open(real, 'a', encoding='utf-8'):
                pass
        except OSError as e:
            fail(prog, f"{what} '{path}': cannot write it ({e.strerror})")
        if not existed:
            os.remove(real)
    for where, source in read:
        if stages and os.path.realpath(stages) == where:
            fail(prog, f"--stages '{stages}' is the {source} folder; its pictures would be "
                       'read as frames')


def calibration_problem(calibration, source):
    """Why `calibration` cannot be used with --source `source`, or None."""
    if calibration == 'topic' and topic_of(source) is None and not is_bag(source):
        return (f"--calibration topic reads the camera_info beside a ROS image topic, live or "
                f"in a bag, and --source '{source}' is neither: give --source ros:TOPIC (e.g. "
                'ros:/camera/rgb/image_raw) or a .bag, or --calibration lecture, none or a FILE')
    return None


def check_arguments(prog, args):
    """Everything about the arguments that can be checked before anything is opened."""
    topic = topic_of(args.source)
    if topic is not None and topic_problem(topic):
        fail(prog, topic_problem(topic))
    problem = calibration_problem(args.calibration, args.source)
    if problem:
        fail(prog, problem)
    if args.stages:  # a folder that exists, or one to make in a folder that does
        if os.path.exists(args.stages) and not os.path.isdir(args.stages):
            fail(prog, f"--stages '{args.stages}': not a folder")
        problem = output_problem(os.path.join(args.stages, 'x') if os.path.isdir(args.stages)
                                 else args.stages)
        if problem:
            fail(prog, f"--stages '{args.stages}': {problem}")
    if args.bag_images and not args.bag:
        fail(prog, '--bag-images needs --bag FILE')
    outputs = [(path, what) for path, what in ((args.decisions, '--decisions'),
                                                (args.video, '--video'), (args.bag, '--bag'))
               if path]
    for path, what in outputs:
        check_output(prog, path, what)
    inputs = [(args.source, '--source'), (args.calibration, '--calibration'),
              (args.mounting, '--mounting'), (args.lane, '--lane')]
    check_outputs_apart(prog, inputs, outputs, args.force, args.stages)
    if args.show:
        if not os.environ.get('DISPLAY') and not os.environ.get('WAYLAND_DISPLAY'):
            fail(prog, '--show needs a display (DISPLAY is not set); use --video FILE instead')
        try:
            cv2.namedWindow('kobuki_lane')
        except cv2.error:
            fail(prog, '--show needs an OpenCV build with GUI support (pip install '
                       'opencv-python instead of opencv-python-headless); use --video FILE')
