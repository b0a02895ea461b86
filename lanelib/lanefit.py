"""Which of the lines in view are the robot's lane, and where that lane goes.

The lane's centre line is an arc through (0, e) in the robot frame (x ahead, y left), with
heading psi [rad] and curvature k [1/m, + bends left]: an arc, not a polynomial in x, so that a
Duckietown bend that turns 90 degrees within half a metre is one lane. Its left line lies half a
lane width to its left, its right line half a lane width to its right.

The search: every piece of line in view, on every side its colour allows, seeds lanes whose
line runs along it where it lies, straight and bending (each bending seed traced back along its
arc to the robot), and the lane predicted from earlier frames, when there is one. Each
seed is fitted to the pieces that lie on its two lines (Gauss-Newton on their distances from
the arc, within a tolerance that starts at half a lane width and tightens to a quarter), and the
lane kept is the one whose two lines are best supported: sqrt(left) + sqrt(right) of the line
lengths they explain, discounted with distance ahead (far points are less certain), for a
robot outside the lane it names, and, with a lane expected, for lying away from where it was
expected at the robot (one line alone fits a lane on either side of it equally well), and of
lanes supported alike, the one whose lines lie nearest their pieces; a piece
running across the fitted lane's lines where it lies (over ASKEW) is on neither. So a
neighbouring lane's lines, a centre line the robot is crossing, a line of the wrong colour on
a side, are not its lane's, and one line alone still places the lane, half a lane width beside
it, on the side it was.

With a spread allowed (find_lane's spread_limit), the width between the lines may change in
proportion to the distance ahead: a camera pitched a little off the mounting the floor is drawn
with splays lines parallel on the floor (or closes them), and fitted parallel they turned and
bent the lane.

Where the lane's curvature changes in view (a bend's entry seen from its straight, an S-bend's
turn the other way), the lane kept is refitted as two arcs, the second going on from the first
(a bend: where, and its curvature), when they fit its pieces much better: one arc through the
robot fits such a lane only turned away from it at the robot. The two arcs are fitted only
where a bend linearised about the one arc would fit much better too (a solve, against the
fit's many): on many frames with no bend in view the fit is not made, and on a few with a
sharp bend (that fits far better than its linearisation says) the one arc is kept.
"""

import math

import numpy as np

from lanelib.colour import POINTS

TOLERANCES = (0.5, 0.35, 0.25, 0.25)  # [lane widths] for the fitting rounds
SEED_CURVATURES = (0.0, -0.5, 0.5, -1.0, 1.0, -2.0, 2.0)  # [1 / lane width]
ITERATIONS = 4  # Gauss-Newton steps per fitting round
PRIOR_PULL = 0.03  # [of the line in view] pull towards the expected offset and heading
ASKEW = math.radians(30)  # a piece turned more than this from its line is not on it
# where a second arc may take over from the first (a bend's entry or exit, an S-bend's turn
# the other way), as fractions of the way from the nearest to the furthest of the lane's points
# ahead (where the fit starts from: it moves), and how much better it must fit to be kept: the
# weighted squared distances of the lane's points at most this fraction of the one arc's
BEND_STARTS = (0.25, 0.5, 0.75)
BEND_GAIN = 0.5
BEND_MIN = 0.1  # [1 / lane width] a smaller change of curvature is no bend
BEND_FLOOR = 0.01  # [lane widths] one arc as near its points as this (RMS) needs no bend
# a bend is fitted only where, linearised about the one arc (_bend_gain), it leaves at most
# this fraction of the one arc's weighted squared distances. Not exact: a sharp bend can fit
# far better than its linearisation says. Over 3,192 fits (17 simulated runs, the real frames)
# every bend kept (which leaves at most BEND_GAIN) had left at most 0.53 so, and 40 % of the
# fits that kept none are not made; in gym-duckietown 37 of 5,176 bends kept without the
# screen left 0.7 to 0.96 so, and 20 % of its fits that kept none are skipped: its 20
# criterion episodes drove alike either way (docs/benchmarks.md, 67th and 68th sessions)
BEND_SCREEN = 0.7
# Levenberg-Marquardt steps of a bend's fit (every start's at once). It has not settled by then
# (at the twelfth step some start still improved in 164 of 168 full fits), so the count is a
# price, not a convergence. 8 take 0.77 of the time (the bench's 333 recorded fits, 1.42 against
# 1.84 ms a call) and drove gym-duckietown's criterion alike, but left the benchmark's corner
# with a gap (lecture world, seed 0) at 65 %; 10 kept that benchmark's lecture world, but the
# held-out S-bends completed 25 of 32 against 28: not kept (docs/benchmarks.md, 73rd session)
BEND_ITERATIONS = 12
# every fit's steps are held within these: a lane turned at most 1.4 rad (80 degrees) at the
# robot, bending at most 30 /m (a circle 3.3 cm in radius), so that a step on few points stays
# among lanes a camera could see
HEADING_LIMIT = 1.4  # [rad]
CURVATURE_LIMIT = 30.0  # [1/m]
SETTLED = 1e-12  # a Gauss-Newton fit whose last step moved nothing more than this has settled:
# fitted again to the same points on the same sides, it stays where it is
TIE = 1e-6  # lanes scored within this fraction of the best are equally supported (rounding)


def signed_distance(x, y, e, psi, k):
    """Distance of points from the centre arc, + to the left of its direction. Arrays of arcs
    (e, psi, k of shape (S, 1)) give an (S, N) array. Exact for any k, 0 included: in the arc's
    own frame (u ahead, v left of its start) the circle of curvature k is
    2 v - k (u^2 + v^2) = 0, and the distance is that over 1 + k r, r from the circle's centre."""
    return _distance(x, y, e, psi, k)[0]


