"""The lane estimate: where the robot's lane is, frame after frame, as predict and update.

    measure   one frame: among all the pieces of line in view, the robot's own lane
              (lanelib/lanefit.py: the lane whose two lines the pieces best support, with the
              colours allowed on each side), as an arc through the robot; None when too
              little of its lines is seen (only those near enough, to start a lane:
              ImprovedParams.seen_within), or the robot would be more than half a lane
              outside it
    predict   the last estimate moved with the robot's motion since (and a little less sure)
    follows   whether a measurement can be the lane predicted: its heading at the robot, and
              where it lies across, within gates of the prediction's (ImprovedParams.turn_gate,
              shift_gate)
    blend     the prediction and the measurement weighed by the measurement's confidence

The estimate is the centre line as y = a + b x + c x^2 about the robot (x ahead, y left): its
offset (-a), heading (-atan b) and curvature (2c / (1 + b^2)^1.5 at the robot), and how sure of
it (0..1). It is predicted and blended as the arc it is measured as (offset, heading,
curvature), not as the parabola's coefficients: for a lane turned across the view, as at a
tight corner, c is many times the curvature, and moved as a coefficient it bent the lane
expected several times more than anything measured (Duckietown's simulator: 4 to 40 / m).
"""

import math
from dataclasses import dataclass, replace

import numpy as np

from lanelib.lanefit import LaneFit, centre_path, find_lane, robot_offset, sharpest

MIN_SEEN = 0.25  # [lane widths] of the lane's lines: less is no lane (a scrap, a glint)
FULL_VIEW = 2.9  # [lane widths] of line seen counts as a full view (confidence 1)
ONE_LINE = 0.7  # how sure one line alone makes the estimate, against both
FORGET = 0.8  # how much of its confidence a prediction keeps, per frame
TURNED = math.radians(80)  # a lane predicted to run more than this across the view is lost
CROSSING_STEPS = 4  # Newton steps to where the lane crosses the robot's sideways axis


@dataclass
class LaneEstimate:
    a: float  # centre line y at x = 0 [m]
    b: float  # slope of the centre line at x = 0
    c: float  # half its curvature [1/m]
    confidence: float  # 0..1
    left: int = 0  # pieces on the left line
    right: int = 0  # pieces on the right line
    reach: float = 1.0  # [m] mean distance ahead of the points the fit rests on
    points: tuple = None  # the centre-line points the fit rests on: x, y, weight (robot frame)
    width: float = None  # [m] between the lines, as measured
    bend: tuple = None  # (s0 [m], k2 [1/m]): from s0 along it the lane bends k2 (lanefit)
    spread: float = 0.0  # the width's change per metre ahead, as measured (lanefit._halves)
    seen: float = 0.0  # [m] ahead, the farthest of the points the fit rests on (0: none)

    @property
    def offset(self):  # robot left of the lane centre [m]
        return -self.a

    @property
    def heading(self):  # robot turned left of the lane direction [rad]
        return -math.atan(self.b)

    @property
    def curvature(self):  # the lane bends left [1/m]
        return 2 * self.c / (1 + self.b ** 2) ** 1.5

    @property
    def arc(self):  # (e, psi, k) of the arc it starts as, lanefit's shape
        return self.a, math.atan(self.b), self.curvature

    @property
    def across(self):  # the centre line's distance to the robot's left, across the lane [m]
        return robot_offset(*self.arc)

    def point_at(self, distance):
        """(x, y, heading) of the centre line `distance` [m] from the robot, following it as
        the arc it starts as, and the bend after (a polynomial in x cannot turn 90 degrees)."""
        return LaneFit(self.arc, None, 0, 0, None, bend=self.bend).point_at(distance)

    def bent_within(self, distance):
        """[1/m] the largest |curvature| of the centre line within `distance` [m] of the robot:
        the arc's, or the bend's beyond it where that begins nearer."""
        return sharpest(self.curvature, self.bend, distance)

    def lateral_at(self, distance):
        """How far to the left [m] the centre line lies `distance` metres from the robot."""
        return self.point_at(distance)[1]

    def bent_away(self, distance):
        """How far to the left [m] the centre line, `distance` metres from the robot, has bent
        away from the straight line it starts along at the robot: of lateral_at, the part that
        is the lane's own bending, not the robot's offset or heading."""
        x, y, _ = self.point_at(distance)
        psi = math.atan(self.b)
        return (y - self.a) * math.cos(psi) - x * math.sin(psi)


def half_curvature(k, b):
    """c of the parabola y = a + b x + c x^2 that bends k [1/m] where its slope is b."""
    return k * (1 + b * b) ** 1.5 / 2


