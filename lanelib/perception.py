"""What the improved controller sees: the floor band of each frame, undistorted, cut into colour
masks in the frame's own light, and the pieces of tape they hold, on the floor.

    FloorView   for one camera, frame size and mounting: the floor band (roi_near to roi_far
                ahead, less the border undistortion leaves empty, whose edge would look like a
                line), its rows, the undistortion maps of those rows, its edge pixels and the
                floor around each pixel (lanelib/colour.py judges brightness against it)
    perceive    one frame: a Detection holding the pieces of tape on the floor (robot frame,
                metres, the longest max_pieces of them) and the colour masks of the band

Only the band's rows are undistorted (the same maps as the whole frame's, so its pixels, masks
and pieces are the whole undistorted frame's: tests/test_pipeline.py); the whole frame is
undistorted only when a picture needs it (then its masks are the whole frame's too).
"""

import math

import cv2
import numpy as np

from lanelib.camera import LECTURE_CAMERA, undistortion_maps
from lanelib.colour import ELONGATION, Piece, colour_masks, floor_boxes, tape_pieces, view_sides
from lanelib.geometry import floor_to_row, repitched
from lanelib.stages import Detection, as_bgr, slope_sum


def floor_band(width, height, matrix, mounting, near, far, camera=None, margin=4):
    """Mask (255 = keep) of the floor `near`..`far` metres ahead, for the undistorted image
    with camera matrix `matrix`. With a calibration (`camera`), less the border undistortion
    leaves empty."""
    top = int(np.clip(math.floor(floor_to_row(far, matrix, mounting)), 0, height))
    bottom = int(np.clip(math.ceil(floor_to_row(near, matrix, mounting)), top, height))
    mask = np.zeros((height, width), np.uint8)
    mask[top:bottom] = 255
    if camera is not None:
        white = np.full((height, width), 255, np.uint8)
        filled = cv2.remap(white, *undistortion_maps(camera, width, height),
                           cv2.INTER_LINEAR) == 255
        filled = cv2.erode(filled.astype(np.uint8) * 255, np.ones((3, 3), np.uint8),
                           iterations=margin)
        mask = cv2.bitwise_and(mask, filled)
    return mask


class FloorView:
    """What stays the same for one camera, frame size and setting (module doc). camera: a
    lanelib.camera.Camera, or None (frames as they come, taken as the lecture camera's
    geometry scaled to them); p: ImprovedParams in metres."""

    def __init__(self, camera, width, height, p, source=None):
        self.key = (id(camera), width, height, source)
        self.camera = camera
        self.matrix = (camera or LECTURE_CAMERA).scaled_to(width, height).matrix
        self.mask = floor_band(width, height, self.matrix, p.mounting, p.roi_near, p.roi_far,
                               camera)
        rows = np.flatnonzero(self.mask.any(axis=1))
        self.first, self.last = (int(rows[0]), int(rows[-1]) + 1) if rows.size else (0, 0)
        # source: the size of the frames this view reads, when it is not (width, height): the
        # undistortion reads them at this size (p.column_binning), or a frame as it comes is
        # shrunk to it
        self.source = source
        self.maps = (undistortion_maps(camera, width, height, source) if camera is not None
                     else None)
        self.floor = self.mask[self.first:self.last]
        self.sides = self.surroundings = None  # no floor in view: the whole frame is read
        if self.last > self.first:
            self.sides = view_sides(self.floor)  # the band's edge: where the view cuts a tape
            self.surroundings = floor_boxes(self.floor)

    @staticmethod
    def size_for(frame, p):
        """(width, height, source) of the view that reads `frame` with settings p: the same
        camera read out at fewer pixels (p.read_width), and at fewer columns, every row kept
        (p.column_binning): read so by the undistortion itself, from `source` (the size
        shrunk to read_width; None with no binning), or with no calibration by the one resize
        that shrinks the frame (read)."""
        h, w = frame.shape[:2]
        if 0 < p.read_width < w:
            w, h = p.read_width, max(1, round(h * p.read_width / w))
        source = (w, h) if p.column_binning > 1 and w > 1 else None
        if source:
            w = max(1, round(w / p.column_binning))
        return w, h, source

    def read(self, frame):
        """The frame as this view reads it (INTER_AREA where its size changes): shrunk to the
        size the undistortion reads (`source`, or the view's own); with no calibration, to the
        view's own size, the shrinking to read_width and the binning of columns one resize."""
        size = self.source if self.maps is not None and self.source else self.mask.shape[::-1]
        if frame.shape[1::-1] == tuple(size):
            return frame
        return cv2.resize(frame, size, interpolation=cv2.INTER_AREA)

    def undistort(self, raw):
        """The whole undistorted frame of a frame as read (read)."""
        if self.maps is None:
            return raw
        return cv2.remap(raw, *self.maps, cv2.INTER_LINEAR)

    def band(self, raw):
        """The band's rows of the undistorted frame, exactly as in the whole one."""
        if self.maps is None:
            return raw[self.first:self.last]
        m1, m2 = self.maps
        return cv2.remap(raw, m1[self.first:self.last], m2[self.first:self.last],
                         cv2.INTER_LINEAR)

    def shown(self, picture):
        """A picture of the image read, as wide as the frame it was read from (binned columns
        stretched back), so that it has the camera's shape."""
        if self.source is None or picture.shape[1] == self.source[0]:
            return picture
        return cv2.resize(picture, (self.source[0], picture.shape[0]),
                          interpolation=cv2.INTER_LINEAR)


