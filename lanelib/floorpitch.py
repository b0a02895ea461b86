"""The camera's pitch read from the floor's motion, with odometry: the floor is rigid, so the
tape seen a moment ago, moved by how the robot moved since, lies where the tape is seen now,
but only when both are put on the floor with the camera's true pitch.

A camera that looks further down than its mounting says draws the floor stretched with distance
ahead (geometry.repitched): a point d ahead of the lens at about d (1 + d tan e / h), its
sideways distance with it. The stretch moves with the camera, not with the floor, so after the
robot has driven or turned, the tape of an earlier frame, moved as odometry says, no longer
lies on the tape seen now: a dash's end seen 0.5 m ahead, 9 cm later, is drawn 1.5 cm off with
the pitch 1 degree off; in a turn the stretch swings sideways with the view. How far the tape
misses, for each pitch tried, says the pitch whatever shape the lane has. The splay of the
lane's two lines (ImprovedController.learn_pitch) says it only where the lane is straight:
before a corner the fit still calls the lane straight, and the corner ahead reads as splay
(docs/benchmarks.md, forty-first and forty-second sessions).

Each frame with odometry the reader compares the pieces of tape in view with those of the
frame `lag` seconds before, at the pitch it holds and STEP either side: each piece's points
(Piece.summary) against the earlier pieces of its colour, each drawn as two segments from its
near end through its middle to its far end, a point's miss capped at CAP, and only the points
the earlier frame saw the floor about and that lie near its tape at the pitch held. Newton's
step on the parabola through the three misses says where this pair of frames puts the pitch;
the pitch held moves GAIN of the way there (the first pairs more: a camera's pitch stays, and
one pair of frames, a glint, a duck, says little alone).
"""

import math
from collections import deque

import numpy as np

from lanelib.geometry import repitched
from lanelib.robot import moved_by, seen_from

CAP = 0.03  # [m] a point further than this from the earlier tape counts as this far (the tape
# left view, a piece of something else); and only points this far inside the earlier frame's
# view are counted (nearer its ends, the ends' own stretch would be read)
STEP = 0.2  # [deg] the pitches tried: the one held and this either side
MOVE = 2.0  # [deg] the furthest one pair of frames moves the pitch held, before GAIN
GAIN = 0.1  # each pair of frames moves the pitch held this share of the way to its reading (the
# first ones more: the n-th 1 / n of the way, their mean, until that is GAIN)
NEAR_TAPE = CAP / 2  # [m] the points counted lie this near the earlier tape at the pitch held
MIN_MOVE = 0.03  # [m] of travel, and of the turn at TURN_REACH ahead, between the frames
# compared: less says nothing of the stretch
TURN_REACH = 0.3  # [m]
MIN_POINTS = 12  # points of the frame in the earlier frame's view: fewer say nothing


class _Frame:
    """One frame's tape, in arrays: each piece's summary points (P, 3: colour.POINTS) and
    colour."""

    def __init__(self, t, pose, made, pieces):
        self.t, self.pose, self.made = t, pose, made
        self.colour = np.array([p.colour for p in pieces])
        self.x = np.array([p.summary[0] for p in pieces]).reshape(-1, 3)
        self.y = np.array([p.summary[1] for p in pieces]).reshape(-1, 3)
        # as an earlier frame's tape: the two segments from the piece's near end through its
        # middle point to its far end (its summary points lie a sixth, a half and five sixths
        # along it), so that a line's pieces meet end to end, and a dash ends where it ends
        self.ends_x, self.ends_y = self.x.copy(), self.y.copy()
        for ends, mid in ((self.ends_x, self.x), (self.ends_y, self.y)):
            ends[:, 0] = 1.5 * mid[:, 0] - 0.5 * mid[:, 1]
            ends[:, 2] = 1.5 * mid[:, 2] - 0.5 * mid[:, 1]


