#!/usr/bin/env python3
"""Lane following for a Kobuki, as in IISc "Advanced IoT Applications", Lecture 14.

Each frame: undistort with the lecture's camera (calibration_camera), gray, GaussianBlur 5x5,
Canny 85/85, mask to the region_of_interest triangle (0,h) (w/2,h/2) (w,h) (algorithm 1.1),
HoughLinesP, then theta = sum of atan2 over every segment. theta > 6: turn left,
theta < -6: turn right, else straight; a geometry_msgs/Twist ("thrust") goes to
/mobile_base/commands/velocity at 4 Hz. Where the lecture's code had defects this node fixes
them (see README): no segments, or |theta| == 6 exactly, stops the robot (decision "none"),
and every way of ending the run publishes a zero Twist first.

usage:
    python kobuki_lane.py                              the robot: camera 0, beside
                                                       roslaunch kobuki_node minimal.launch
    python kobuki_lane.py --source samples/track --dry-run --decisions d.jsonl --video d.avi
    python kobuki_lane.py --source run.bag --image-topic /camera/rgb/image_raw --dry-run \
        --bag commands.bag --stages stages/
    roslaunch kobuki_lane kobuki_lane.launch           the same node with launch parameters

default values: the lecture's numbers (--help lists each with its unit). Each setting can come
from a flag, a private ROS parameter (_threshold:=8 or <param> in a launch file), or the
default, in that order of precedence.

safety: a watchdog publishes a stop whenever --watchdog seconds pass without a command; a lost
camera is stopped for at once and reopened for --camera-retry seconds; a frame the pipeline
fails on is answered with a stop; while the ROS master is gone the robot is held stopped.

exit status: 0 input ended or the node was shut down, 1 camera lost or repeated pipeline
errors, 2 bad arguments, an unopenable source, no frame at all, or no ROS master, 130 Ctrl-C,
143 SIGTERM.
"""

import argparse
import json
import math
import os
import signal
import socket
import sys
import threading
import time
import xmlrpc.client
from dataclasses import dataclass

import cv2
import numpy as np

from calibration import CalibrationError, load_calibration, undistortion_maps
from frames import Prefetch, SourceError, open_source
from settings import add_arguments, finite, output_problem, positive, resolve, setting

TOPIC = '/mobile_base/commands/velocity'  # kobuki_node's velocity command input


@dataclass
class LaneParams:
    """Every number the node uses, with its unit and its place in the lecture."""

    algorithm: str = setting('1.1', "'1.1' masks the Canny edges with the ROI triangle "
                             "before Hough; '1.0' does not (the lecture's first demo)",
                             choices=('1.0', '1.1'))
    blur_kernel: int = setting(5, 'GaussianBlur kernel size, odd (lecture: (5, 5), sigma 0)',
                               'px', lambda k: k > 0 and k % 2 == 1)
    canny_low: float = setting(85.0, 'Canny lower hysteresis threshold (lecture: 85)', '',
                               finite)
    canny_high: float = setting(85.0, 'Canny upper hysteresis threshold (lecture: 85)', '',
                                finite)
    hough_rho: float = setting(6.0, 'HoughLinesP distance resolution (lecture: rho=6)', 'px',
                               positive)
    hough_theta: float = setting(math.pi / 60, 'HoughLinesP angle resolution '
                                 '(lecture: theta=pi/60)', 'rad', positive)
    hough_threshold: int = setting(160, 'HoughLinesP accumulator votes (lecture: 160)', 'votes',
                                   positive)
    min_line_length: float = setting(40.0, 'HoughLinesP minLineLength (lecture: 40)', 'px',
                                     finite)
    max_line_gap: float = setting(25.0, 'HoughLinesP maxLineGap (lecture: 25)', 'px', finite)
    slope_min: float = setting(0.5, 'segments with |slope| below this join neither slope group '
                               '(lecture: 0.5)', '', finite)
    threshold: float = setting(6.0, 'theta above +threshold turns left, below -threshold right '
                               '(lecture: threshold = 6)', 'rad, summed', finite)
    turn_linear: float = setting(0.01, 'forward speed while turning (lecture: 0.01)', 'm/s',
                                 finite)
    turn_angular: float = setting(0.06, 'turn rate; left +, right - (lecture: 0.06)', 'rad/s',
                                  finite)
    straight_linear: float = setting(0.05, 'forward speed going straight (lecture: 0.05)', 'm/s',
                                     finite)
    rate: float = setting(4.0, 'loop and publish rate (lecture: rospy.Rate(4))', 'Hz', positive)


# ---------------------------------------------------------------- the lecture's stages

def as_bgr(frame):
    """Any frame (gray, 1/3/4 channels, 8/16-bit or float) as 8-bit BGR."""
    if frame.dtype == np.uint16:
        frame = (frame >> 8).astype(np.uint8)
    elif frame.dtype != np.uint8:
        f = np.nan_to_num(frame.astype(np.float64))
        scale = 255.0 if f.size and f.max() <= 1.0 else 1.0
        frame = np.clip(f * scale, 0, 255).astype(np.uint8)
    if frame.ndim == 2 or frame.shape[2] == 1:
        return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    if frame.shape[2] == 4:
        return cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
    return frame


def region_of_interest_vertices(width, height):
    """The lecture's triangle: bottom corners and the image centre, for any frame size."""
    return np.array([[(0, height), (width / 2, height / 2), (width, height)]], np.int32)


def region_of_interest(img, vertices):
    """Keep only the pixels of img inside the polygon(s) `vertices`."""
    mask = np.zeros_like(img)
    cv2.fillPoly(mask, vertices, 255)
    return cv2.bitwise_and(img, mask)


def hough_lines(edges, p):
    """HoughLinesP with the lecture's arguments, as an (N, 4) int array (never None)."""
    lines = cv2.HoughLinesP(edges, rho=p.hough_rho, theta=p.hough_theta,
                            threshold=int(p.hough_threshold), lines=np.array([]),
                            minLineLength=p.min_line_length, maxLineGap=p.max_line_gap)
    # fixed: the lecture tests `lines != None`, which raises on an array; None means none found
    if lines is None:
        return np.empty((0, 4), np.int32)
    return lines.reshape(-1, 4)


