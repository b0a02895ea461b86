"""The lane memory: the centre line as seen in the last `seconds`, kept in the frame the robot
started in and moved with its motion (odometry while it comes, else the commands sent).

A camera looking ahead sees the floor from some way in front of the robot (the lecture's level
webcam from 0.6 m): the lane between the robot and there is known only from earlier frames.
The estimate (lanelib/estimate.py) fits one arc to what is in view; the memory keeps the lane's
shape as it was seen, so that a bend's entry, an S-bend's turn the other way, or a U-turn the
camera has lost sight of, are steered on as they are:

    centre_line(near, far)   the remembered centre line between near and far metres ahead, as
                             y = a + b x + c x^2: where the lane lies about the robot (the
                             estimate's anchor) and at the look-ahead (what the robot steers at)
    line_about(reach)        the straight line nearest the remembered points about the robot,
                             distances square to it: the anchor with memory_anchor 'line'
    arc(start)               the remembered centre line within a metre, as an arc through the
                             robot: it can turn any angle (what the robot follows when the lane
                             is out of view)
"""

import math

import numpy as np

from lanelib.lanefit import fit_lanes, signed_distance
from lanelib.robot import arc_step, moved_by

ENOUGH = 6  # points: fewer remembered in a stretch say nothing of it
ACROSS = math.cos(1.4)  # a line turned more than 1.4 rad (lanefit's HEADING_LIMIT) from the
# robot's heading has no offset at the robot worth the name