def perceive(frame, view, profile, p, piece_length, keep_stages=False, mark=None, pitch=0.0):
    """One frame's Detection (the frame as `view` reads it: FloorView.read): its pieces of
    tape (colour.Piece, robot frame) in the lane profile's colours, the longest p.max_pieces
    of them (`cluttered` when there were more), and the band's colour masks (masks, first
    row); the undistorted frame made when needed.
    mark: called with 'undistort', 'colour' and 'pieces' as each stage ends (tools/bench).
    pitch [deg]: the camera looks this much further down than p.mounting says (the
    controller's correction, pitch_tolerance): the pieces are put on the floor so, the band
    stays the one p.mounting gives."""
    mark = mark or (lambda stage: None)
    raw = as_bgr(frame)
    detection = Detection(np.empty((0, 4), np.int32), slope_sum(np.empty((0, 4))))
    detection.pitch = pitch
    mounting = p.mounting.looking_down(pitch)
    if keep_stages or view.last <= view.first:  # the whole frame (and no floor in view)
        image = view.undistort(raw)
        detection.set_image(image)
        if keep_stages:
            detection.stages = dict(raw=raw, undistorted=image)
        first, band, floor = 0, image, view.mask
        sides, surroundings = view_sides(floor), floor_boxes(floor)
    else:
        detection.set_image(None, lambda: view.undistort(raw))
        first, band, floor = view.first, view.band(raw), view.floor
        sides, surroundings = view.sides, view.surroundings
    mark('undistort')
    masks = colour_masks(band, floor, profile.colours, surroundings)
    mark('colour')
    pieces = []
    for colour in profile.colours:
        lines = [line for line in (profile.left, profile.right) if line.colour == colour]
        # a colour only dashed lines have is cut into dashes; one a solid line has, into lines
        style = 'dashed' if all(line.style == 'dashed' for line in lines) else 'solid'
        pieces += tape_pieces(cv2.bitwise_and(masks[colour], floor), colour, view.matrix,
                              mounting, max(line.width for line in lines),
                              0.1 * p.lane_width, piece_length, row0=first, side=sides,
                              elongation=ELONGATION[style])
    pieces.sort(key=lambda piece: -piece.length)
    detection.cluttered = len(pieces) > p.max_pieces
    detection.pieces, detection.masks = pieces[:p.max_pieces], (masks, first)
    mark('pieces')
    return detection


def repitched_pieces(pieces, mounting, turn_deg):
    """The pieces (found with `mounting`) where they lie if the camera looks `turn_deg` further
    down than the mounting says (geometry.repitched): their points, direction and length. Every
    point is moved in one call (a call per piece took as long as the moving)."""
    if not pieces:
        return []
    # each piece's direction and length: those of a 2 cm stretch along it through its middle
    c = np.array([math.cos(p.phi) for p in pieces])
    s = np.array([math.sin(p.phi) for p in pieces])
    mx = np.array([p.summary[0].mean() for p in pieces])
    my = np.array([p.summary[1].mean() for p in pieces])
    ends = np.cumsum([len(p.x) for p in pieces])
    x, y = repitched(np.concatenate([p.x for p in pieces] + [mx - 0.01 * c, mx + 0.01 * c]),
                     np.concatenate([p.y for p in pieces] + [my - 0.01 * s, my + 0.01 * s]),
                     mounting, turn_deg)
    first, last = slice(ends[-1], ends[-1] + len(pieces)), slice(ends[-1] + len(pieces), None)
    dx, dy = x[last] - x[first], y[last] - y[first]
    return [Piece(px, py, math.atan2(ddy, ddx), p.colour, p.length * math.hypot(ddx, ddy) / 0.02,
                  p.width, p.region)
            for p, px, py, ddx, ddy in zip(pieces, np.split(x[:ends[-1]], ends[:-1]),
                                            np.split(y[:ends[-1]], ends[:-1]), dx, dy)]