@dataclass
class SlopeSum:
    """What the lecture computes from the segments."""

    theta: float = 0.0  # sum of atan2(y2 - y1, x2 - x1) over all segments [rad]
    value: float = 0.0  # left_slope / lc + right_slope / rc, logged only
    left_slope: float = 0.0
    left_count: int = 0
    right_slope: float = 0.0
    right_count: int = 0
    vertical: int = 0  # segments with x1 == x2


def slope_sum(lines, slope_min=0.5):
    """theta and value exactly as the lecture's loop computes them."""
    s = SlopeSum()
    for x1, y1, x2, y2 in np.asarray(lines).reshape(-1, 4).tolist():
        s.theta += math.atan2(y2 - y1, x2 - x1)
        # fixed: the lecture divides by zero here. A vertical segment's slope sign depends only
        # on endpoint order, so it counts in theta but joins neither slope group.
        if x2 == x1:
            s.vertical += 1
            continue
        slope = (y2 - y1) / (x2 - x1)
        if math.fabs(slope) < slope_min:
            continue
        if slope <= 0:
            s.left_slope += slope
            s.left_count += 1
        else:
            s.right_slope += slope
            s.right_count += 1
    # the lecture's counters start at 1 and drop back by one if they moved: max(count, 1)
    s.value = s.left_slope / max(s.left_count, 1) + s.right_slope / max(s.right_count, 1)
    return s


class Detection:
    """One frame through the pipeline.

    lines: (N, 4) segments x1, y1, x2, y2 in the undistorted image [px]; slopes: SlopeSum;
    image: the undistorted BGR frame the segments belong to (made on first use, since only
    pictures need the whole of it); stages: intermediate images, only when asked for.
    """

    def __init__(self, lines, slopes, image=None, stages=None, make_image=None,
                 cluttered=False):
        self.lines, self.slopes, self.stages = lines, slopes, stages
        self.cluttered = cluttered  # too many edges to read; Hough was skipped
        self._image, self._make_image = image, make_image

    @property
    def image(self):
        if self._image is None and self._make_image is not None:
            self._image, self._make_image = self._make_image(), None
        return self._image


class Layout:
    """What stays the same from frame to frame for one frame size, camera and mask: the
    undistortion maps (cv2.undistort rebuilds them on every call), the mask, the part of the
    frame it reaches and the buffers."""

    STRIPS = 8  # the band is undistorted in this many strips, each only as wide as the mask
    # needs there (bench.py: more strips cost more in calls than they save in pixels)

    def __init__(self, width, height, camera, roi, p):
        self.key = (width, height, p.algorithm, p.blur_kernel)
        self.camera, self.roi = camera, roi
        self.maps = None
        if camera is not None:
            self.maps = undistortion_maps(camera, width, height)
        if roi is not None:
            self.mask = roi
        elif p.algorithm == '1.1':  # the lecture's function applied to an all-kept image
            self.mask = region_of_interest(np.full((height, width), 255, np.uint8),
                                           region_of_interest_vertices(width, height))
        else:
            self.mask = None
        rows = (np.flatnonzero(self.mask.any(axis=1)) if self.mask is not None
                else np.arange(height))
        self.top, self.bottom = (int(rows[0]), int(rows[-1]) + 1) if rows.size else (0, 0)
        self.area = cv2.countNonZero(self.mask) if self.mask is not None else width * height
        # an edge pixel depends on the blurred pixels 2 px away (Sobel, then non-maximum
        # suppression) and those on the gray ones blur_kernel // 2 px away
        self.margin = p.blur_kernel // 2 + 3
        self.first = max(self.top - self.margin, 0)
        self.last = min(self.bottom + self.margin, height)
        if self.mask is None:  # algorithm 1.0: every pixel, in one piece
            self.strips = [(0, height, 0, width)] if height and width else []
            self.pieces = [((0, height, 0, width),) * 3] if height and width else []
        else:
            self.strips = self._strips(width, height)
            self.pieces = self._pieces(width, height)
        # remap is about a third faster on 4 channels than on 3, and each channel comes out the
        # same, so the strips are undistorted from a BGRA copy of the part of the frame they
        # read (bench.py: 0.26 against 0.36 ms, the copy included)
        self.band = self.source = self.bgra = None
        if self.maps is not None:
            self.band = np.zeros((self.last - self.first, width, 4), np.uint8)
            self.source = self._source(width, height)
            self.bgra = np.zeros((height, width, 4), np.uint8)
        self.edges = np.zeros((height, width), np.uint8)  # Hough's input; zero off the band

    def _strips(self, width, height):
        """(first row, last row, first column, last column) of each strip of the band."""
        bounds = np.linspace(self.first, self.last, self.STRIPS + 1).astype(int)
        strips = []
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            near = self.mask[max(a - self.margin, 0):min(b + self.margin, height)]
            cols = np.flatnonzero(near.any(axis=0))
            if b > a and cols.size:
                strips.append((int(a), int(b), max(int(cols[0]) - self.margin, 0),
                               min(int(cols[-1]) + 1 + self.margin, width)))
        return strips

    def _source(self, width, height):
        """Rows and columns of the frame the strips' bilinear interpolation reads."""
        m1 = self.maps[0]
        xy = [m1[a:b, x0:x1].reshape(-1, 2) for a, b, x0, x1 in self.strips]
        if not xy:
            return 0, 0, 0, 0
        xy = np.concatenate(xy)
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0) + 2  # the pixel and the next
        return (int(np.clip(y0, 0, height)), int(np.clip(y1, 0, height)),
                int(np.clip(x0, 0, width)), int(np.clip(x1, 0, width)))

    def _pieces(self, width, height):
        """The band's rows split in two where that leaves the fewest pixels to gray, blur and
        edge (for the triangle, where it is half as wide as at the bottom). Per piece: rows a:b
        and columns c0:c1 the mask reaches; the rectangle grayed and blurred (the margin round
        it); the rectangle edged (3 px round it: an edge depends on the blurred pixels 2 px
        away). Each rectangle is its own image to OpenCV, so its border only touches pixels
        outside the part that is kept. bench.py: the split saves about 4 % of the frame's time,
        a third piece nothing more."""
        m = self.margin
        kept = self.mask.any(axis=1)
        lo = np.where(kept, (self.mask != 0).argmax(axis=1), width)  # first and last column
        hi = np.where(kept, width - (self.mask[:, ::-1] != 0).argmax(axis=1), 0)  # kept + 1

        def piece(a, b):
            c0, c1 = int(lo[a:b].min(initial=width)), int(hi[a:b].max(initial=0))
            if c1 <= c0:
                return None
            gray = (max(a - m, 0), min(b + m, height), max(c0 - m, 0), min(c1 + m, width))
            edge = (max(a - 3, gray[0]), min(b + 3, gray[1]), max(c0 - 3, gray[2]),
                    min(c1 + 3, gray[3]))
            return (a, b, c0, c1), gray, edge

        def area(pieces):
            return sum((g1 - g0) * (gc1 - gc0) for _, (g0, g1, gc0, gc1), _ in pieces)

        best = [q for q in [piece(self.top, self.bottom)] if q]
        for at in range(self.top + 1, self.bottom):
            two = [q for q in (piece(self.top, at), piece(at, self.bottom)) if q]
            if area(two) < area(best):
                best = two
        return best

    def matches(self, width, height, camera, roi, p):
        return (self.key == (width, height, p.algorithm, p.blur_kernel)
                and self.camera is camera and self.roi is roi)

    def undistort(self, raw):
        """The whole undistorted frame."""
        if self.maps is None:
            return raw
        return cv2.remap(raw, *self.maps, cv2.INTER_LINEAR)

    def undistort_band(self, raw):
        """Rows first:last of the undistorted frame, as BGRA, right wherever the mask's edges
        can depend on them (elsewhere whatever an earlier frame left)."""
        if self.maps is None:
            return raw[self.first:self.last]
        m1, m2 = self.maps
        y0, y1, x0, x1 = self.source
        cv2.cvtColor(raw[y0:y1, x0:x1], cv2.COLOR_BGR2BGRA, dst=self.bgra[y0:y1, x0:x1])
        for a, b, x0, x1 in self.strips:
            cv2.remap(self.bgra, m1[a:b, x0:x1], m2[a:b, x0:x1], cv2.INTER_LINEAR,
                      dst=self.band[a - self.first:b - self.first, x0:x1])
        return self.band