def robot_offset(e, psi, k):
    """How far the centre arc lies to the robot's left [m], across the arc (the robot's
    distance from it, + when the robot is to its right): e is where the arc crosses the robot's
    sideways axis, which for a lane running across the view lies much further out than the lane
    itself (e cos psi on a straight lane), so a robot well inside a lane it is turning into would
    be judged outside it by e."""
    return -signed_distance(0.0, 0.0, e, psi, k)


def sharpest(k, bend, within=math.inf):
    """[1/m] the largest |curvature| of a centre line that bends k, and bend[1] from bend[0]
    [m] along it (bend None: no second arc), within `within` [m] of the robot."""
    if bend is not None and bend[0] < within:
        return max(abs(k), abs(bend[1]))
    return abs(k)


def centre_path(arc, lengths, bend=None):
    """(x, y, heading) arrays of the centre line at arc lengths `lengths` [m] from where it
    crosses the robot's sideways axis: the arc (e, psi, k), and with a bend (s0, k2) from s0
    on the arc of curvature k2 that goes on from it."""
    e, psi, k = arc
    lengths = np.asarray(lengths, float)
    x, y, h = _along_arc(0.0, e, psi, k, lengths)
    if bend is not None:
        s0, k2 = bend
        x0, y0, h0 = _along_arc(0.0, e, psi, k, np.array([s0]))
        x2, y2, h2 = _along_arc(x0[0], y0[0], h0[0], k2, lengths - s0)
        later = lengths > s0
        x, y, h = np.where(later, x2, x), np.where(later, y2, y), np.where(later, h2, h)
    return x, y, h


def _along_arc(x0, y0, h0, k, lengths):
    """(x, y, heading) `lengths` [m] along the arc of curvature k from (x0, y0) heading h0."""
    h = h0 + k * lengths
    if abs(k) < 1e-4:
        return x0 + lengths * math.cos(h0), y0 + lengths * math.sin(h0), h
    return (x0 + (np.sin(h) - math.sin(h0)) / k, y0 + (math.cos(h0) - np.cos(h)) / k, h)


def bent_distance(x, y, arc, bend):
    """signed_distance from the centre line that is the arc (e, psi, k) up to s0 along it and
    the arc of curvature k2 after (bend: (s0, k2)): a point is the second arc's when its
    nearest point on the first arc's circle lies beyond s0."""
    return _bent_distances(x, y, np.array([[*arc, bend[1], bend[0]]], float))[0]


def _bent_distances(x, y, q):
    """bent_distance for P centre lines at once, q (P, 5): e, psi, k, k2, s0; (P, N). The
    fit of a bend calls it a dozen times a frame on a few dozen points, so its time is its
    numpy calls: each sine and cosine is taken once, and the straight (k = 0) forms only
    where some line is straight (np.where's other branch, every element the same)."""
    e, psi, k, k2, s0 = (q[:, i:i + 1] for i in range(5))
    # where the second arc starts: _along_arc from (0, e) heading psi, s0 along
    h0 = psi + k * s0
    s, c, s2, c2 = np.sin(psi), np.cos(psi), np.sin(h0), np.cos(h0)
    straight = np.abs(k) < 1e-4
    if straight.any():
        bent = np.where(straight, 1.0, k)
        x0 = np.where(straight, s0 * c, (s2 - s) / bent)
        y0 = np.where(straight, e + s0 * s, e + (c - c2) / bent)
    else:
        x0, y0 = (s2 - s) / k, e + (c - c2) / k
    u, v = _turned(x, y - e, s, c)  # in the first arc's frame, and the second's
    first = _distance_in(u, v, s, c, k)[0]
    second = _distance_in(*_turned(x - x0, y - y0, s2, c2), s2, c2, k2)[0]
    return np.where(_along_in(u, v, k) > s0, second, first)


def _along(x, y, e, psi, k):
    """How far along the arc (e, psi, k) [m] the points' nearest points on its circle lie;
    arrays of arcs (e, psi, k of shape (S, 1)) give an (S, N) array."""
    return _along_in(*_arc_frame(x, y, e, psi)[:2], k)


def _along_in(u, v, k):
    """_along from the points in the arc's own frame."""
    flat = np.abs(k) < 1e-9
    if not flat.any():  # np.where's other branch, every element the same, in fewer calls
        return np.arctan2(k * u, 1 - k * v) / k
    return np.where(flat, u, np.arctan2(k * u, 1 - k * v) / np.where(flat, 1.0, k))


def _arc_frame(x, y, e, psi):
    """(u, v, sin psi, cos psi): points in the arc's own frame, u ahead, v left of its start."""
    s, c = np.sin(psi), np.cos(psi)
    return (*_turned(x, y - e, s, c), s, c)


def _turned(dx, dy, s, c):
    """(u, v): offsets (dx, dy) from a point in the frame heading (cos, sin) = (c, s) there."""
    return dx * c + dy * s, dy * c - dx * s


def _distance(x, y, e, psi, k, jacobian=False, out=None):
    """signed_distance, and with `jacobian` its derivatives in e, psi and k (an array
    (..., 3), or written into `out`, and None returned)."""
    return _distance_in(*_arc_frame(x, y, e, psi), k, jacobian, out)