class PitchFromMotion:
    """The pitch correction [deg] (the camera looks this much further down than `mounting`
    says, within +/- tolerance) read from frames and the motion between them (module doc)."""

    def __init__(self, mounting, tolerance, lag):
        self.mounting, self.tolerance, self.lag = mounting, tolerance, lag
        self.frames = deque()
        self.pose = np.zeros(3)  # x, y, yaw since the history began
        self.t = 0.0
        self.value = 0.0  # the correction held while a frame is read
        self.read_count = 0  # pairs of frames read

    def read(self, pieces, made, moved, dt, held):
        """Take one frame's pieces (put on the floor with the pitch correction `made`) and how
        the robot moved since the last frame (ahead, left, turned; None without odometry, and
        then the frames before are forgotten); return the pitch correction `held` [deg] moved
        by what this frame and the one `lag` before it say."""
        self.value = held
        if moved is None:
            self.frames.clear()
            return self.value
        self.pose = np.array(moved_by(*self.pose, *moved))
        self.t += dt
        frame = _Frame(self.t, self.pose, made, pieces)
        earlier = None
        while self.frames and self.t - self.frames[0].t >= self.lag:
            earlier = self.frames.popleft()
        if earlier is not None:
            self.frames.appendleft(earlier)  # the frame `lag` before: kept for the next one
            self._step(earlier, frame)
        self.frames.append(frame)
        return self.value

    def _step(self, earlier, now):
        """Move the pitch held towards where this pair of frames puts it."""
        motion = seen_from(now.pose, earlier.pose)  # the earlier robot frame in the present one
        if math.hypot(motion[0], motion[1]) + TURN_REACH * abs(motion[2]) < MIN_MOVE:
            return
        costs = self.misses(earlier, now, motion)
        if costs is None:
            return
        low, mid, high = costs
        slope, bend = (high - low) / (2 * STEP), (low + high - 2 * mid) / STEP ** 2
        # Newton's step to the parabola's minimum; down the slope as far as MOVE where the
        # misses have no minimum near (a slope, or they bend the other way)
        step = -slope / bend if bend * MOVE > abs(slope) else -math.copysign(MOVE, slope)
        self.read_count += 1
        self.value += max(GAIN, 1.0 / self.read_count) * step
        self.value = min(max(self.value, -self.tolerance), self.tolerance)

    def misses(self, earlier, now, motion):
        """(low, held, high): the mean capped squared distance [m^2] of the present frame's
        points to the earlier frame's tape of their colour, moved by `motion` (the earlier
        robot frame's x, y and heading in the present one), at the pitch held less STEP, at it,
        and plus STEP; None with fewer than MIN_POINTS in the earlier frame's view. The points
        counted are the same at each pitch: those between the earlier frame's nearest and
        furthest tape of their colour, along the robot's heading then, at the pitch held."""
        # the present pieces and the earlier ones of the colours both frames hold
        new, old = np.isin(now.colour, earlier.colour), np.isin(earlier.colour, now.colour)
        if not new.any():
            return None
        new_colour = np.repeat(now.colour[new], 3)  # each point's
        old_colour = np.repeat(earlier.colour[old], 2)  # each segment's
        same = new_colour[:, None] == old_colour[None, :]
        x1, y1 = now.x[new].ravel(), now.y[new].ravel()
        x0, y0 = earlier.ends_x[old], earlier.ends_y[old]
        tx, ty, turn = motion
        c, s = math.cos(turn), math.sin(turn)
        # the three pitches in one array each (axis 0): the same arithmetic, in a third of
        # the calls
        pitches = np.array([[self.value], [self.value - STEP], [self.value + STEP]])
        nx, ny = repitched(x1, y1, self.mounting.looking_down(now.made), pitches - now.made)
        ex, ey = repitched(x0, y0, self.mounting.looking_down(earlier.made),
                           pitches[..., None] - earlier.made)
        along = (nx[0] - tx) * c + (ny[0] - ty) * s  # ahead of the robot as it was then
        first, last = np.empty(len(along)), np.empty(len(along))
        for colour in np.unique(new_colour):  # the earlier tape's nearest and furthest
            reach = ex[0][old_colour[::2] == colour]
            first[new_colour == colour] = reach.min()
            last[new_colour == colour] = reach.max()
        keep = (along > first + CAP) & (along < last - CAP)  # at the pitch held
        if np.count_nonzero(keep) < MIN_POINTS:
            return None
        ox, oy = tx + c * ex - s * ey, ty + s * ex + c * ey
        # each piece's two segments: from (ax, ay) along (ux, uy), at each pitch
        ax, ay = ox[..., :2].reshape(3, 1, -1), oy[..., :2].reshape(3, 1, -1)
        ux, uy = ox[..., 1:].reshape(3, 1, -1) - ax, oy[..., 1:].reshape(3, 1, -1) - ay
        px, py = nx[:, keep, None] - ax, ny[:, keep, None] - ay
        along = np.clip((px * ux + py * uy) / np.maximum(ux * ux + uy * uy, 1e-12), 0.0, 1.0)
        d2 = np.where(same[keep], (px - along * ux) ** 2 + (py - along * uy) ** 2, CAP ** 2)
        d2 = np.minimum(d2.min(axis=2), CAP ** 2)
        matched = d2[0] < NEAR_TAPE ** 2  # the points near the earlier tape at the pitch held
        if np.count_nonzero(matched) < MIN_POINTS:
            return None
        result = [float(v[matched].mean()) for v in d2]
        held, low, high = result
        return low, held, high