class Pipeline:
    """calibrate -> gray -> blur -> Canny -> ROI -> Hough -> slope sum, doing only the work
    that can change a segment.

    The segments are identical, frame by frame, to the lecture's literal calls (whole frame,
    cv2.undistort each time; tests/test_pipeline.py holds the line): the undistortion maps are
    made once; only the part of the frame near the mask is undistorted (from a BGRA copy:
    remap is faster on 4 channels), and gray, blur and Canny run on two rectangles that hold
    the mask's rows plus the few pixels their edges depend on (Layout._pieces). Hough still
    gets a full-size image, zero off the mask, so its accumulator is the one the lecture's
    call builds. Canny's hysteresis can link weak edges from far away
    unless canny_low == canny_high (the lecture's 85, 85); otherwise, and when the stages are
    kept for pictures, the whole frame is processed.
    """

    def __init__(self, p, mark=None, max_edge_fraction=None):
        self.p = p
        self.mark = mark or (lambda stage: None)  # called after each stage (bench.py times them)
        # None (the lecture): Hough always runs. A fraction: masks with more edge pixels than
        # that are not read, which bounds Hough's time on dense texture (improved controller)
        self.max_edge_fraction = max_edge_fraction
        self._layout = None

    def layout(self, width, height, camera, roi):
        if self._layout is None or not self._layout.matches(width, height, camera, roi, self.p):
            self._layout = Layout(width, height, camera, roi, self.p)
        return self._layout

    def __call__(self, frame, camera, keep_stages=False, roi=None):
        p, mark = self.p, self.mark
        mark('start')
        raw = as_bgr(frame)
        height, width = raw.shape[:2]
        lay = self.layout(width, height, camera, roi)
        whole = keep_stages or p.canny_low != p.canny_high or lay.top == lay.bottom
        image = lay.undistort(raw) if whole else lay.undistort_band(raw)
        mark('undistort')
        if whole:
            # fixed: the lecture takes gray from the raw frame, so undistortion had no effect
            gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            mark('gray')
            blurred = cv2.GaussianBlur(gray, (p.blur_kernel, p.blur_kernel), 0)
            mark('blur')
            edged = cv2.Canny(blurred, p.canny_low, p.canny_high)
            mark('canny')
            masked = edged if lay.mask is None else cv2.bitwise_and(edged, lay.mask)
            mark('roi')
        else:
            masked = self.band_edges(image, lay)
        cluttered = (self.max_edge_fraction is not None and
                     cv2.countNonZero(masked) > self.max_edge_fraction * lay.area)
        lines = np.empty((0, 4), np.int32) if cluttered else hough_lines(masked, p)
        mark('hough')
        slopes = slope_sum(lines, p.slope_min)
        mark('slopes')
        if keep_stages:
            roi_mask = lay.mask if lay.mask is not None else np.full_like(edged, 255)
            stages = dict(raw=raw, undistorted=image, gray=gray, blurred=blurred, edges=edged,
                          roi=roi_mask, masked=masked)
            return Detection(lines, slopes, image, stages, cluttered=cluttered)
        if whole:
            return Detection(lines, slopes, image, cluttered=cluttered)
        return Detection(lines, slopes, make_image=lambda: lay.undistort(raw),
                         cluttered=cluttered)

    def band_edges(self, band, lay):
        """The same stages piece by piece (Layout._pieces) on rows lay.first:lay.last:
        Hough's full-size input, the mask's edges and zero elsewhere."""
        p, mark, first = self.p, self.mark, lay.first
        to_gray = cv2.COLOR_BGRA2GRAY if band.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        grays = [cv2.cvtColor(band[g0 - first:g1 - first, gc0:gc1], to_gray)
                 for _, (g0, g1, gc0, gc1), _ in lay.pieces]
        mark('gray')
        blurred = [cv2.GaussianBlur(gray, (p.blur_kernel, p.blur_kernel), 0) for gray in grays]
        mark('blur')
        edged = [cv2.Canny(b[e0 - g0:e1 - g0, ec0 - gc0:ec1 - gc0], p.canny_low, p.canny_high)
                 for b, (_, (g0, _, gc0, _), (e0, e1, ec0, ec1)) in zip(blurred, lay.pieces,
                                                                        strict=True)]
        mark('canny')
        if lay.mask is None:
            mark('roi')
            return edged[0]
        for e, ((a, b, c0, c1), _, (e0, _, ec0, _)) in zip(edged, lay.pieces, strict=True):
            cv2.bitwise_and(e[a - e0:b - e0, c0 - ec0:c1 - ec0], lay.mask[a:b, c0:c1],
                            dst=lay.edges[a:b, c0:c1])
        mark('roi')
        return lay.edges