def _distance_in(u, v, s, c, k, jacobian=False, out=None):
    """_distance from the points in the arc's own frame (_arc_frame's u, v, sin, cos)."""
    ku, kv1 = k * u, 1 - k * v
    root = np.sqrt(ku * ku + kv1 * kv1)  # k r
    squared = u * u + v * v
    q, den = 2 * v - k * squared, 1 + root
    d = q / den
    if not jacobian:
        return d, None
    # d(q)/d(u, v, k) and d(root)/d(u, v, k); u, v depend on e (-s, -c) and psi (v, -u)
    root = np.maximum(root, 1e-12)
    q_u, q_v = -2 * ku, 2 * kv1
    r_u, r_v = k * ku / root, -k * kv1 / root
    q_k, r_k = -squared, (ku * u - kv1 * v) / root
    q_e, r_e = -(q_u * s + q_v * c), -(r_u * s + r_v * c)
    q_psi, r_psi = q_u * v - q_v * u, r_u * v - r_v * u
    columns = (q_e - d * r_e) / den, (q_psi - d * r_psi) / den, (q_k - d * r_k) / den
    if out is None:
        return d, np.stack(columns, axis=-1)
    for i, column in enumerate(columns):  # no stacked copy made and then copied into out
        out[..., i] = column
    return d, None


def _distances(x, y, arcs, jacobian=False, out=None):
    e, psi, k = (arcs[:, i:i + 1] for i in range(3))
    return _distance(x, y, e, psi, k, jacobian, out)


def fit_lanes(x, y, sides, w, lanes, priors, limits, iterations=ITERATIONS, last_step=None):
    """Weighted least squares of the points' distances from their lines, for S lanes at once:
    x, y (N,) points; sides (S, N) each point's line (+1 left, -1 right, 0 neither), w (S, N)
    their weights; lanes (S, 4) the starts (e, psi, k, width), a point on side s lying
    s * width / 2 from the centre arc, or (S, 5) (e, psi, k, width, spread), s * (width +
    spread x) / 2 (_halves). priors: (weights, target), each of the lanes' length: each
    parameter pulled towards its target with that weight; limits: the width's bounds (equal:
    held there), and with a spread its bound (+-; 0: held). last_step: an (S,) array, when
    given, gets each lane's largest change in its last step. Gauss-Newton."""
    lanes = lanes.astype(float).copy()
    n = lanes.shape[1]
    pull, target = (np.asarray(v, float) for v in priors)
    pull = pull + 1e-9
    if limits[0] == limits[1]:
        pull[3] = 1e12  # no step in the width
    jac = np.empty(sides.shape + (n,))
    jac[..., 3] = -sides / 2  # the width's column: the same every step
    low = [-HEADING_LIMIT, -CURVATURE_LIMIT, limits[0]]  # psi, k, width (, spread)
    high = [HEADING_LIMIT, CURVATURE_LIMIT, limits[1]]
    if n == 5:
        jac[..., 4] = -sides * x / 2  # and the spread's
        if not limits[2]:
            pull[4] = 1e12  # no step in the spread
        low.append(-limits[2])
        high.append(limits[2])
    low, high = np.array(low), np.array(high)
    pulled = np.diag(pull)
    for _ in range(iterations):
        d, _ = _distances(x, y, lanes, jacobian=True, out=jac[..., :3])
        wj = np.swapaxes(jac * w[..., None], 1, 2)  # (S, n, N)
        a = wj @ jac + pulled
        b = (wj @ (d - sides * _halves(lanes, x))[..., None])[..., 0] + pull * (lanes - target)
        step = np.linalg.solve(a, b[..., None])[..., 0]
        lanes -= step
        lanes[:, 1:] = np.minimum(np.maximum(lanes[:, 1:], low), high)  # np.clip's values
    if last_step is not None:
        last_step[:] = np.abs(step).max(axis=1)
    return lanes


def _halves(lanes, x):
    """(S, N): half the width between the lines of each lane (S, 4 or 5) at points x (N,) ahead:
    width / 2, or (width + spread x) / 2. A camera pitched a little off the mounting given
    draws the floor wrongly by an amount that grows with the distance ahead: lines parallel on
    the floor are drawn splayed (or closing), their spacing changing in proportion to it. The
    spread is that change, per metre ahead, as this view shows the lane."""
    return _spacing(lanes[:, 3:], x)


def _spacing(own, x):
    """_halves from the lanes' width (and spread) columns alone, own (S, 1 or 2)."""
    half = own[:, :1] / 2
    if own.shape[1] < 2:
        return np.broadcast_to(half, (len(own), len(x)))
    return half + own[:, 1:2] * x / 2


class LaneFit:
    """The lane found: arc (e, psi, k) and its width between the line centres as the lines
    show it; per piece its side (+1 left, -1 right, 0 not the lane's); the lengths of line on
    each side [m]; the centre-line points the pieces give (x, y, weight); and where the lane's
    curvature changes, if it does: bend (s0 [m] along it, k2 [1/m] after), else None;
    predicted: whether it is the lane predicted, refitted (find_lane's prior)."""

    def __init__(self, arc, sides, left, right, centre, width=None, bend=None, predicted=False,
                 spread=0.0):
        self.e, self.psi, self.k = arc[:3]
        self.width, self.bend, self.predicted = width, bend, predicted
        self.spread = spread  # the width's change per metre ahead, as the view shows it
        self.sides, self.left, self.right, self.centre = sides, left, right, centre

    @property
    def across(self):  # the centre line's distance to the robot's left, across the lane [m]
        return robot_offset(self.e, self.psi, self.k)

    def point_at(self, distance):
        """(x, y, heading) of the centre line at `distance` [m] from the robot, along it; on
        a circle too small to reach that far, its point furthest from the robot (half way
        round: the way the lane goes; going on round would come back beside the robot)."""
        k = sharpest(self.k, self.bend)
        s = np.linspace(0.0, min(3.0 * distance, 2 * math.pi / max(k, 1e-9)) + 1e-6, 400)
        x, y, h = centre_path((self.e, self.psi, self.k), s, self.bend)
        reach = np.hypot(x, y)
        far = reach >= distance
        i = int(np.argmax(far)) if far.any() else int(np.argmax(reach))
        return float(x[i]), float(y[i]), float(h[i])