class LaneMemory:
    """Centre-line points (x, y, weight) of the last `seconds` of frames, in the start frame;
    with `most`, at most that many of each frame's points (add)."""

    def __init__(self, seconds, most=0):
        self.seconds = seconds
        self.most = most
        self.pose = np.zeros(3)  # x, y, yaw of the robot in the start frame
        self.t = 0.0
        self.clear()

    def move(self, v, omega, dt):
        """Dead reckoning: `dt` seconds at (v [m/s], omega [rad/s])."""
        self._moved_to(np.array(arc_step(*self.pose, v, omega, dt)), dt)

    def move_by(self, ahead, left, turned, dt):
        """The robot moved `ahead` and `left` [m] and turned `turned` [rad] (in its frame before
        the move) in `dt` seconds: from odometry."""
        self._moved_to(np.array(moved_by(*self.pose, ahead, left, turned)), dt)

    def _moved_to(self, pose, dt):
        """The robot is at `pose` `dt` seconds later: points older than `seconds` are gone."""
        self.pose = pose
        self.t += dt
        old = 0  # frames seen longer ago than `seconds`: the first ones
        while old < len(self.seen) and self.t - self.seen[old][0] > self.seconds:
            old += 1
        if old:
            self.start += sum(count for _, count in self.seen[:old])
            self.seen = self.seen[old:]
        self._local = None

    @property
    def points(self):
        """(X, Y, weight) of every point remembered, in the start frame, oldest first."""
        return self._buffer[:, self.start:self.end]

    def add(self, x, y, w):
        """Centre-line points seen now (robot frame). With `most` and more points than that,
        every k-th of them, the fewest k that leave at most `most`, weighed up so that they
        carry the frame's whole weight: each fit the memory makes is a weighted sum over its
        points, and its time grows with them (the Duckiebot's frame gives about 1,100)."""
        if self.most and len(x) > self.most:
            k = -(-len(x) // self.most)
            total = w.sum()
            x, y, w = x[::k], y[::k], w[::k]
            w = w * (total / w.sum())
        px, py, yaw = self.pose
        cos, sin = math.cos(yaw), math.sin(yaw)
        chunk = (px + cos * x - sin * y, py + sin * x + cos * y, w)
        n = len(chunk[0])
        if self.end + n > self._buffer.shape[1]:  # full: the points into a new buffer (one
            # already handed out, local()'s weights, stays as it is)
            live = self.points
            self._buffer = np.empty((3, max(2 * (live.shape[1] + n), 1024)))
            self.start, self.end = 0, live.shape[1]
            self._buffer[:, :self.end] = live
        self._buffer[:, self.end:self.end + n] = chunk
        self.end += n
        self.seen.append((self.t, n))
        if self._local is not None:  # the points in hand and the new ones, as local() would
            # make them all (each point's arithmetic is its own): the steering asks for them
            # after every add, and all of them again took a fifth of the memory's time
            new = self._in_robot_frame(*chunk)
            self._local = tuple(np.concatenate([old, more]) for old, more in zip(self._local, new))

    def _in_robot_frame(self, X, Y, w):
        """Points (X, Y) of the start frame in the robot's frame now, and their weights."""
        px, py, yaw = self.pose
        X, Y = X - px, Y - py
        cos, sin = math.cos(yaw), math.sin(yaw)
        return cos * X + sin * Y, -sin * X + cos * Y, w

    def local(self):
        """All remembered points in the robot's frame now: x, y, weight (worked out once per
        pose and set of points: a frame asks for them up to three times)."""
        if self._local is None:
            self._local = self._in_robot_frame(*self.points)
        return self._local

    def clear(self):
        # every point remembered, oldest first, in one buffer (X, Y, weight): a point is added
        # past the end and forgotten by moving the start (kept as a list of chunks, a frame's
        # each, they were joined afresh each time the robot moved: a fifth of the memory's
        # time); and each frame's time and how many points it gave, oldest first
        self._buffer, self.start, self.end = np.empty((3, 0)), 0, 0
        self.seen = []
        self._local = None  # local()'s answer until the robot moves or points come or go

    def centre_line(self, near, far, min_span, outlier=None):
        """(a, b, c) of the remembered centre line fitted between near and far metres ahead,
        or None with fewer than ENOUGH points there or spanning less than min_span. With
        `outlier` [m], two more rounds drop the points that far off the fit (points sorted to
        the wrong line, a lane width off)."""
        x, y, w = self.local()
        keep = (x > near) & (x < far)
        if np.count_nonzero(keep) < ENOUGH or np.ptp(x[keep]) < min_span:
            return None
        x, y, w, middle = x[keep], y[keep], w[keep], (near + far) / 2
        coef = fit_centre(x, y, w, x0=middle)
        for _ in range(2 if outlier else 0):
            keep = np.abs(y - (coef[0] + coef[1] * x + coef[2] * x ** 2)) < outlier
            if np.count_nonzero(keep) < ENOUGH:
                break
            coef = fit_centre(x[keep], y[keep], w[keep], x0=middle)
        return coef

    def line_about(self, reach, min_span):
        """(offset [m], heading [rad]) at the robot of the straight line nearest the remembered
        points within `reach` metres of the robot, each point's distance taken square to the
        line: their weighted principal axis, through their weighted mean. None with fewer than
        ENOUGH points there, spanning less than min_span along the line, or a line running
        across the robot's heading (which crosses its sideways axis nowhere near). Unlike
        centre_line's, whose distances are taken across the robot's heading, a part of the lane
        that runs across the view (a tight corner's way out) weighs no more than its length."""
        x, y, w = self.local()
        keep = np.hypot(x, y) < reach
        if np.count_nonzero(keep) < ENOUGH:
            return None
        x, y, w = x[keep], y[keep], w[keep]
        total = w.sum()
        mx, my = (w @ x) / total, (w @ y) / total  # the weighted mean: the line runs through it
        dx, dy = x - mx, y - my
        angle = 0.5 * math.atan2(2 * float(w @ (dx * dy)), float(w @ (dx * dx) - w @ (dy * dy)))
        c, s = math.cos(angle), math.sin(angle)  # c >= 0: along the line, ahead
        along = dx * c + dy * s
        if c < ACROSS or np.ptp(along) < min_span:
            return None
        return float(my - mx * s / c), angle

    def arc(self, start, reach, outlier):
        """The remembered centre line within `reach` metres of the robot as an arc (e, psi, k)
        through the robot, refined from `start` (e, psi, k), dropping points `outlier` metres
        off it; and the points it rests on (x, y); None with fewer than ENOUGH points."""
        x, y, w = self.local()
        keep = np.hypot(x, y) < reach
        if np.count_nonzero(keep) < ENOUGH:
            return None
        x, y, w = x[keep], y[keep], w[keep]
        arc = np.array([[*start, 0.0]], float)
        hold = ([1e-6 * w.sum()] * 3 + [0.0], [0.0] * 4)
        for _ in range(3):
            arc = fit_lanes(x, y, np.zeros((1, len(x))), w[None, :], arc, hold, (0.0, 0.0),
                            iterations=6)
            near = np.abs(signed_distance(x, y, *arc[0, :3])) < outlier
            if np.count_nonzero(near) < ENOUGH:
                return None
            x, y, w = x[near], y[near], w[near]
        return tuple(float(v) for v in arc[0, :3]), (x, y)


def fit_centre(x, y, w, ridge=0.05, x0=0.0):
    """Weighted least squares y = a + b x + c x^2, with c pulled towards 0 on short spans.
    The pull acts on the curve written about x0 (put x0 amid the points): there a and b are
    what the points say, whatever becomes of c (written about 0, pulling c on a short span far
    ahead would tilt the line instead of bending it). Solved from the weighted moments of the
    points (the normal equations): the memory holds about 10,000 points, and a design matrix
    of them took about three times as long (0.27 to 0.29 ms a call against 0.10)."""
    u = x - x0
    wu = w * u
    wu2 = wu * u
    s0, s1, s2 = w.sum(), wu.sum(), wu2.sum()
    s3, s4 = wu2 @ u, wu2 @ (u * u)
    normal = np.array([[s0, s1, s2], [s1, s2 + 1e-4 * s0, s3], [s2, s3, s4 + ridge * s0]])
    a, b, c = np.linalg.solve(normal, [w @ y, wu @ y, wu2 @ y])
    return float(a - b * x0 + c * x0 ** 2), float(b - 2 * c * x0), float(c)