def detect(frame, camera, p, keep_stages=False, roi=None):
    """One frame through a fresh Pipeline (the loop keeps one Pipeline for all frames).

    roi: a mask image (uint8, 255 = keep) to use instead of the algorithm's triangle.
    """
    return Pipeline(p)(frame, camera, keep_stages, roi)


@dataclass(frozen=True)
class Command:
    decision: str  # left | right | straight | none
    linear_x: float  # [m/s]
    angular_z: float  # [rad/s]


STOP = Command('none', 0.0, 0.0)


class LectureRule:
    """The lecture's bang-bang rule on theta, with its silent cases made explicit."""

    name = 'lecture'

    def __init__(self, p):
        self.p = p
        self.pipeline = Pipeline(p)

    def perceive(self, frame, camera, keep_stages=False):
        return self.pipeline(frame, camera, keep_stages)

    def extra(self):
        return {}

    def __call__(self, detection):
        p, theta = self.p, detection.slopes.theta
        # fixed: with no segments the lecture published nothing; stop instead
        if len(detection.lines) == 0:
            return STOP
        if theta > p.threshold:
            return Command('left', p.turn_linear, p.turn_angular)
        if theta < -p.threshold:
            return Command('right', p.turn_linear, -p.turn_angular)
        if abs(theta) < p.threshold:
            return Command('straight', p.straight_linear, 0.0)
        # fixed: |theta| == threshold matched no branch in the lecture; stop instead
        return STOP


STAGE_TITLES = (('raw', 'raw frame'), ('undistorted', '1 calibration_camera: undistorted'),
                ('gray', '2 cvtColor: gray'), ('blurred', '3 GaussianBlur 5x5'),
                ('edges', '4 Canny 85, 85'), ('roi', '5 region_of_interest: the triangle'),
                ('masked', '6 edges inside the triangle'))


def stage_pictures(detection, command, p):
    """(title, BGR image) for every stage of a detection made with keep_stages=True, ending
    with the Hough segments, theta, value and the decision."""
    pictures = [(title, as_bgr(detection.stages[key])) for key, title in STAGE_TITLES]
    pictures.append(('7 HoughLinesP, theta, decision', annotate(detection, command, p)))
    return pictures


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


def write_stages(folder, index, detection, command, p):
    """NNNN_K_stage.png for each stage of frame NNNN, and NNNN_sheet.png with all of them."""
    pictures = stage_pictures(detection, command, p)
    keys = [key for key, _ in STAGE_TITLES] + ['hough']
    for k, ((_, image), key) in enumerate(zip(pictures, keys, strict=True)):
        cv2.imwrite(os.path.join(folder, f'{index:04d}_{k}_{key}.png'), image)
    cv2.imwrite(os.path.join(folder, f'{index:04d}_sheet.png'), contact_sheet(pictures))


def annotate(detection, command, p):
    """The lecture's green segments on the undistorted frame, plus what was decided."""
    image = detection.image.copy()
    h, w = image.shape[:2]
    if p.algorithm == '1.1':
        cv2.polylines(image, region_of_interest_vertices(w, h), True, (0, 200, 255), 1)
    for x1, y1, x2, y2 in detection.lines.tolist():
        cv2.line(image, (x1, y1), (x2, y2), (0, 255, 0), 2)
    s = detection.slopes
    text = (f'{command.decision}  theta {s.theta:+.2f}  value {s.value:+.3f}  '
            f'{len(detection.lines)} lines  v {command.linear_x:.2f} w {command.angular_z:+.2f}')
    scale = max(0.3, w / 1400)
    band = int(28 * scale / 0.45)
    cv2.rectangle(image, (0, 0), (w, band), (0, 0, 0), -1)
    cv2.putText(image, text, (5, int(band * 0.7)), cv2.FONT_HERSHEY_SIMPLEX, scale,
                (255, 255, 255), 1, cv2.LINE_AA)
    return image


# ---------------------------------------------------------------- the node's loop

def make_twist(twist_type, command):
    thrust = twist_type()
    thrust.linear.x = float(command.linear_x)
    thrust.angular.z = float(command.angular_z)
    return thrust


class VideoSink:
    """Annotated frames to a video file, at the loop rate; opened on the first frame."""

    def __init__(self, path, fps):
        self.path, self.fps = path, fps
        self._writer, self._size = None, None

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

    def close(self):
        if self._writer is not None:
            self._writer.release()


class Progress:
    """A one-line progress display on stderr, redrawn at most twice a second."""

    def __init__(self, total, enabled, stream=sys.stderr):
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
        self.stream.write(f'\rframe {frames}{of}  {fps:.1f} frames/s ')
        self.stream.flush()

    def done(self):
        if self.enabled:
            self.update(self.frames, final=True)
            self.stream.write('\n')


def below_kobuki_timeout(x):
    return math.isfinite(x) and 0 < x <= 0.5