def _points(pieces, reach):
    """Each piece's POINTS points (Piece.summary), weighted less the further ahead they are."""
    x = np.concatenate([p.summary[0] for p in pieces])
    y = np.concatenate([p.summary[1] for p in pieces])
    w = np.concatenate([p.summary[2] for p in pieces]) / (1.0 + (x / reach) ** 2)
    return x, y, w


def _askew(lanes, pieces):
    """(S, pieces): whether each piece runs more than ASKEW across the lane's lines where it
    lies (lanes (S, 4) e, psi, k, width; the lines' direction at a point is the centre arc's
    at the point abreast of it). A bend's outer tape seen again beyond a gap has turned across
    the view and lies a lane width over, where the other line would be, but not along it:
    taken for that line, it made a straight lane of a 0.5 m bend (wood's corner). Only the
    lanes fitted are judged so: in the fitting rounds a lane not yet bent would turn away the
    pieces of its own bend."""
    x = np.array([p.summary[0].mean() for p in pieces])
    y = np.array([p.summary[1].mean() for p in pieces])
    phi = np.array([p.phi for p in pieces])
    e, psi, k = (lanes[:, i:i + 1] for i in range(3))
    u, v, _, _ = _arc_frame(x, y, e, psi)
    heading = psi + np.arctan2(k * u, 1 - k * v)  # round the circle's centre (k 0: psi)
    turn = (phi - heading + math.pi / 2) % math.pi - math.pi / 2  # a piece has no direction
    return np.abs(turn) > ASKEW


def _sides(distance, allowed, half, tol, regions=None, askew=None):
    """(S, pieces) each piece's side in each lane: the allowed side (allowed: (pieces, 2)
    left, right) whose line, half (S,) or (S, pieces) from the centre, its points lie nearest
    on average, within tol; 0 for neither, and 0 where `askew` (S, pieces) says the piece runs
    across the lines rather than along them (_askew). regions: (weights (pieces,), one-hot
    (pieces, R)) of the mask regions the pieces were cut from: one region is one tape, so one
    line; where a lane puts pieces of one region on both its lines (a tape bending across the
    view, partly lost in a shadow, taken for both), the pieces on the side with less of it
    are not the lane's."""
    d = distance.reshape(len(distance), len(allowed), POINTS).mean(axis=2)
    half = half[:, None] if half.ndim == 1 else half
    left = np.where(allowed[:, 0], np.abs(d - half), np.inf)
    right = np.where(allowed[:, 1], np.abs(d + half), np.inf)
    sides = np.where((left <= right) & (left < tol), 1, np.where(right < tol, -1, 0))
    if askew is not None:
        sides = np.where(askew, 0, sides)
    if regions is not None:
        weight, onehot = regions
        on_left = ((sides == 1) * weight) @ onehot  # (S, R)
        on_right = ((sides == -1) * weight) @ onehot
        side = np.where(on_left >= on_right, 1, -1) @ onehot.T  # (S, pieces): its region's
        sides = np.where(sides == side, sides, 0)
    return sides


def _regions(pieces):
    """(weights, one-hot (pieces, R)) of the pieces' mask regions, for _sides; None when
    no region has more than one piece."""
    names = [p.region if p.region is not None else ('piece', i) for i, p in enumerate(pieces)]
    unique = {name: j for j, name in enumerate(dict.fromkeys(names))}
    if len(unique) == len(names):
        return None
    onehot = np.zeros((len(names), len(unique)))
    onehot[np.arange(len(names)), [unique[n] for n in names]] = 1.0
    return np.array([p.length for p in pieces]), onehot


