"""The command lines' shared conventions: a mistake the user can fix is one line on stderr,
'PROG: error: what was wrong and what to do', and exit status 2, never a traceback."""

import os
import sys

import cv2

from lanelib.settings import output_problem


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


def check_outputs_apart(prog, source, outputs, stages, force):
    """Refuse an output that would destroy an input or another output: one that is the
    source file, lies in the source folder (it would be read as a frame), is named twice, or
    exists already (unless `force`); and a --stages folder that is the source folder."""
    where = os.path.realpath(source) if os.path.exists(source) else None
    seen = {}
    for path, what in outputs:
        real = os.path.realpath(path)
        if where and real == where:
            fail(prog, f"{what} '{path}' is the --source itself: writing it would destroy it")
        if where and os.path.isdir(where) and os.path.dirname(real) == where:
            fail(prog, f"{what} '{path}' is inside the --source folder, where it would be read "
                       'as a frame; write it elsewhere')
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
    if stages and where and os.path.realpath(stages) == where:
        fail(prog, f"--stages '{stages}' is the --source folder; its pictures would be read as "
                   'frames')


def check_arguments(prog, args):
    """Everything about the arguments that can be checked before anything is opened."""
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
    check_outputs_apart(prog, args.source, outputs, args.stages, args.force)
    if args.show:
        if not os.environ.get('DISPLAY') and not os.environ.get('WAYLAND_DISPLAY'):
            fail(prog, '--show needs a display (DISPLAY is not set); use --video FILE instead')
        try:
            cv2.namedWindow('kobuki_lane')
        except cv2.error:
            fail(prog, '--show needs an OpenCV build with GUI support (pip install '
                       'opencv-python instead of opencv-python-headless); use --video FILE')