@dataclass
class Safety:
    """How the loop protects the robot. Not the lecture's (it had none), so not in LaneParams."""

    watchdog: float = setting(0.4, 'no command for this long (a slow frame or camera): publish '
                              'a stop, and again as long as it lasts; a frame that took longer '
                              'to process is acted on with a stop. At most 0.5, below the '
                              "Kobuki driver's 0.6 s command timeout", 's', below_kobuki_timeout)
    watchdog_check: float = setting(0.1, 'how often the watchdog looks', 's',
                                    below_kobuki_timeout)
    camera_retry: float = setting(5.0, 'a live camera that stops giving frames is reopened for '
                                  'this long before the run ends (exit status 1)', 's', finite)
    max_errors: int = setting(5, 'this many frames in a row failing in the pipeline end the run '
                              '(exit status 1)', 'frames', positive)


KOBUKI_MAX_LINEAR = 0.7  # [m/s] the Kobuki's top speed
KOBUKI_MAX_ANGULAR = math.pi  # [rad/s] the Kobuki's top turn rate


def safe(command):
    """The command within the Kobuki's limits; anything not finite becomes a stop."""
    if not (math.isfinite(command.linear_x) and math.isfinite(command.angular_z)):
        return STOP
    return Command(command.decision,
                   min(max(command.linear_x, -KOBUKI_MAX_LINEAR), KOBUKI_MAX_LINEAR),
                   min(max(command.angular_z, -KOBUKI_MAX_ANGULAR), KOBUKI_MAX_ANGULAR))


class LaneFollower:
    """Owns the publisher, the rate and the frame source; one command per loop iteration.

    `ros` is the rospy module or a rospy_standin.StandInRospy; `twist_type` the matching Twist.
    """

    def __init__(self, ros, twist_type, source, params, camera, controller=None,
                 decisions=None, video=None, show=False, progress=None, wait_for_base=0.0,
                 safety=None, bag=None, debug=None, stages=None):
        self.ros, self.twist_type, self.source = ros, twist_type, source
        self.p, self.camera = params, camera
        self.controller = controller or LectureRule(params)
        self.decisions, self.video, self.show = decisions, video, show
        self.progress = progress or Progress(None, False)
        self.wait_for_base = wait_for_base
        self.safety = safety or Safety()
        self.stages = stages  # a folder: every stage of every frame as pictures
        self.bag = bag  # bags.BagRecorder: every command sent, and frames if it wants them
        # (publisher, message maker): annotated frames, built only while someone subscribes
        self.debug, self.debug_message = debug or (None, None)
        self.counts = dict(left=0, right=0, straight=0, none=0)
        self.frames = 0
        self.errors = 0  # pipeline failures in a row
        self.failed = 0  # frames the pipeline failed on, in all
        self.watchdog_stops = 0
        self.ended = None  # why the loop ended
        self.stop_requested = None
        self.hold = None  # while set (e.g. 'ROS master lost'), every command is a stop
        self._lock = threading.Lock()
        self._stopped = False
        self._last_sent = None  # ros time of the last command published
        self._stalled = False
        self._pub = ros.Publisher(TOPIC, twist_type, queue_size=1)
        ros.on_shutdown(self.stop_robot)

    def request_stop(self, reason):
        """Ask the loop to end after this iteration (signal handlers call this)."""
        if self.stop_requested is None:
            self.stop_requested = reason

    def _send(self, command):
        """Publish (and record in the bag, if any); the caller holds the lock."""
        self._pub.publish(make_twist(self.twist_type, command))
        if self.bag is not None:
            self.bag.twist(self.ros.get_time(), command.linear_x, command.angular_z)

    def hold_stopped(self, reason):
        """Stop the robot now and answer every frame with a stop until resume()."""
        self.hold = reason
        self._publish(STOP)

    def resume(self):
        self.hold = None

    def _publish(self, command):
        with self._lock:
            if self._stopped:
                return  # never move again once the stop has been sent
            self._send(safe(command))
            self._last_sent = self.ros.get_time()

    def _watchdog(self, _event):
        """Runs on a timer: a stop whenever the loop has not published for too long."""
        now = self.ros.get_time()
        with self._lock:
            if self._stopped or self._last_sent is None:
                return
            if now - self._last_sent < self.safety.watchdog:
                self._stalled = False
                return
            self._send(STOP)
            self._last_sent = now
            self.watchdog_stops += 1
            first = not self._stalled
            self._stalled = True
        if first:
            self.ros.logwarn('no command for %.1f s (slow frame or camera): robot stopped',
                             self.safety.watchdog)

    def stop_robot(self):
        """Publish a zero Twist once; later commands are refused. Safe from any thread."""
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
            try:
                self._send(STOP)
            except self.ros.ROSException as e:  # topic already closed by a ROS shutdown
                self.ros.logwarn('could not publish the final stop: %s', e)

    def step(self, frame, label, read_at=None):
        """Process one frame and publish its command; returns the decision record.

        read_at: ros time the frame arrived; a result ready more than watchdog seconds later
        is stale, and the robot is stopped instead."""
        read_at = self.ros.get_time() if read_at is None else read_at
        if self.stages:
            detection = self.controller.perceive(frame, self.camera, keep_stages=True)
        else:
            detection = self.controller.perceive(frame, self.camera)
        command = self.controller(detection)
        late = self.ros.get_time() - read_at > self.safety.watchdog
        held = self.hold
        if late or held:
            command = STOP
        self._publish(command)
        s = detection.slopes
        record = dict(frame=self.frames, source=label, lines=int(len(detection.lines)),
                      theta=round(s.theta, 6), value=round(s.value, 6),
                      decision=command.decision, linear_x=command.linear_x,
                      angular_z=command.angular_z, t=round(self.ros.get_time(), 6),
                      left_count=s.left_count, right_count=s.right_count, vertical=s.vertical,
                      **self.controller.extra())
        if late:
            record['late'] = True
        if held:
            record['held'] = held
        self.counts[command.decision] += 1
        self.frames += 1
        self.ros.loginfo('frame %d (%s): %d lines, theta %+.3f, value %+.3f -> %s '
                         '(linear.x %.2f, angular.z %+.2f)%s', record['frame'], label,
                         record['lines'], s.theta, s.value, command.decision,
                         command.linear_x, command.angular_z,
                         ' [late: stopped]' if late else f' [{held}: stopped]' if held else '')
        self._write(record)
        if self.stages:
            write_stages(self.stages, record['frame'], detection, command, self.p)
        sinks = self._picture_sinks()
        if sinks:  # the annotated picture is drawn only when something takes it
            image = annotate(detection, command, self.p)
            for sink in sinks:
                sink(image)
        self.progress.update(self.frames)
        return record

    def _write(self, record):
        if self.decisions is not None:
            self.decisions.write(json.dumps(record) + '\n')
            self.decisions.flush()

    def _failed(self, label, error):
        """A frame the pipeline could not process: log it, stop the robot, go on."""
        self.errors += 1
        self.failed += 1
        self._publish(STOP)
        self.ros.logerr('frame %d (%s): %s: %s; robot stopped (%d in a row)', self.frames, label,
                        type(error).__name__, error, self.errors)
        self._write(dict(frame=self.frames, source=label, decision='none',
                         error=f'{type(error).__name__}: {error}',
                         t=round(self.ros.get_time(), 6)))
        self.counts['none'] += 1
        self.frames += 1

    def _picture_sinks(self):
        """Where this frame's annotated picture goes: the video, the bag if it records frames,
        the debug topic while someone subscribes, the window."""
        sinks = []
        if self.video is not None:
            sinks.append(self.video.write)
        if self.bag is not None and self.bag.images:
            sinks.append(lambda image: self.bag.image(self.ros.get_time(), image))
        if self.debug is not None and self.debug.get_num_connections() > 0:
            sinks.append(lambda image: self.debug.publish(self.debug_message(image)))
        if self.show:
            sinks.append(self._show)
        return sinks

    def _show(self, image):
        cv2.imshow('kobuki_lane', image)
        if cv2.waitKey(1) & 0xFF == ord('q'):
            self.request_stop('q pressed')

    def _await_base(self):
        deadline = time.monotonic() + self.wait_for_base
        while self._pub.get_num_connections() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        if self._pub.get_num_connections() == 0 and self.wait_for_base > 0:
            self.ros.logwarn('nothing subscribes to %s yet (is minimal.launch running?); '
                             'publishing anyway', TOPIC)

    def _camera_back(self, since):
        """After a failed read from a live source: stop, then reopen it until it gives frames
        again or camera_retry seconds have passed since the first failure."""
        ros = self.ros
        self._publish(STOP)
        if ros.get_time() - since > self.safety.camera_retry:
            return False
        ros.logwarn("no frame from '%s': robot stopped; reopening it (for up to %.0f s)",
                    self.source.name, self.safety.camera_retry)
        while ros.get_time() - since <= self.safety.camera_retry:
            if self.stop_requested or ros.is_shutdown():
                return True  # the loop ends for that reason instead
            ros.sleep(1.0)
            if self.source.reopen():
                ros.loginfo("reopened '%s'", self.source.name)
                return True
        return False

    def run(self):
        """The lecture's main loop, at a steady rate, ending with the robot stopped."""
        ros = self.ros
        self._await_base()
        rate = ros.Rate(self.p.rate)
        timer = ros.Timer(ros.Duration(self.safety.watchdog_check), self._watchdog)
        lost_since = None
        try:
            while self.ended is None:
                if ros.is_shutdown():
                    self.ended = 'ROS shutdown'
                    break
                if self.stop_requested:
                    self.ended = self.stop_requested
                    break
                ok, frame, label = self.source.read()
                if not ok:
                    if not self.source.live:
                        self.ended = 'end of input'
                        break
                    lost_since = ros.get_time() if lost_since is None else lost_since
                    if not self._camera_back(lost_since):
                        self.ended = 'camera lost'
                    continue
                lost_since = None
                try:
                    self.step(frame, label, ros.get_time())
                    self.errors = 0
                except ros.ROSInterruptException:
                    raise
                except Exception as e:  # one bad frame must not leave the robot moving
                    self._failed(label, e)
                    if self.errors >= self.safety.max_errors:
                        self.ended = 'pipeline errors'
                        break
                # fixed: the lecture sleeps only in its straight branch; every branch keeps 4 Hz
                rate.sleep()
        except ros.ROSInterruptException:
            self.ended = 'ROS shutdown'
        finally:
            timer.shutdown()
            # fixed: nothing stopped the robot when the lecture's loop ended; always stop
            self.stop_robot()
            self.progress.done()
        return self.ended