def find_lane(pieces, profile, lane_width, prior=None, explained=0.6, width_tolerance=0.3,
              anchor=None, prior_first=False, width=None, spread_limit=0.0, expected=None):
    """The best-supported lane (LaneFit) among the pieces, or None. prior: (e, psi, k) of the
    lane expected from earlier frames; when it, refitted, explains `explained` of the line in
    view with the robot inside it, it is the lane (LaneFit.predicted), whatever else the search
    finds. It is refitted as the search's first seed, where it grows as it would alone; with
    prior_first (it was the lane the frame before), alone first, and the search only if it
    fails: the same lane either way, in about half the time when it holds. anchor:
    (e, psi) the lane is expected to have at the robot (default: the prior's); every fit is
    pulled a little towards it. The width between the lines is fitted within width_tolerance
    of lane_width (a camera's pitch a little off, a track taped a little wider, make the lines
    look that much further apart: forced to the profile's width the lane would tilt to fit
    them); with one line in view it stays `width`, the width last measured (default
    lane_width; held within the same bounds). spread_limit: how much the width may change per
    metre ahead (_halves; 0: the lines are parallel), pulled a little towards none (with one
    line in view it shares that line's slope with the lane's heading, which the anchor holds:
    a single line's turn is taken in part as a splay). expected: (k, spread) [1/m]: the
    curvature the lane is predicted to have, and how far from it a lane may be bent: each
    lane's support is weighed by that normal distribution."""
    if not pieces:
        return None
    limits = (lane_width * (1 - width_tolerance), lane_width * (1 + width_tolerance))
    width = lane_width if width is None else float(np.clip(width, *limits))
    half = width / 2
    points = _points(pieces, 2.6 * lane_width)
    allowed = np.array([[1 in s, -1 in s] for s in (profile.sides(p.colour) for p in pieces)])
    total = float(points[2].sum())
    # priors: k towards 0, weakly (a point x ahead moves k x^2 / 2 with k, so this weighs about
    # as much as 0.2 % of the points a lane width ahead), the width towards `width`; and
    # with a lane expected, its offset and heading at the robot, as much as 3 % of the
    # points near the robot: the lines seen far ahead place the lane there well, but its
    # offset and heading under the robot only through a long lever (a bend's entry seen from
    # a level camera fits an arc turned the wrong way), which the expected lane steadies
    weights = [0.0, 0.0, 0.002 * total * lane_width ** 4, 0.02 * total]
    target = [0.0, 0.0, 0.0, width]
    if spread_limit:  # the spread towards none as the width towards `width`, two lane
        # widths ahead (where a change of spread moves a line as far as one of width there)
        limits += (spread_limit,)
        weights.append(0.02 * total * lane_width ** 2)
        target.append(0.0)
    own = (width, 0.0) if spread_limit else (width,)  # a seed's own width (and spread)
    anchor = anchor if anchor is not None else None if prior is None else prior[:2]
    if anchor is not None:
        weights[:2] = PRIOR_PULL * total, PRIOR_PULL * total * lane_width ** 2
        target[:2] = anchor
    priors = (weights, target)
    search = (pieces, points, allowed, lane_width, priors, limits, _regions(pieces), anchor,
              expected)

    def holds(found):  # the prior, refitted, is the lane: both its lines in view (one line
        # alone fits a lane on either side of it, and which one is the search's to say: the
        # score, with the anchor), the robot inside it, most of the line in view explained
        if found is None:
            return False
        _, lane, sides, support = found
        return bool(1 in sides and -1 in sides and abs(robot_offset(*lane[:3])) <= lane[3] / 2
                    and support >= explained * total)

    if prior is not None and prior_first:
        found = _fit_seeds(np.array([[*prior, *own]], float), *search)[1]
        if holds(found):
            return _lane(pieces, found, points, priors, limits, lane_width, predicted=True)
    seeds = [] if prior is None else [(*prior, *own)]
    for piece, (may_left, may_right) in zip(pieces, allowed):
        x0, y0 = piece.summary[0][1], piece.summary[1][1]
        for side in [s for s, may in ((1, may_left), (-1, may_right)) if may]:
            seeds += _seeds_along(x0, y0, piece.phi, side * half, lane_width, own)
    found, first = _fit_seeds(np.array(seeds, float), *search)
    if prior is not None and holds(first):
        return _lane(pieces, first, points, priors, limits, lane_width, predicted=True)
    return None if found is None else _lane(pieces, found, points, priors, limits, lane_width)


def _seeds_along(x0, y0, phi, side, lane_width, own):
    """Seeds (e, psi, k, *own: the width, and the spread where it is fitted) of lanes, one
    per SEED_CURVATURES, whose line `side` [m] to the left of the centre runs through (x0, y0)
    in the direction phi: the centre arc through the point abreast of it, heading phi there,
    traced back to the robot's sideways axis (a bending lane's heading at the robot is not the
    piece's: a bend's outer line seen across the view, seeded turned as the piece and then
    bent, began a quarter turn from the lane). A circle that never reaches the axis seeds
    nothing."""
    s, c = math.sin(phi), math.cos(phi)
    xc, yc = x0 + side * s, y0 - side * c
    seeds = []
    for k in (q / lane_width for q in SEED_CURVATURES):
        if k == 0.0:
            seeds.append((yc - math.tan(phi) * xc, phi, 0.0, *own))
            continue
        a = s - k * xc
        if abs(a) < 1.0:
            psi = math.asin(a)
            seeds.append((yc + (c - math.cos(psi)) / k, psi, k, *own))
    return seeds


