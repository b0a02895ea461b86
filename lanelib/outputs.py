"""What a run leaves behind: decision records, annotated pictures, stage sheets, video, progress.

The annotated picture (the lecture's green segments on the undistorted frame, plus what was
decided) is drawn only when something takes it: the video, a bag that records frames, the
debug image topic while someone subscribes, or the window.
"""

import functools
import json
import math
import os
import sys
import time

import cv2
import numpy as np

from lanelib.stages import as_bgr, region_of_interest_vertices

STAGE_TITLES = (('raw', 'raw frame'), ('undistorted', '1 calibration_camera: undistorted'),
                ('gray', '2 cvtColor: gray'), ('blurred', '3 GaussianBlur 5x5'),
                ('edges', '4 Canny 85, 85'), ('roi', '5 region_of_interest: the triangle'),
                ('masked', '6 edges inside the triangle'))


def annotate(detection, command, p):
    """The lecture's green segments on the undistorted frame, plus what was decided."""
    image = detection.image.copy()
    h, w = image.shape[:2]
    if p.algorithm == '1.1':
        cv2.polylines(image, region_of_interest_vertices(w, h), True, (0, 200, 255), 1)
    for x1, y1, x2, y2 in detection.lines.tolist():
        cv2.line(image, (x1, y1), (x2, y2), (0, 255, 0), 2)
    s = detection.slopes
    return text_band(image, f'{command.decision}  theta {s.theta:+.2f}  value {s.value:+.3f}  '
                            f'{len(detection.lines)} lines  v {command.linear_x:.2f} '
                            f'w {command.angular_z:+.2f}')


MASK_TINTS = {'white': (255, 160, 0), 'yellow': (0, 220, 255), 'red': (0, 0, 255),
              'any': (255, 0, 255)}  # BGR: how each colour mask is shown


def tint(image, masks, first=0, alpha=0.6):
    """The image with each mask's pixels (rows first.. of it) blended towards its tint."""
    out = image.copy()
    for name, mask in masks.items():
        rows = out[first:first + len(mask)]
        on = mask > 0
        rows[on] = ((1 - alpha) * rows[on] + alpha * np.array(MASK_TINTS[name])).astype(np.uint8)
    return out


def draw_curve(image, xs, ys, to_pixels, colour, thickness=2):
    """A curve of floor points (robot frame) drawn onto the undistorted image."""
    u, v, ok = to_pixels(xs, ys)
    pts = np.stack([u[ok], v[ok]], axis=1)
    if len(pts) > 1:
        cv2.polylines(image, [np.round(pts).astype(np.int32).reshape(-1, 1, 2)], False,
                      colour, thickness, cv2.LINE_AA)


def text_band(image, text):
    """A black band across the top of the image with `text` on it."""
    w = image.shape[1]
    scale = max(0.3, w / 1400)
    band = int(28 * scale / 0.45)
    cv2.rectangle(image, (0, 0), (w, band), (0, 0, 0), -1)
    cv2.putText(image, text, (5, int(band * 0.7)), cv2.FONT_HERSHEY_SIMPLEX, scale,
                (255, 255, 255), 1, cv2.LINE_AA)
    return image


def lecture_pictures(detection, command, p, draw=annotate):
    """(key, title, BGR image) for every stage of a detection made with keep_stages=True,
    ending with the Hough segments, theta, value and the decision."""
    pictures = [(key, title, as_bgr(detection.stages[key])) for key, title in STAGE_TITLES]
    pictures.append(('hough', '7 HoughLinesP, theta, decision', draw(detection, command, p)))
    return pictures


def stage_pictures(detection, command, p, draw=annotate):
    """(title, BGR image) of lecture_pictures."""
    return [(title, image) for _, title, image in lecture_pictures(detection, command, p, draw)]


def contact_sheet(pictures, width=320, columns=4):
    """The pictures side by side, each scaled to `width` with its title above it."""
    tiles = []
    for title, image in pictures:
        h, w = image.shape[:2]
        tile = cv2.resize(image, (width, max(1, round(h * width / w))),
                          interpolation=cv2.INTER_AREA)
        band = np.zeros((22, width, 3), np.uint8)
        cv2.putText(band, title, (4, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1,
                    cv2.LINE_AA)
        tiles.append(np.vstack([band, tile]))
    height = max(t.shape[0] for t in tiles)
    tiles = [cv2.copyMakeBorder(t, 0, height - t.shape[0], 0, 0, cv2.BORDER_CONSTANT)
             for t in tiles]
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % columns)
    rows = [np.hstack(tiles[i:i + columns]) for i in range(0, len(tiles), columns)]
    return np.vstack(rows)