# ---------------------------------------------------------------- wiring

EXIT_STATUS = {'end of input': 0, 'ROS shutdown': 0, 'q pressed': 0, 'camera lost': 1,
               'pipeline errors': 1, 'SIGINT': 130, 'SIGTERM': 143}


def split_ros_args(argv):
    """Separate rospy's name:=value arguments from ours; _name:=value are private params."""
    import yaml

    ours, private = [], {}
    for arg in argv:
        if ':=' in arg:
            name, value = arg.split(':=', 1)
            if name.startswith('_') and not name.startswith('__'):
                private[name[1:]] = yaml.safe_load(value)
        else:
            ours.append(arg)
    return ours, private


def build_parser():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    io = parser.add_argument_group('input and output')
    io.add_argument('--source', default='0',
                    help='camera index, video file, folder of images (name order), '
                         "image pattern like 'frames/%%04d.png', or URL (default: 0)")
    io.add_argument('--calibration', default='lecture',
                    help="'lecture' (the lecture's camera matrix, default), 'none', or a ROS "
                         'camera_info YAML path')
    io.add_argument('--dry-run', action='store_true',
                    help='no ROS: record the commands instead of publishing them; over files '
                         'this runs as fast as it can')
    io.add_argument('--realtime', action='store_true',
                    help='in a dry run, keep the real loop rate instead of running flat out')
    io.add_argument('--decisions', metavar='FILE',
                    help='write one JSON object per frame (JSON Lines), flushed per frame')
    io.add_argument('--video', metavar='FILE', help='write annotated frames (.avi or .mp4)')
    io.add_argument('--stages', metavar='DIR',
                    help='write every stage of every frame as pictures (raw, undistorted, gray, '
                         'blurred, Canny edges, ROI mask, masked edges, Hough segments with '
                         'theta and the decision) and one contact sheet per frame')
    io.add_argument('--bag', metavar='FILE',
                    help=f'record every command sent as geometry_msgs/Twist on {TOPIC} in a new '
                         'ROS 1 bag (complete even after Ctrl-C)')
    io.add_argument('--bag-images', action='store_true',
                    help='also record the annotated frames in the bag, as '
                         'sensor_msgs/CompressedImage on /kobuki_lane/debug_image/compressed')
    io.add_argument('--image-topic', metavar='TOPIC',
                    help='with --source run.bag: the sensor_msgs/Image or CompressedImage '
                         'topic to play (needed when the bag has more than one)')
    io.add_argument('--show', action='store_true',
                    help='show annotated frames in a window (needs a display and an OpenCV '
                         'build with GUI); q quits')
    io.add_argument('--progress', choices=('auto', 'on', 'off'), default='auto',
                    help='progress line on stderr (auto: when stderr is a terminal)')
    io.add_argument('--quiet', action='store_true', help='no per-frame log lines')
    io.add_argument('--wait-for-base', type=float, default=2.0, metavar='SECONDS',
                    help='on ROS, wait this long for a subscriber (the Kobuki base) before '
                         'the first command (default: 2)')
    io.add_argument('--controller', choices=('lecture', 'improved'), default=None,
                    help="'lecture': the lecture's rule on theta (default); 'improved': lane "
                         'offset and heading from the segments on the floor, PD steering '
                         '(lane_control.py)')
    add_arguments(parser.add_argument_group("the lecture's settings (defaults are the "
                                            "lecture's)"), LaneParams)
    from lane_control import ImprovedParams

    add_arguments(parser.add_argument_group('the improved controller (--controller improved)'),
                  ImprovedParams)
    add_arguments(parser.add_argument_group('safety'), Safety)
    return parser