def _fit_seeds(seeds, pieces, points, allowed, lane_width, priors, limits, regions=None,
               anchor=None, expected=None):
    """(score, lane, sides, support) of the best lane grown from the seeds (S, 4 or 5: e, psi,
    k, width (, spread)), and of the lane grown from the first seed; each None where there is
    none; expected: find_lane's, each lane's score weighed by it. Each
    seed grows on its own (a seed whose lane another's joins is dropped, the first kept), so
    the first grows as it would alone: find_lane's prior, refitted, without a fit of its own
    (two fits cost as much as one search: the time is the calls, not the seeds)."""
    x, y, w = points
    ahead = x.reshape(-1, POINTS).mean(axis=1)  # each piece's distance ahead
    lanes, before = seeds, None  # before: each lane's sides in the round before, when its fit
    # there had settled
    for tol in TOLERANCES:
        distance = _distances(x, y, lanes)[0]
        sides = _sides(distance, allowed, _halves(lanes, ahead), tol * lane_width, regions)
        if before is not None and np.array_equal(sides, before):
            continue  # the fit the round before, from where it settled: it would not move
        on = np.repeat(sides, POINTS, axis=1)
        step = np.empty(len(lanes))
        lanes = fit_lanes(x, y, on, (on != 0) * w, lanes, priors, limits, last_step=step)
        # seeds from pieces of one line mostly grow into one lane: fit it once
        grid = np.round(lanes / (0.02 * lane_width, 0.02, 0.1 / lane_width, 0.02 * lane_width,
                                 0.02)[:lanes.shape[1]])
        firsts = _firsts(grid)
        lanes, before = lanes[firsts], None
        if np.all(step[firsts] < SETTLED):
            before = sides[firsts]
    distance = _distances(x, y, lanes)[0]
    half, halves = lanes[:, 3] / 2, _halves(lanes, ahead)  # at the robot; at each piece
    sides = _sides(distance, allowed, halves, TOLERANCES[-1] * lane_width, regions,
                   _askew(lanes, pieces))
    on = np.repeat(sides, POINTS, axis=1)
    left, right = ((on == 1) * w).sum(axis=1), ((on == -1) * w).sum(axis=1)
    # line in the middle half of the lane, where only floor should be
    middle = np.abs(distance.reshape(len(lanes), -1, POINTS).mean(axis=2)) < halves / 2
    inside = (np.repeat(middle & (sides == 0), POINTS, axis=1) * w).sum(axis=1)
    # the robot outside the lane it names
    outside = np.maximum(0.0, np.abs(robot_offset(*lanes[:, :3].T)) - half)
    score = (np.sqrt(left) + np.sqrt(right) - np.sqrt(inside)) * np.exp(-outside / half)
    if anchor is not None:
        # with one line in view, a lane with it on the left and one with it on the right are
        # equally supported, a lane width apart at the robot: the one where the robot was
        # expected to be is the robot's (a tape bending across the view, taken for the other
        # line from one frame to the next, flipped the estimate by a lane width)
        score = score * np.exp(-0.5 * ((lanes[:, 0] - anchor[0]) / half) ** 2)
    if expected is not None:
        # the lane predicted: a lane bent much otherwise (at a tight corner, the far edge
        # across the view with the nearest dashes of the centre line, turned away and bent the
        # other way) is weighed down, however long the line it rests on
        score = score * np.exp(-0.5 * ((lanes[:, 2] - expected[0]) / expected[1]) ** 2)
    score[~sides.any(axis=1)] = -1.0
    # of lanes that explain the same line equally (the same pieces: near the robot, a lane
    # turned at the robot and bending back runs along them as well as a straight one), the
    # one nearest its pieces, not the first in the seeds' order: on a real Duckietown frame
    # (visual_control_test.png) a straight lane and one turned 44 degrees bending back 2.9 /m
    # scored alike, and the order of the pieces chose between them
    tied = np.flatnonzero(score >= score.max() - TIE * max(score.max(), 0.0))
    miss = ((distance[tied] - on[tied] * _halves(lanes[tied], x)) ** 2 * (on[tied] != 0) *
            w).sum(axis=1)
    best = int(tied[np.argmin(miss)])
    return tuple((score[i], lanes[i], sides[i], float(left[i] + right[i])) if score[i] > 0
                 else None for i in (best, 0))


def _firsts(rows):
    """The indices of each distinct row's first occurrence, in order: np.unique(rows, axis=0,
    return_index=True)'s, sorted, in a quarter of its time (a stable sort of the rows and
    where they change; np.unique sorts a structured copy of them)."""
    order = np.lexsort(rows.T[::-1])
    ranked = rows[order]
    new = np.ones(len(rows), bool)
    new[1:] = np.any(ranked[1:] != ranked[:-1], axis=1)
    return np.sort(order[new])


def _lane(pieces, found, points, priors, limits, lane_width, predicted=False):
    """The LaneFit of the lane found (_fit_seeds), with a bend where one fits its points
    better (_fit_bend)."""
    _, lane, sides, _ = found
    bend = _fit_bend(points, np.repeat(sides, POINTS), lane, lane_width, priors, limits)
    if bend is not None:
        lane, bend = bend
    lengths = [sum(p.length for p, s in zip(pieces, sides) if s == side) for side in (1, -1)]
    return LaneFit(lane, sides, lengths[0], lengths[1],
                   _centre_points(pieces, sides, lane, bend), float(lane[3]), bend, predicted,
                   float(lane[4]) if len(lane) > 4 else 0.0)