def write_stages(folder, index, pictures):
    """NNNN_K_stage.png for each (key, title, image) of frame NNNN, and NNNN_sheet.png with
    all of them; returns (files, bytes) written. OSError when a picture could not be written
    (a full disk, the folder gone: cv2.imwrite only says False)."""
    paths = [os.path.join(folder, f'{index:04d}_{k}_{key}.png')
             for k, (key, _, _) in enumerate(pictures)]
    images = [image for _, _, image in pictures]
    paths.append(os.path.join(folder, f'{index:04d}_sheet.png'))
    images.append(contact_sheet([(title, image) for _, title, image in pictures]))
    for path, image in zip(paths, images):
        if not cv2.imwrite(path, image) or not os.path.getsize(path):
            raise OSError(f"cannot write '{path}' (is the disk full, or the folder gone?)")
    return len(paths), sum(os.path.getsize(path) for path in paths)


def finite(value):
    """A record's value with every float that is not finite (NaN, inf) made None: JSON has no
    NaN, and a reader of the records would fail on it."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def decision_record(index, label, detection, command, t, extra):
    """One line of --decisions: what the frame showed and what was decided."""
    s = detection.slopes
    return dict(frame=index, source=label, lines=int(len(detection.lines)),
                theta=round(s.theta, 6), value=round(s.value, 6), decision=command.decision,
                linear_x=command.linear_x, angular_z=command.angular_z, t=round(t, 6),
                left_count=s.left_count, right_count=s.right_count, vertical=s.vertical,
                **extra)


class VideoSink:
    """Annotated frames to a video file, at the loop rate; opened on the first frame. close()
    checks that every frame is in the file: OpenCV's writer says nothing when the disk is
    full."""

    def __init__(self, path, fps):
        self.path, self.fps = path, fps
        self._writer, self._size = None, None
        self.frames = 0

    def write(self, image):
        if self._writer is None:
            self._size = (image.shape[1], image.shape[0])
            fourcc = 'mp4v' if self.path.lower().endswith('.mp4') else 'MJPG'
            self._writer = cv2.VideoWriter(self.path, cv2.VideoWriter_fourcc(*fourcc),
                                           self.fps, self._size)
            if not self._writer.isOpened():
                raise OSError(f"cannot write video '{self.path}' (use .avi or .mp4)")
        if (image.shape[1], image.shape[0]) != self._size:
            image = cv2.resize(image, self._size)
        self._writer.write(image)
        self.frames += 1

    def close(self):
        if self._writer is None:
            return
        self._writer.release()
        self._writer = None
        capture = cv2.VideoCapture(self.path)
        readable = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if capture.isOpened() else 0
        capture.release()
        if readable < self.frames:
            raise OSError(f'only {readable} of its {self.frames} frames are in the file (is the '
                          'disk full?)')


class Progress:
    """A one-line progress display on stderr, redrawn at most twice a second."""

    def __init__(self, total=None, enabled=False, stream=sys.stderr):
        self.total, self.enabled, self.stream = total, enabled, stream
        self.start = time.monotonic()
        self.frames = 0
        self._last = 0.0

    def update(self, frames, final=False):
        now = time.monotonic()
        self.frames = frames
        if not self.enabled or (now - self._last < 0.5 and not final):
            return
        self._last = now
        of = f'/{self.total}' if self.total else ''
        fps = frames / max(now - self.start, 1e-9)
        self._write(f'\rframe {frames}{of}  {fps:.1f} frames/s ')

    def _write(self, text):
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # the terminal gone: no more progress, the run goes on
            self.enabled = False

    def done(self):
        if self.enabled:
            self.update(self.frames, final=True)
            self._write('\n')


class Outputs:
    """Where each frame's results go. p: the lecture's settings (the pictures draw its ROI).

    decisions: a text file for JSON Lines; video: a VideoSink; stages: a folder for every
    stage of every frame; bag: a bags.BagRecorder (frames, if it records them); debug:
    (publisher, message maker(image, stamp, frame_id)) for the debug image topic, showing the
    annotated picture or, by debug_stage, one stage's (a key of `pictures`: edges, masked,
    mask_white, pieces, ...); watch: what else takes each record; show: a window; draw(detection,
    command, p): what makes the annotated picture (annotate: the lecture's); pictures(detection,
    command, p): the stages' (key, title, image) (lecture_pictures).

    An output that cannot be written (a full disk, its folder removed) is said once through
    `warn`, closed and left out from then on; the others, and the run, go on. `failures` says
    which and why ({'--decisions FILE': why}), for the run's last word and its exit status."""

    def __init__(self, p, decisions=None, video=None, stages=None, bag=None, debug=None,
                 show=False, progress=None, draw=None, pictures=None, warn=None,
                 debug_stage='annotated', watch=()):
        self.p, self.decisions, self.video, self.stages = p, decisions, video, stages
        self.debug_stage = debug_stage  # what the debug image shows: a picture's key
        self.watch = list(watch)  # called with each frame's record (topics, diagnostics)
        self.stage_files = self.stage_bytes = 0  # what --stages has written
        self.bag, self.show, self.draw = bag, show, draw or annotate
        self.pictures = pictures or (lambda d, c, p: lecture_pictures(d, c, p, self.draw))
        self.debug, self.debug_message = debug or (None, None)
        self.progress = progress or Progress()
        self.failures = {}
        self._warn = warn or (lambda text: print(f'warning: {text}', file=sys.stderr))
        self._frame = None  # the frame being written, for the failures' word

    def _names(self):
        """{attribute: how the user named it} for each output there is."""
        names = {'debug': 'the debug image topic'}
        if self.decisions is not None:
            names['decisions'] = f"--decisions '{getattr(self.decisions, 'name', '')}'"
        if self.video is not None:
            names['video'] = f"--video '{self.video.path}'"
        if self.bag is not None:
            names['bag'] = f"--bag '{self.bag.path}'"
        if self.stages:
            names['stages'] = f"--stages '{self.stages}'"
        return names

    def _safely(self, sink, action):
        """Do `action` for one output; if it fails, say so, close it and leave it out."""
        if not getattr(self, sink):
            return
        try:
            action()
        except Exception as e:  # OSError, or what OpenCV and rosbags make of one
            name = self._names()[sink]
            at = f' at frame {self._frame}' if self._frame is not None else ''
            self.failures[name] = f'{_why(e)}{at}'
            self._warn(f'{name} cannot be written{at} ({_why(e)}): it is left out from now on; '
                       'the run goes on')
            self._close(sink)

    def _close(self, sink):
        """Close one output; a failure is kept in `failures` (the first one said stands)."""
        out, name = getattr(self, sink), self._names().get(sink)
        setattr(self, sink, None)
        if not out or sink in ('stages', 'debug'):
            return
        try:
            out.close()
        except Exception as e:
            self.failures.setdefault(name, f'{_why(e)} when it was closed')

    def write(self, record):
        if self.decisions is not None:
            line = json.dumps(finite(record)) + '\n'

            def write():
                self.decisions.write(line)
                self.decisions.flush()

            self._safely('decisions', write)

    def wants_stages(self):
        """Whether the next frame must keep its stages: --stages, or the debug image showing a
        stage while someone looks."""
        return bool(self.stages) or self._debug_shows_stage()

    def _debug_shows_stage(self):
        return (self.debug is not None and self.debug_stage != 'annotated' and
                self.debug.get_num_connections() > 0)

    def frame(self, record, detection, command, t, header=None):
        """A frame's record and pictures; True if the window's user pressed q. header: (stamp
        [s], frame_id) of the frame, for the debug image; default (t, 'camera')."""
        self._frame = record['frame']
        self.write(record)
        for take in self.watch:
            take(record)
        pictures = None
        if (self.stages or self._debug_shows_stage()) and detection.stages is not None:
            pictures = self.pictures(detection, command, self.p)
        if self.stages and pictures is not None:
            def stages():
                files, size = write_stages(self.stages, record['frame'], pictures)
                self.stage_files += files
                self.stage_bytes += size

            self._safely('stages', stages)
        quit_pressed = False
        sinks = self._picture_sinks(t, header or (t, 'camera'), pictures)
        if sinks or self.show:  # the annotated picture is drawn only when something takes it
            image = self.draw(detection, command, self.p)
            for sink, action in sinks:
                self._safely(sink, functools.partial(action, image))
            if self.show:
                cv2.imshow('kobuki_lane', image)
                quit_pressed = cv2.waitKey(1) & 0xFF == ord('q')
        self.progress.update(record['frame'] + 1)
        return quit_pressed

    def _picture_sinks(self, t, header, pictures):
        sinks = []
        if self.video is not None:
            sinks.append(('video', self.video.write))
        if self.bag is not None and self.bag.images:
            sinks.append(('bag', lambda image: self.bag.image(t, image)))
        if self.debug is not None and self.debug.get_num_connections() > 0:
            stage = None
            if pictures is not None:
                stage = next((image for key, _, image in pictures if key == self.debug_stage),
                             None)
                if stage is None:
                    self._warn(f"debug_image '{self.debug_stage}' is no stage of this controller "
                               f"(it has {', '.join(key for key, _, _ in pictures)}): the debug "
                               'image shows the annotated frame')
                    self.debug_stage = 'annotated'
            sinks.append(('debug', lambda image: self.debug.publish(
                self.debug_message(image if stage is None else stage, *header))))
        return sinks

    def record_twist(self, t, linear_x, angular_z):
        """A command sent, into the bag (SafeBase's record)."""
        self._safely('bag', lambda: self.bag.twist(t, linear_x, angular_z))

    def close(self):
        """Close every output, each whatever became of the others."""
        for sink in ('decisions', 'video', 'bag', 'stages'):
            self._close(sink)


def _why(error):
    """An error in a few words: the OS's own for an OSError."""
    if isinstance(error, OSError) and error.strerror:
        return error.strerror + (f": '{error.filename}'" if error.filename else '')
    return ' '.join(str(error).split()) or type(error).__name__


def summary(frames, skipped, counts, elapsed, ended):
    fps = frames / elapsed if elapsed > 0 else 0.0
    return (f'kobuki_lane: {frames} frames ({skipped} skipped) in {elapsed:.2f} s, {fps:.1f} '
            f'frames/s: left {counts["left"]}, right {counts["right"]}, straight '
            f'{counts["straight"]}, none {counts["none"]}'
            f'{", search %d" % counts["search"] if counts.get("search") else ""}; ended: {ended}')
