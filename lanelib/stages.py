"""The lecture's stage functions, each as the slides have it (slide times in the comments).

kobuki_lane.detect() calls them in the slides' order; lanelib/fast.py calls the same ones on
less of the frame. Every departure from the slides is marked `# fixed:` with the reason.
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np


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
    """The lecture's triangle (21:44): bottom corners and the image centre, for any size."""
    return np.array([[(0, height), (width / 2, height / 2), (width, height)]], np.int32)


def region_of_interest(img, vertices):
    """Keep only the pixels of img inside the polygon(s) `vertices` (19:16 to 20:44)."""
    mask = np.zeros_like(img)
    cv2.fillPoly(mask, vertices, 255)
    return cv2.bitwise_and(img, mask)


def hough_lines(edges, p):
    """HoughLinesP with the lecture's arguments (21:44, 22:22): an (N, 4) int array, never
    None."""
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
    """theta and value exactly as the lecture's loop computes them (22:22 to 23:14)."""
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
    pictures need the whole of it); stages: intermediate images, only when asked for;
    The improved controller reads colours instead of segments and adds: pieces, the pieces of
    tape it found (lanelib/colour.py); masks, its colour masks and the row they start at;
    cluttered, more pieces than it reads (it keeps the longest); pitch [deg], how much further
    down than its mounting it took the camera to look when it put the pieces on the floor.
    """

    def __init__(self, lines, slopes, image=None, stages=None, make_image=None,
                 cluttered=False):
        self.lines, self.slopes, self.stages = lines, slopes, stages
        self.cluttered = cluttered
        self.pieces, self.masks, self.pitch = [], ({}, 0), 0.0
        self._image, self._make_image = image, make_image

    @property
    def image(self):
        if self._image is None and self._make_image is not None:
            self._image, self._make_image = self._make_image(), None
        return self._image

    def set_image(self, image, make_image=None):
        self._image, self._make_image = image, make_image