def make_controller(args, params, get_param):
    """The lecture's rule, or the improved controller with its settings resolved."""
    name = args.controller or str(get_param('~controller', 'lecture'))
    if name == 'lecture':
        return LectureRule(params)
    if name != 'improved':
        raise ValueError(f"controller must be lecture or improved, not '{name}'")
    from lane_control import ImprovedController, ImprovedParams

    return ImprovedController(params, resolve(ImprovedParams, args, get_param))


def fail(message):
    """A mistake the user can fix: say what it was and exit with status 2, no traceback."""
    print(f'kobuki_lane.py: error: {message}', file=sys.stderr)
    raise SystemExit(2)


def check_output(path, what):
    """Refuse an output path whose folder is missing or read-only before the run starts."""
    problem = output_problem(path)
    if problem:
        fail(f"{what} '{path}': {problem}")


def master_online(timeout=3.0):
    """True if the ROS master at ROS_MASTER_URI answers within `timeout` seconds."""
    import rosgraph

    old = socket.getdefaulttimeout()
    socket.setdefaulttimeout(timeout)
    try:
        return rosgraph.is_master_online()
    finally:
        socket.setdefaulttimeout(old)


def connect_ros():
    """The real rospy and Twist, with the node registered (rospy reads _name:=value itself);
    exit status 2 if no master."""
    try:
        import rospy
        from geometry_msgs.msg import Twist
    except ImportError as e:
        fail(f"ROS 1 is not importable ({e}); install Debian's python3-rospy and "
             'python3-geometry-msgs, or use --dry-run')
    uri = os.environ.get('ROS_MASTER_URI', 'http://localhost:11311 (ROS_MASTER_URI unset)')
    if not master_online():
        fail(f'no ROS master answers at {uri}; start roscore (or roslaunch kobuki_node '
             'minimal.launch), or use --dry-run')
    # our own signal handlers send the stop before rospy is told to shut down
    rospy.init_node('kobuki_lane', disable_signals=True)
    return rospy, Twist


class TimeoutTransport(xmlrpc.client.Transport):
    """XML-RPC over HTTP that gives up after `timeout` seconds (a host that vanished would
    otherwise hang the caller), without touching the process-wide socket timeout rospy uses."""

    def __init__(self, timeout):
        super().__init__()
        self.timeout = timeout

    def make_connection(self, host):
        conn = super().make_connection(host)
        conn.timeout = self.timeout
        return conn


class MasterWatch:
    """Watches the ROS master from a thread. While it is gone the robot is held stopped (the
    connection to the base is peer to peer and still works); when a master answers again the
    node's publishers are registered with it again, which rospy does not do by itself, and
    driving resumes. Both are logged."""

    def __init__(self, follower, rospy, period=1.0, timeout=1.0):
        self.follower, self.rospy, self.period, self.timeout = follower, rospy, period, timeout
        self.uri = os.environ.get('ROS_MASTER_URI', 'http://localhost:11311')
        self.lost = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name='master-watch', daemon=True)

    def start(self):
        self._thread.start()
        return self

    def stop(self):
        self._stop.set()

    def _master(self):
        return xmlrpc.client.ServerProxy(self.uri, transport=TimeoutTransport(self.timeout))

    def alive(self):
        try:
            code, _, _ = self._master().getPid(self.rospy.get_name())
            return code == 1
        except Exception:  # refused, reset, timed out, a bad reply: not there
            return False

    def _register_again(self):
        from rospy.impl.registration import get_topic_manager

        master, me, api = self._master(), self.rospy.get_name(), self.rospy.get_node_uri()
        topics = get_topic_manager().get_publications()
        for topic, data_type in topics:
            master.registerPublisher(me, topic, data_type, api)
        return [topic for topic, _ in topics]

    def _watch(self):
        log = self.rospy
        while not self._stop.wait(self.period):
            alive = self.alive()
            if not alive and not self.lost:
                self.lost = True
                self.follower.hold_stopped('ROS master lost')
                log.logwarn('ROS master at %s does not answer: robot held stopped until it is '
                            'back', self.uri)
            elif alive and self.lost:
                try:
                    topics = self._register_again()
                except Exception as e:  # it went away again, or refused: try next time
                    log.logwarn('ROS master at %s is back but registering failed (%s); '
                                'still holding the robot stopped', self.uri, e)
                    continue
                self.lost = False
                self.follower.resume()
                log.logwarn('ROS master at %s is back: registered %s again; driving again',
                            self.uri, ', '.join(topics))