def _fit_bend(points, on, lane, lane_width, priors, limits):
    """(lane (e, psi, k, width), bend (s0, k2)) of the centre line as two arcs, the second
    taking over s0 along the first, fitted to the lane's points (on: each point's side), when
    the one arc misses them by more than BEND_FLOOR (RMS) and the two leave at most BEND_GAIN
    of its weighted squared distances, change the curvature by at least BEND_MIN, bend less
    tightly than the lane's half width, keep the lane's lines on its pieces and the robot no
    further out of it; else None. A bend's entry
    seen from its straight, an S-bend's turn the other way: one arc through the robot fits
    such a lane only turned away from it at the robot. Levenberg-Marquardt in (e, psi, k, k2,
    s0, width) from s0 at BEND_STARTS, each from parabolas through the points before and
    after s0, or from the one arc where too few points lie before s0 for a parabola; the one
    arc's priors, k2 and s0 free; derivatives by differences. Both starts at every knot (six
    fits, not three) kept the same 95 of 333 recorded bends at 2.00 ms a call against 1.72:
    where a knot's parabolas could be made, its arc start won 5 of 168 fits. The starts are
    fitted side by side in arrays (one evaluation of every start and its steps per
    iteration): a start at a time took about 10 ms a frame. None without fitting where even
    the bend linearised about the one arc leaves more than BEND_SCREEN of its distances
    (_bend_gain: one solve, about 0.1 ms against a fit's 3)."""
    x, y, w = points
    w = (on != 0) * w
    own = w > 0  # the lane's own points: the fit needs only these, the last check every one
    if np.count_nonzero(own) < 2 * POINTS:
        return None
    full = x, y, on
    x, y, on, w = x[own], y[own], on[own], w[own]
    # the one arc's priors, and none on k2 and s0 (after k): np.insert took as long as a step
    pull, target = (np.array([*v[:3], 0.0, 0.0, *v[3:]], float) for v in priors)
    pull += 1e-9
    n = len(pull)  # e, psi, k, k2, s0, width (, spread)
    if limits[0] == limits[1]:
        pull[5] = 1e12  # no step in the width
    if n == 7 and not limits[2]:
        pull[6] = 1e12  # nor in the spread
    steps = np.array((1e-6, 1e-6, 1e-4, 1e-4, 1e-5))

    def costs(qs):  # (S,) costs and (S, N) residuals of S parameter sets
        r = _bent_distances(x, y, qs[:, :5]) - on * _spacing(qs[:, 5:], x)
        return r ** 2 @ w + (qs - target) ** 2 @ pull, r

    halves = _halves(np.asarray(lane, float)[None, :], x)[0]
    d, arc_jac = _distances(x, y, lane[None, :], jacobian=True)
    missed = d[0] - on * halves  # each point's distance from its line
    one = float(w @ missed ** 2)
    if one <= w.sum() * (BEND_FLOOR * lane_width) ** 2:
        return None  # the one arc fits: nothing to gain
    knots = x.min() + np.array(BEND_STARTS) * np.ptp(x)
    if one - _bend_gain(x, y, on, w, lane, limits, missed, arc_jac[0], knots) > (
            BEND_SCREEN * one):
        return None  # not even a linearised bend fits much better
    e, psi, k = lane[:3]
    own = list(lane[3:])  # the width (and spread)
    starts = []
    centre = y - on * halves  # each point moved across onto the lane's centre line
    for s0 in knots:  # one start a knot: the parabolas where they can be made, else the arc
        near, far = x < s0, x >= s0
        if np.count_nonzero(near) >= 2 * POINTS:  # before s0 a line or a parabola, after
            a, slope, k1 = _parabola(x[near], centre[near], w[near])
            k2 = _parabola(x[far], centre[far], w[far])[2] if (
                np.count_nonzero(far) >= 3 * POINTS) else k
            starts.append([a, math.atan(slope), k1, k2, s0, *own])
        else:
            starts.append([e, psi, k, k, s0, *own])
    moves = np.zeros((6, n))
    moves[1:, :5] = np.diag(steps)

    def evaluated(qs):  # costs(qs), and the residuals' derivatives (S, N, 5) by differences
        cost, res = costs((qs[:, None, :] + moves).reshape(-1, n))  # each and its 5 steps
        res = res.reshape(len(qs), 6, -1)
        slopes = (res[:, 1:] - res[:, :1]) / steps[:, None]
        return cost[::6], res[:, 0], slopes.transpose(0, 2, 1)

    # every start at once: each its own Levenberg-Marquardt, in one array; a trial is
    # evaluated with its steps, so that where it is kept its derivatives are at hand
    q = np.array(starts, float)
    jac = np.empty((len(q), len(x), n))
    jac[:, :, 5] = -on / 2
    if n == 7:
        jac[:, :, 6] = -on * x / 2
    c, r, jac[:, :, :5] = evaluated(q)
    damping = np.full(len(q), 1e-3)
    pulled = np.diag(pull)
    low = [-HEADING_LIMIT, -CURVATURE_LIMIT, -CURVATURE_LIMIT, x.min(), limits[0]]
    high = [HEADING_LIMIT, CURVATURE_LIMIT, CURVATURE_LIMIT, x.max(), limits[1]]
    if n == 7:
        low.append(-limits[2])
        high.append(limits[2])
    low, high = np.array(low), np.array(high)
    eye = np.eye(n)
    for _ in range(BEND_ITERATIONS):
        wj = jac.transpose(0, 2, 1) * w
        normal = wj @ jac + pulled
        scaled = normal + damping[:, None, None] * (normal * eye)
        gradient = (wj @ r[..., None])[..., 0] + pull * (q - target)
        trial = q - np.linalg.solve(scaled, gradient[..., None])[..., 0]
        trial[:, 1:] = np.minimum(np.maximum(trial[:, 1:], low), high)  # np.clip's values
        c_trial, r_trial, j_trial = evaluated(trial)
        better = c_trial < c  # kept where better: one call each, no copies of the rows
        column = better[:, None]
        np.copyto(q, trial, where=column)
        np.copyto(c, c_trial, where=better)
        np.copyto(r, r_trial, where=column)
        np.copyto(jac[:, :, :5], j_trial, where=column[:, None])
        damping = np.where(better, damping / 3, damping * 10)
    best = int(np.argmin(c))  # the best start's fit (the first of equals, as before)
    q, c_best = q[best], float(r[best] ** 2 @ w)
    x, y, on = full
    r = bent_distance(x, y, q[:3], (q[4], q[3])) - on * _spacing(q[None, 5:], x)[0]
    off = np.abs(r.reshape(-1, POINTS).mean(axis=1))[on[::POINTS] != 0]
    if (c_best > BEND_GAIN * one or abs(q[3] - q[2]) * lane_width < BEND_MIN or
            abs(q[3]) * q[5] / 2 >= 1 or  # the inner line would turn back on itself
            np.any(off > TOLERANCES[-1] * lane_width) or
            abs(robot_offset(*q[:3])) > max(q[5] / 2, abs(robot_offset(*lane[:3])))):
        return None
    return np.delete(q, (3, 4)), (float(q[4]), float(q[3]))