def measure(pieces, profile, p, prior=None, anchor=None, prior_first=False, width=None,
            expected=None, splay=True, within=0.0):
    """One frame's LaneEstimate from pieces of line with their colours, or None (module doc);
    and the lanefit.LaneFit it rests on (or None). p: ImprovedParams in metres; prior: the
    arc (e, psi, k) of the lane expected; anchor: (offset, heading) of the lane expected at
    the robot, if known better than the prior's; prior_first: try the prior alone first (it
    was the lane the frame before: lanefit.find_lane); width: the width between the lines last
    measured with both in view: one line alone lies half of it from the lane's centre
    (default: the profile's). With p.pitch_tolerance the lines may splay (lanefit._halves),
    unless `splay` is False: the pitch is read otherwise (from the floor's motion), and lines
    parallel on the floor are drawn parallel. within [m]: only the lines this near count
    towards MIN_SEEN (0: all of them)."""
    # a pitch off by d stretches the floor drawn by about 1 + tan(d) x / h at x ahead (h the
    # camera's height): the width between the lines changes by lane_width tan(d) / h a metre
    spread_limit = (p.lane_width * math.tan(math.radians(p.pitch_tolerance)) / p.camera_height
                    if splay else 0.0)
    fit = find_lane(pieces, profile, p.lane_width, prior, width_tolerance=p.width_tolerance,
                    anchor=anchor, prior_first=prior_first, width=width,
                    spread_limit=spread_limit, expected=expected)
    if fit is None or abs(fit.across) > fit.width:
        return None, fit
    seen = near_seen(pieces, fit.sides, within) if within else fit.left + fit.right
    if seen < MIN_SEEN * p.lane_width:
        return None, fit
    b = math.tan(fit.psi)
    confidence = (min(1.0, (fit.left + fit.right) / (FULL_VIEW * p.lane_width)) *
                  (1.0 if fit.left and fit.right else ONE_LINE))
    cx, _, cw = fit.centre
    return LaneEstimate(fit.e, b, half_curvature(fit.k, b), confidence,
                        int(np.sum(fit.sides == 1)), int(np.sum(fit.sides == -1)),
                        float(np.average(cx, weights=cw)), fit.centre, fit.width, fit.bend,
                        fit.spread, float(np.max(cx))), fit


def near_seen(pieces, sides, distance):
    """[m] of the lane's lines (the pieces given a side) within `distance` [m] ahead, counted
    by their summary points."""
    on = [piece.summary for piece, side in zip(pieces, sides) if side]
    if not on:
        return 0.0
    x = np.concatenate([points[0] for points in on])  # one array: a sum per piece cost 5 times
    return float(np.concatenate([points[2] for points in on])[x <= distance].sum())


def predict(est, ds, dtheta):
    """The centre line as seen after the robot drove `ds` [m] ahead and turned `dtheta` [rad],
    or None when it would run across the robot's view (more than TURNED from its heading).
    The lane is an arc (lanefit), and an arc stays one as the robot moves: its offset and
    heading are where it crosses the robot's new sideways axis, its curvature its own (the
    parabola y = a + b x + c x^2 moved instead bent more each time the robot turned to follow
    it: c held, curvature 2c / (1 + b^2)^1.5 grew as b shrank)."""
    e, psi, k = est.arc
    cos, sin = math.cos(dtheta), math.sin(dtheta)
    s = ds * math.cos(psi)  # along the arc to where it crosses the new axis: Newton from here
    for _ in range(CROSSING_STEPS):
        x, y, h = (float(v[0]) for v in centre_path((e, psi, k), [s]))
        step = math.cos(h - dtheta)
        if abs(step) < 1e-6:
            return None
        s -= ((x - ds) * cos + y * sin) / step
    x, y, h = (float(v[0]) for v in centre_path((e, psi, k), [s]))
    heading = (h - dtheta + math.pi) % (2 * math.pi) - math.pi
    if not (math.isfinite(s) and abs(heading) < TURNED):
        return None
    bend = est.bend
    if bend is not None:  # the bend comes nearer; driven into, its curvature is the lane's
        bend = (bend[0] - s, bend[1])
        if bend[0] <= 0:
            k, bend = bend[1], None
    b = math.tan(heading)
    return replace(est, a=-(x - ds) * sin + y * cos, b=b, c=half_curvature(k, b),
                   confidence=est.confidence * FORGET, bend=bend, seen=max(0.0, est.seen - s))


def follows(pred, meas, gate, shift=0.0):
    """Whether the lane measured can be the lane predicted: turned at the robot no more than
    `gate` [rad] from it, and moved across no more than `shift` [m] (0: either is off). The
    prediction has already moved the lane by the robot's own motion, so what is left is the
    estimate's error; a lane turned or moved much further is another line's:
    - at a tight corner the next straight's lines run across the view, and fitted as one lane
      through the robot they turned it by up to 80 degrees in one frame, at full confidence
      (gym-duckietown, small_loop seed 5 with domain rand: predicted -3 degrees, measured +80);
    - the robot moves across its lane a few centimetres a frame, so a lane found half a lane
      width or more beside the one predicted lies nearer the next lane's centre than its own:
      its lines are the neighbour's, or one line taken for the other (gym-duckietown with domain
      rand, 40 episodes: the estimate jumped 0.2 to 0.3 m in one frame in four, all of which
      failed, and at most 0.085 m in the others).
    The controller counts such a frame as one with no lane; once the estimate is stale
    (lost_timeout) a lane found replaces it, and so it does while the estimate is only just
    found (improved.CONFIRMED)."""
    return ((not gate or abs(meas.heading - pred.heading) <= gate)
            and (not shift or abs(meas.across - pred.across) <= shift))


def blend(pred, meas, weight):
    """The prediction moved `weight` (0..1) of the way to the measurement: its offset, heading
    and curvature, and its confidence (module doc). The bend ahead is
    the measurement's where it sees one; where it sees none, the bend predicted fades into
    the arc measured at the same pace (out of the near view, a bend's entry is measured as
    one arc bent less than either of its parts, which is no reason to forget the bend)."""
    def towards(old, new):
        return old + weight * (new - old)

    bend = meas.bend
    if bend is None and pred.bend is not None:
        bend = (pred.bend[0], towards(pred.bend[1], meas.curvature))
    (e0, psi0, k0), (e1, psi1, k1) = pred.arc, meas.arc
    psi, k = towards(psi0, psi1), towards(k0, k1)
    b = math.tan(psi)
    return LaneEstimate(towards(e0, e1), b, half_curvature(k, b),
                        towards(pred.confidence, meas.confidence),
                        meas.left, meas.right, meas.reach, width=meas.width, bend=bend,
                        spread=meas.spread, seen=meas.seen)