def debug_publisher(rospy):
    """~debug_image/compressed: the annotated frames, for rqt_image_view; the node builds them
    only while something subscribes."""
    from sensor_msgs.msg import CompressedImage

    def message(image):
        msg = CompressedImage()
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = 'camera'
        msg.format = 'jpeg'
        msg.data = cv2.imencode('.jpg', image, [cv2.IMWRITE_JPEG_QUALITY, 80])[1].tobytes()
        return msg

    return rospy.Publisher('~debug_image/compressed', CompressedImage, queue_size=1), message


def install_signal_handlers(follower):
    def handler(signum, _frame):
        name = signal.Signals(signum).name
        follower.request_stop(name)
        # a second signal of the same kind is not ignored
        signal.signal(signum, signal.SIG_DFL if signum == signal.SIGTERM
                      else signal.default_int_handler)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def check_show():
    if not os.environ.get('DISPLAY') and not os.environ.get('WAYLAND_DISPLAY'):
        fail('--show needs a display (DISPLAY is not set); use --video FILE instead')
    try:
        cv2.namedWindow('kobuki_lane')
    except cv2.error:
        fail('--show needs an OpenCV build with GUI support (pip install opencv-python '
             'instead of opencv-python-headless); use --video FILE instead')


def summary(follower, elapsed):
    c = follower.counts
    fps = follower.frames / elapsed if elapsed > 0 else 0.0
    return (f'kobuki_lane: {follower.frames} frames ({follower.source.skipped} skipped) in '
            f'{elapsed:.2f} s, {fps:.1f} frames/s: left {c["left"]}, right {c["right"]}, '
            f'straight {c["straight"]}, none {c["none"]}; ended: {follower.ended}')


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ours, private = split_ros_args(argv)
    parser = build_parser()
    args = parser.parse_args(ours)
    if args.stages and not os.path.isdir(args.stages):
        fail(f"--stages '{args.stages}': no such folder (make it first)")
    if args.stages and not os.access(args.stages, os.W_OK):
        fail(f"--stages '{args.stages}': folder is not writable")
    if args.bag_images and not args.bag:
        fail('--bag-images needs --bag FILE')
    for path, what in ((args.decisions, '--decisions'), (args.video, '--video'),
                       (args.bag, '--bag')):
        if path:
            check_output(path, what)
    if args.show:
        check_show()
    try:
        camera = load_calibration(args.calibration)
    except CalibrationError as e:
        parser.error(str(e))

    if args.dry_run:
        from rospy_standin import SimClock, StandInRospy, Twist, WallClock

        twist_type = Twist
        clock_live = args.realtime or args.source.isdigit() or '://' in args.source
        ros = StandInRospy(WallClock() if clock_live else SimClock(), params=private,
                           quiet=args.quiet, keep=100)
        ros.init_node('kobuki_lane')
    else:
        ros, twist_type = connect_ros()
    try:
        params = resolve(LaneParams, args, ros.get_param)
        safety = resolve(Safety, args, ros.get_param)
        controller = make_controller(args, params, ros.get_param)
    except (ValueError, TypeError) as e:
        parser.error(str(e))
    try:
        source = open_source(args.source, warn=ros.logwarn, image_topic=args.image_topic)
    except SourceError as e:
        fail(str(e))
    bag = None
    if args.bag:  # the one output that can still be refused: before any other is opened
        from bags import BagError, BagRecorder

        try:
            bag = BagRecorder(args.bag, TOPIC, images=args.bag_images)
        except BagError as e:
            source.release()
            fail(str(e))

    show_progress = args.progress == 'on' or (args.progress == 'auto' and sys.stderr.isatty())
    decisions = open(args.decisions, 'w', encoding='utf-8') if args.decisions else None
    video = VideoSink(args.video, params.rate) if args.video else None
    debug = None if args.dry_run else debug_publisher(ros)
    # last, so that no early exit leaves its thread inside OpenCV (that aborts the process)
    if not source.live:
        source = Prefetch(source)  # decode the next frames on the second core
    follower = LaneFollower(ros, twist_type, source, params, camera, controller=controller,
                            decisions=decisions,
                            video=video, show=args.show,
                            progress=Progress(source.total, show_progress),
                            wait_for_base=0.0 if args.dry_run else args.wait_for_base,
                            safety=safety, bag=bag, debug=debug, stages=args.stages)
    install_signal_handlers(follower)
    ros.loginfo('kobuki_lane: source %s, %s controller, algorithm %s, calibration %s, %.1f Hz '
                'on %s%s', source.name, controller.name, params.algorithm, args.calibration,
                params.rate, TOPIC,
                ' (dry run)' if args.dry_run else '')
    watch = None if args.dry_run else MasterWatch(follower, ros).start()
    start = time.monotonic()
    try:
        ended = follower.run()
    finally:
        if watch is not None:
            watch.stop()
        source.release()
        for sink in (decisions, video, bag):
            if sink is not None:
                sink.close()
        if not args.dry_run:
            time.sleep(0.3)  # let rospy's sender thread deliver the final zero Twist
            ros.signal_shutdown(follower.ended or 'exception')
    print(summary(follower, time.monotonic() - start), file=sys.stderr)
    if ended == 'camera lost':
        print(f"kobuki_lane.py: error: camera lost: no frame from '{source.name}'",
              file=sys.stderr)
    if ended == 'pipeline errors':
        print(f'kobuki_lane.py: error: {follower.errors} frames in a row failed in the '
              'pipeline (see the log above)', file=sys.stderr)
    if ended == 'end of input' and follower.frames == 0:
        fail(f"no frame could be read from '{source.name}' (corrupt, truncated or an "
             'unsupported format?)')
    read = follower.frames + source.skipped
    if ended == 'end of input' and source.total and read < source.total - 1:
        ros.logwarn('the input ended after %d of its %d frames (truncated?)',
                    read, source.total)
    return EXIT_STATUS.get(ended, 0)


if __name__ == '__main__':
    import kobuki_lane  # run as the module itself, so lane_control shares its classes

    sys.exit(kobuki_lane.main())