def _bend_gain(x, y, on, w, lane, limits, r, slopes, knots):
    """How much of the weighted squared distance of the lane's points (x, y, sides `on`,
    weights w) from the one arc (lane) bending at one of the knots [m ahead] takes away at
    best, linearised: the residuals r against the one arc's derivatives (slopes (N, 3): in e,
    psi and k; and the width's and spread's, where they are free) and a bend's, (s - s0)^2 / 2
    at s along the arc past the knot s0. Weighted least squares by the normal equations, every
    knot in one solve."""
    columns = [slopes, -on[:, None] / 2]
    if limits[0] == limits[1]:
        columns.pop()  # the width held
    if len(lane) > 4 and limits[2]:
        columns.append(-on[:, None] * x[:, None] / 2)
    fixed = np.hstack(columns)  # (N, m - 1): the same at every knot
    past = np.maximum(_along(x, y, *lane[:3]) - knots[:, None], 0.0)  # (K, N)
    a = np.empty(past.shape + (fixed.shape[1] + 1,))  # (K, N, m)
    a[..., :-1] = fixed
    a[..., -1] = past ** 2 / 2
    wa = np.swapaxes(a, 1, 2) * w  # (K, m, N)
    normal, b = wa @ a, (wa @ r)[..., None]
    # a little ridge: with one line in view the offset and the width move it alike
    normal += np.eye(normal.shape[1]) * (1e-12 * np.trace(normal, axis1=1, axis2=2))[:, None,
                                                                                    None]
    return float((b[..., 0] * np.linalg.solve(normal, b)[..., 0]).sum(axis=1).max())


def _parabola(x, y, w):
    """(y at x = 0, slope there, curvature in the middle) of the weighted least-squares
    parabola through points, a line for fewer than 3 * POINTS of them. Solved from the weighted
    moments about the points' weighted mean (the normal equations, well conditioned there):
    the same lanes as np.polyfit's least squares on the bench's 1,538 bend fits, and the fit
    1.76 ms a call against 2.07; np.polyfit stays for points all at one distance ahead."""
    sw = w.sum()
    m = (w @ x) / sw
    u = x - m
    wu = w * u
    wu2 = wu * u
    s1, s2 = wu.sum(), wu2.sum()
    line = len(x) < 3 * POINTS
    if line:
        normal, moments = [[sw, s1], [s1, s2]], [w @ y, wu @ y]
    else:
        s3 = wu2 @ u
        normal = [[sw, s1, s2], [s1, s2, s3], [s2, s3, wu2 @ (u * u)]]
        moments = [w @ y, wu @ y, wu2 @ y]
    try:
        a, b, *c = np.linalg.solve(normal, moments)  # y = a + b (x - m) (+ c (x - m)^2)
    except np.linalg.LinAlgError:  # a singular system: the points at one distance
        if line:
            slope, a = np.polyfit(x, y, 1, w=np.sqrt(w))
            return a, slope, 0.0
        c, b, a = np.polyfit(x, y, 2, w=np.sqrt(w))
        middle = b + 2 * c * np.average(x, weights=w)
        return a, b, 2 * c / (1 + middle ** 2) ** 1.5
    if line:
        return a - b * m, b, 0.0
    c = c[0]
    # at x = 0: a - b m + c m^2, slope b - 2 c m; in the middle (x = m) the slope is b
    return a - b * m + c * m * m, b - 2 * c * m, 2 * c / (1 + b ** 2) ** 1.5


def _left_normals(x, y, x0, y0, h0, k):
    """The left normal of the arc of curvature k from (x0, y0) heading h0, at the points
    nearest (x, y) on its circle (towards the circle's centre for a left bend)."""
    if abs(k) < 1e-4:
        return np.full(len(x), -math.sin(h0)), np.full(len(x), math.cos(h0))
    cx, cy = x0 - math.sin(h0) / k, y0 + math.cos(h0) / k
    dx, dy = cx - x, cy - y
    r = np.maximum(np.hypot(dx, dy), 1e-9)
    return math.copysign(1.0, k) * dx / r, math.copysign(1.0, k) * dy / r


def _centre_points(pieces, sides, lane, bend=None):
    """The lane's pieces moved half a lane width (where they lie: _halves) towards the centre
    line, across it. Every piece's points at once (each point's arithmetic is its own, so a
    call a piece gave the same numbers in more calls)."""
    mine = [(piece, side) for piece, side in zip(pieces, sides) if side]
    x = np.concatenate([piece.x for piece, _ in mine])
    y = np.concatenate([piece.y for piece, _ in mine])
    signs = np.concatenate([np.full(len(piece.x), side) for piece, side in mine])
    e, psi, k = arc = lane[:3]
    nx, ny = _left_normals(x, y, 0.0, e, psi, k)
    if bend is not None:
        (x0,), (y0,), (h0,) = centre_path(arc, [bend[0]])
        later = _along(x, y, e, psi, k) > bend[0]
        nx2, ny2 = _left_normals(x, y, x0, y0, h0, bend[1])
        nx, ny = np.where(later, nx2, nx), np.where(later, ny2, ny)
    half = _halves(np.asarray(lane, float)[None, :], x)[0]
    return (x - signs * half * nx, y - signs * half * ny,
            np.concatenate([piece.w for piece, _ in mine]))
