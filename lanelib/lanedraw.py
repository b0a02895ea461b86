"""The improved controller's pictures: what it saw and what it decided, on the frame.

    draw_lane       the undistorted frame, the colour masks tinted, the lane's centre (green),
                    left (orange) and right (blue) lines on the floor, the decision and estimate
    stage_pictures  every stage: the frame, undistorted, the floor band, each colour mask, the
                    pieces of tape (the lane's by side, the rest grey), the lane (--stages)
"""

import math

import cv2
import numpy as np

from lanelib.geometry import floor_to_pixels
from lanelib.lanefit import centre_path
from lanelib.outputs import draw_curve, text_band, tint
from lanelib.stages import as_bgr

SIDE_COLOURS = {0: (0, 255, 0), 1: (0, 160, 255), -1: (255, 128, 0)}  # BGR: centre, left, right


def arc_points(estimate, lengths, offset=0.0):
    """Points (x, y) of the estimate's centre line (its arc, and its bend ahead) at arc
    lengths `lengths`, moved `offset` [m] to its left."""
    x, y, h = centre_path(estimate.arc, lengths, estimate.bend)
    return x - offset * np.sin(h), y + offset * np.cos(h)


def draw_lane(controller, detection, command):
    """The picture the video, the debug topic and the window show (module doc), as wide as
    the frame read (FloorView.shown)."""
    masks, first = detection.masks
    profile, p, e = controller.profile, controller.p, controller.estimate
    shown = {c: m for c, m in masks.items() if c in profile.colours or c == 'red'}
    image = tint(detection.image, shown, first, alpha=0.35)
    if e is not None and controller.matrix is not None:
        lengths = np.linspace(0.0, p.roi_far, 40)
        for side, colour in SIDE_COLOURS.items():
            x, y = arc_points(e, lengths, side * p.lane_width / 2)
            draw_curve(image, x, y, lambda a, b: floor_to_pixels(a, b, controller.matrix,
                                                                 controller.mounting), colour)
    text = f'{command.decision}  v {command.linear_x:.2f} w {command.angular_z:+.2f}'
    if e is not None:
        text += (f'  offset {100 * e.offset:+.1f} cm  heading {math.degrees(e.heading):+.1f} '
                 f'deg  curvature {e.curvature:+.2f}/m  confidence {e.confidence:.2f}')
    return text_band(controller.view.shown(image), text)


def stage_pictures(controller, detection, command):
    """(key, title, BGR image) of every stage (module doc)."""
    stages, p, view = detection.stages or {}, controller.p, controller.view
    image = detection.image
    h, w = image.shape[:2]
    band = image.copy()
    band[view.mask == 0] //= 3
    out = [('raw', 'raw frame', as_bgr(stages.get('raw', image))),
           ('undistorted', '1 undistorted', image),
           ('floor', f'2 floor {p.roi_near:.2f} to {p.roi_far:.2f} m ahead', band)]
    masks, first = detection.masks
    for name in controller.profile.colours + ['red']:
        full = np.zeros((h, w), np.uint8)
        full[first:first + len(masks[name])] = masks[name]
        out.append((f'mask_{name}', f'3 {name} mask', cv2.cvtColor(full, cv2.COLOR_GRAY2BGR)))
    picture = (image // 2).copy()
    sides = controller.sides if controller.sides is not None else []
    grey = (150, 150, 150)
    for i, piece in enumerate(detection.pieces):
        colour = SIDE_COLOURS[int(sides[i])] if i < len(sides) and sides[i] else grey
        u, v, ok = floor_to_pixels(piece.x, piece.y, controller.matrix, p.mounting)
        for a, b in zip(u[ok], v[ok]):
            cv2.circle(picture, (int(a), int(b)), 2, colour, -1)
    out.append(('pieces', "4 tape pieces: the lane's left, right; others grey", picture))
    # each picture of the image read as wide as the frame (column_binning: stretched back; with
    # no calibration the frame itself is read binned)
    out = [(key, title, view.shown(picture)) for key, title, picture in out]
    out.append(('lane', '5 the lane, the decision', draw_lane(controller, detection, command)))
    return out
