"""The improved controller's estimate, memory and steering law on synthetic pieces of line with
known answers (lanelib/estimate.py, lanelib/memory.py, lanelib/steering.py). lanefit's search
for the lane among the lines has its own tests in test_lanes.py."""

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from kobuki_lane import LaneParams
from lanelib import lanefit
from lanelib.colour import Piece
from lanelib.estimate import MIN_SEEN, LaneEstimate, blend, measure, near_seen, predict
from lanelib.improved import ANCHOR, CONFIRMED, REGAINED, ImprovedController, ImprovedParams
from lanelib.lanefit import bent_distance, centre_path, robot_offset, signed_distance
from lanelib.lanes import BUILTIN
from lanelib.memory import LaneMemory, fit_centre
from lanelib.robot import arc_step
from lanelib.steering import command, curvature, steer

DT = BUILTIN['duckietown']
P = ImprovedParams(lane='duckietown').in_metres(DT.lane_width)


def frame(pieces):
    """A detection holding only these pieces of line, as the controller takes it."""
    return SimpleNamespace(cluttered=False, pieces=pieces)


def line_pieces(y, colour, along=(0.15, 0.8), step=0.1, dashed=False):
    """Pieces of a straight line at lateral y [m], along x from along[0] to along[1]."""
    pieces = []
    for i, s0 in enumerate(np.arange(along[0], along[1], step)):
        if dashed and i % 2:
            continue
        x = np.linspace(s0, s0 + step, 20)
        pieces.append(Piece(x, np.full_like(x, y), 0.0, colour, step, 0.03))
    return pieces


# ---------------------------------------------------------------- measure

def test_two_lines_are_the_lane_where_it_is_and_sure():
    half = DT.lane_width / 2
    est, fit = measure(line_pieces(0.03 + half, 'yellow', dashed=True) +
                       line_pieces(0.03 - half, 'white'), DT, P)
    assert est.offset == pytest.approx(-0.03, abs=0.005) and abs(est.heading) < 0.01
    assert est.left and est.right and est.confidence == 1.0
    assert est.width == pytest.approx(DT.lane_width, abs=0.005)


def test_one_line_places_the_lane_half_a_width_beside_it_less_sure():
    est, _ = measure(line_pieces(-0.08, 'white'), DT, P)
    assert est.offset == pytest.approx(0.08 - DT.lane_width / 2, abs=0.005)
    assert est.right and not est.left and est.confidence == pytest.approx(
        min(1.0, 0.7 / (2.9 * DT.lane_width)) * 0.7, rel=0.05)


def test_a_neighbours_lane_is_not_the_robots():
    w = DT.lane_width
    own = line_pieces(w / 2, 'yellow', dashed=True) + line_pieces(-w / 2, 'white')
    est, fit = measure(own + line_pieces(1.5 * w, 'white'), DT, P)
    assert abs(est.offset) < 0.01 and list(fit.sides[len(own):]) == [0] * 7


def test_no_line_or_a_scrap_is_no_lane():
    assert measure([], DT, P) == (None, None)
    scrap = line_pieces(0.05, 'white', along=(0.5, 0.52), step=0.03)
    assert measure(scrap, DT, P)[0] is None  # 3 cm: less than a quarter lane width


def test_seen_within_counts_only_the_lines_near_enough():
    """A glint or a wall's foot far up the view spans a long stretch of floor in few pixels:
    measured `within` a distance, only the lines' length that near counts towards seeing a
    lane; without it (0), all of it."""
    d = 2.53 * DT.lane_width
    beyond = line_pieces(-0.08, 'white', along=(d + 0.01, d + 0.31))
    assert sum(piece.length for piece in beyond) > 4 * MIN_SEEN * DT.lane_width
    assert measure(beyond, DT, P, within=d)[0] is None
    assert measure(beyond, DT, P)[0] is not None  # all the lines count
    within = line_pieces(-0.08, 'white', along=(d - 0.3, d))
    assert measure(within, DT, P, within=d)[0] is not None
    both = line_pieces(-0.08, 'white', along=(d - 0.1, d + 0.3))
    assert near_seen(both, [-1] * len(both), d) == pytest.approx(0.1, abs=0.01)
    assert near_seen(both, [0] * len(both), d) == 0  # pieces of no side: none


def test_seen_within_starts_a_lane_only_from_near_lines_and_keeps_one_followed():
    """With seen_within (in lane widths) a lane is started only by lines that near: a fresh
    controller shown only far lines finds no lane, with the default it does. A lane followed
    for CONFIRMED frames is still seen when only its far lines are left (a corner, a gap)."""
    w = DT.lane_width
    far = frame(line_pieces(-w / 2, 'white', along=(2.6 * w, 3.4 * w)))
    near = ImprovedParams(lane='duckietown', memory=0.0, seen_within=2.53)
    fresh = ImprovedController(LaneParams(), near)
    assert fresh.p.seen_within == pytest.approx(2.53 * w)  # in lane widths, like the distances
    fresh(far, 0.0)
    assert fresh.estimate is None and fresh.lost_for > 0
    default = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0))
    default(far, 0.0)
    assert default.estimate is not None and default.lost_for == 0.0
    followed = ImprovedController(LaneParams(), near)
    for k in range(CONFIRMED + 1):
        followed(lane_beside(0.0), k * 0.125)
    assert followed.confirmed >= CONFIRMED
    followed(far, (CONFIRMED + 1) * 0.125)
    assert followed.lost_for == 0.0 and followed.sides is not None


def test_a_lane_the_robot_would_be_far_outside_is_not_its_own():
    est, _ = measure(line_pieces(1.2, 'white') + line_pieces(0.95, 'yellow'), DT, P)
    assert est is None


def test_a_lane_found_after_one_was_lost_must_be_the_one_lost_but_a_first_lane_is_taken():
    """After a lane was seen and lost, a lane the robot stands outside of (the far leg of a
    U-turn) is not taken for it; a controller that has seen no lane yet (a node started
    beside its lane, a single picture) takes the lane it finds."""
    w = DT.lane_width
    off = -0.9 * w  # beyond REGAINED (0.75 lane widths) from the robot
    assert 0.9 > REGAINED
    beside = frame(line_pieces(off + w / 2, 'yellow', dashed=True) +
                   line_pieces(off - w / 2, 'white'))
    own = frame(line_pieces(w / 2, 'yellow', dashed=True) + line_pieces(-w / 2, 'white'))
    nothing = frame([])
    # where the pieces put it (the default start belief pulls a first lane towards the robot)
    params = ImprovedParams(lane='duckietown', search_angle=0.0, start_belief='none')

    fresh = ImprovedController(LaneParams(), params)
    fresh(beside, 0.0)
    assert fresh.lost_for == 0.0 and fresh.estimate.offset == pytest.approx(-off, abs=0.01)
    believing = ImprovedController(LaneParams(), replace(params, start_belief='centred'))
    believing(beside, 0.0)  # taken too, pulled part of the way towards the robot
    assert believing.lost_for == 0.0 and 0.3 * -off < believing.estimate.offset < -off - 0.01

    seen = ImprovedController(LaneParams(), params)
    seen(own, 0.0)
    t = 0.0
    while t < 1.5:  # lost for longer than lost_timeout (1 s)
        t += 0.25
        seen(nothing, t)
    seen(beside, t + 0.25)
    assert seen.lost_for > 1.5  # still lost: not taken for the lane it lost


def lane_beside(across):
    """A straight Duckietown lane whose centre lies `across` [m] to the robot's left."""
    w = DT.lane_width
    return frame(line_pieces(across + w / 2, 'yellow', dashed=True)
                 + line_pieces(across - w / 2, 'white'))


def slanted_pieces(intercept, psi, colour, along=(0.1, 0.6), step=0.08):
    """Pieces of a straight line crossing the robot's sideways axis at `intercept` [m] and
    heading psi [rad] (+ left), over x from along[0] to along[1]."""
    pieces = []
    for s0 in np.arange(along[0], along[1], step * math.cos(psi)):
        x = np.linspace(s0, s0 + step * math.cos(psi), 20)
        pieces.append(Piece(x, intercept + math.tan(psi) * x, psi, colour, step, 0.03))
    return pieces


def test_a_lane_running_across_the_view_with_the_robot_inside_it_is_the_robots():
    # the robot 10 cm right of the centre of a lane that runs 68 degrees to its right (turned
    # into a corner): the centre line crosses the robot's sideways axis 0.27 m to its left,
    # more than a lane width, but the robot is inside the lane, 0.1 m from its centre line
    psi, across = math.radians(-68), 0.10
    e, half = across / math.cos(psi), DT.lane_width / 2 / math.cos(psi)
    est, _ = measure(slanted_pieces(e + half, psi, 'yellow') +
                     slanted_pieces(e - half, psi, 'white'), DT, P)
    assert est is not None and est.across == pytest.approx(across, abs=0.01)
    assert math.degrees(est.heading) == pytest.approx(68, abs=2)


@pytest.mark.parametrize('side', [1, -1])
def test_a_seed_runs_along_its_piece_where_the_piece_lies(side):
    # a piece of a line 0.3 m round a bend of radius 0.24 m (curvature one lane width's
    # worth, a seed curvature), turned 72 degrees from the lane's heading at the robot: the
    # seed of that curvature is the lane itself, although the piece runs nearly across the
    # view; the straight seed is the piece's own line, half a lane width over
    k, half = side / DT.lane_width, DT.lane_width / 2
    arc = (0.02, 0.1, k)
    x, y, h = centre_path(arc, [0.3])
    assert math.degrees(abs(h[0] - arc[1])) == pytest.approx(72, abs=1)
    x0, y0 = x[0] - side * half * math.sin(h[0]), y[0] + side * half * math.cos(h[0])
    seeds = lanefit._seeds_along(x0, y0, h[0], side * half, DT.lane_width, (DT.lane_width,))
    bent = [q for q in seeds if q[2] == pytest.approx(k)]
    assert len(bent) == 1 and bent[0][:2] == pytest.approx(arc[:2], abs=1e-9)
    e, psi, _, _ = [q for q in seeds if q[2] == 0.0][0]
    assert psi == h[0] and signed_distance(x0, y0, e, psi, 0.0) == pytest.approx(side * half)


def test_a_lane_turned_further_than_it_can_have_turned_is_no_lane_until_the_estimate_is_stale():
    """Between two frames the prediction turns the lane by the robot's own turn: a lane found
    turned turn_gate further at the robot (the next straight's lines across the view at a
    tight corner, fitted as one lane) is not taken, and the frame counts as one with no lane;
    a lane within it is blended; once the estimate is stale (lost_timeout) the turned lane is
    taken."""

    def lane(psi_deg):
        psi = math.radians(psi_deg)
        half = DT.lane_width / 2 / math.cos(psi)
        return frame(slanted_pieces(half, psi, 'yellow') + slanted_pieces(-half, psi, 'white'))

    gate = 0.5  # the duckiebot preset's
    assert math.radians(68) > gate > math.radians(10)
    robot = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0,
                                                            turn_gate=gate))
    for k in range(CONFIRMED + 1):  # the lane found, and followed: the gate defends it
        robot(lane(0), k * 0.125)
    assert abs(robot.estimate.heading) < 0.02 and robot.lost_for == 0.0
    t = CONFIRMED * 0.125
    robot(lane(-68), t + 0.125)  # the lane 68 degrees to the right a frame later: not the lane
    assert robot.lost_for == pytest.approx(0.125) and robot.sides is None
    assert abs(robot.estimate.heading) < 0.1  # the prediction, turned by the robot's own turn
    robot(lane(-10), t + 0.25)  # 10 degrees: the lane, blended
    assert robot.lost_for == 0.0 and 0.02 < robot.estimate.heading < math.radians(10)
    t += 0.25
    while robot.lost_for <= 1.0:  # lost_timeout: the estimate is stale
        t += 0.125
        robot(lane(-68), t)
    robot(lane(-68), t + 0.125)
    assert robot.lost_for == 0.0
    # the turned lane, pulled a little towards the prediction (lanefit.PRIOR_PULL)
    assert math.degrees(robot.estimate.heading) == pytest.approx(65, abs=3)
    # without the gate (the default) the turned lane is blended at once
    free = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0))
    free(lane(0), 0.0)
    free(lane(-68), 0.125)
    assert free.lost_for == 0.0 and free.estimate.heading > 0.3


def test_with_bend_belief_the_search_weighs_lanes_by_the_curvature_predicted(monkeypatch):
    """With bend_belief, each frame's search is given the curvature the lane is predicted to
    have and the spread in 1/m (lanefit.find_lane's expected); without it, or with no
    prediction, none."""
    import lanelib.estimate as estimate
    given = []
    real = estimate.find_lane
    monkeypatch.setattr(estimate, 'find_lane',
                        lambda *a, **k: given.append(k['expected']) or real(*a, **k))
    bend = [Piece(x, side * DT.lane_width / 2 - 2.0 * x * x / 2, 0.0, colour, 0.1, 0.03)
            for side, colour in ((1, 'yellow'), (-1, 'white'))
            for x in (np.linspace(s, s + 0.1, 20) for s in np.arange(0.15, 0.8, 0.1))]
    robot = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0,
                                                            bend_belief=0.5))
    robot(frame(bend), 0.0)
    v, omega = robot.last
    predicted = predict(robot.estimate, v * 0.125, omega * 0.125).curvature
    robot(frame(bend), 0.125)
    assert given[0] is None
    assert given[1] == pytest.approx((predicted, 0.5 / DT.lane_width), abs=1e-9)
    assert predicted < -0.1  # bent right, as measured in the first frame
    given.clear()
    free = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0))
    free(frame(bend), 0.0)
    free(frame(bend), 0.125)
    assert given == [None, None]


def test_a_start_belief_expects_the_first_lane_under_the_robot_until_one_is_confirmed(
        monkeypatch):
    """start_belief 'centred': until a lane has been found in CONFIRMED frames running, each
    frame's search expects the lane where a robot is set down, its centre under the robot and
    along its heading (find_lane's anchor (0, 0)), and the first lane found is pulled towards
    it; from then on (reset() or not) the lane predicted. With 'none', no anchor but the
    prediction's. 'centred' is the default, the Kobuki's (no --robot) as the duckiebot's."""
    import lanelib.estimate as estimate
    given = []
    real = estimate.find_lane
    monkeypatch.setattr(estimate, 'find_lane',
                        lambda *a, **k: given.append(k['anchor']) or real(*a, **k))
    w = DT.lane_width
    beside = lane_beside(-0.3 * w)  # the robot 0.3 lane widths left of its lane's centre

    def started(belief=None):
        chosen = {} if belief is None else {'start_belief': belief}
        robot = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0,
                                                                **chosen))
        robot(frame([]), 0.0)  # nothing in view: still unplaced
        firsts = []
        for k in range(1, CONFIRMED + 3):
            robot(beside, k * 0.125)
            firsts.append(robot.estimate.across)
        return robot, firsts

    robot, firsts = started('centred')
    assert given == [(0.0, 0.0)] * (CONFIRMED + 2) + [None]
    assert robot.placed and robot.confirmed == CONFIRMED + 1
    robot.reset()
    given.clear()
    robot(beside, 10.0)
    assert given == [None]  # placed once: a lane lost later is searched for as before
    given.clear()
    _, default_firsts = started()
    assert given == [(0.0, 0.0)] * (CONFIRMED + 2) + [None]
    assert default_firsts == firsts
    given.clear()
    free, free_firsts = started('none')
    assert given == [None] * (CONFIRMED + 3)
    assert free_firsts[0] == pytest.approx(-0.3 * w, abs=0.005)
    assert -0.25 * w < firsts[0] < -0.05 * w  # pulled towards the robot, not onto it


def test_latency_steers_on_the_lane_where_it_will_be_when_the_command_acts():
    """With `latency`, the command is the one for the lane moved on by the last command for
    that long (predict), and the estimate kept is the one measured; 0 steers on it as it is."""
    w = DT.lane_width
    pieces = frame(line_pieces(0.02 + w / 2, 'yellow', dashed=True) +
                   line_pieces(0.02 - w / 2, 'white'))
    commands = {}
    for latency in (0.0, 0.13):
        ctl = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0,
                                                              latency=latency))
        ctl(pieces, 0.0)
        ctl.sent(SimpleNamespace(linear_x=0.2, angular_z=0.8))  # turning left, off the lane
        measured = ctl.estimate
        commands[latency] = ctl.command()
        assert ctl.estimate is measured
    ctl.estimate = predict(measured, 0.2 * 0.13, 0.8 * 0.13)
    ahead = ctl.seen()
    assert (commands[0.13].linear_x, commands[0.13].angular_z) == ahead
    ctl.estimate = measured
    assert (commands[0.0].linear_x, commands[0.0].angular_z) == ctl.seen()
    assert commands[0.13].angular_z < commands[0.0].angular_z - 0.05  # turned further: back
    remembering = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown',
                                                                  latency=0.13))
    remembering(pieces, 0.0)
    remembering.sent(SimpleNamespace(linear_x=0.2, angular_z=0.8))
    memory, pose = remembering.memory, remembering.memory.pose.copy()
    remembering.command()
    assert remembering.memory is memory and np.array_equal(memory.pose, pose)


def seen_through(pieces, matrix, camera, given):
    """The pieces as the controller finds them when the camera is mounted as `camera` but it
    is told `given`: each point to its pixel, and that pixel back to the floor."""
    from lanelib.geometry import floor_to_pixels, pixels_to_floor

    out = []
    for p in pieces:
        u, v, _ = floor_to_pixels(p.x, p.y, matrix, camera)
        x, y, _ = pixels_to_floor(np.stack([u, v], axis=-1), matrix, given)
        out.append(Piece(x, y, math.atan2(y[-1] - y[0], x[-1] - x[0]), p.colour,
                         float(np.hypot(np.diff(x), np.diff(y)).sum()), p.width))
    return out


def test_a_camera_pitched_off_its_mounting_is_corrected_from_the_splay_of_the_lines():
    """A camera looking 3 degrees further down than its mounting says draws the floor
    stretched, the lines splayed: with pitch_tolerance the controller learns the pitch from
    the splay, frame after frame, and then places the lane, from one line too, where it is;
    without, the lane is fitted turned and bending, and one line alone tilted."""
    from lanelib.geometry import Mounting

    w = DT.lane_width
    given = Mounting(0.108, 19.15, 0.066)
    camera = Mounting(0.108, 22.15, 0.066)
    matrix = np.array([[320.0, 0, 320], [0, 320.0, 240], [0, 0, 1]])
    left = line_pieces(0.01 + w / 2, 'yellow', along=(0.15, 0.7), dashed=True)
    right = line_pieces(0.01 - w / 2, 'white', along=(0.15, 0.7))
    both = frame(seen_through(left + right, matrix, camera, given))
    alone = frame(seen_through(right, matrix, camera, given))
    mounted = dict(lane='duckietown', memory=0.0, camera_height=0.108, camera_pitch=19.15,
                   camera_forward=0.066, one_line_width='measured', smoothing=1.0)
    estimates = {}
    for tolerance in (0.0, 4.0):
        ctl = ImprovedController(LaneParams(), ImprovedParams(**mounted,
                                                              pitch_tolerance=tolerance))
        for _ in range(25):
            ctl(both, None)
            ctl.sent(SimpleNamespace(linear_x=0.0, angular_z=0.0))  # standing still
        learned, two = ctl.pitch_error, ctl.estimate
        ctl(alone, None)
        estimates[tolerance] = (learned, two, ctl.estimate, ctl.extra()['pitch_error_deg'])
        assert ctl.mounting.pitch_deg == pytest.approx(19.15 + learned)  # the lane drawn so
    learned, two, one, recorded = estimates[4.0]
    assert learned == pytest.approx(3.0, abs=0.3) and recorded == round(learned, 2)
    for e in (two, one):
        assert e.offset == pytest.approx(-0.01, abs=0.002) and abs(math.degrees(e.heading)) < 0.3
    learned, two, one, recorded = estimates[0.0]
    assert learned == 0.0 and recorded == 0.0
    # the splay fitted as a lane turned and bending (-3.4 degrees), and one line's as a tilt
    assert abs(math.degrees(two.heading)) > 2.0 and abs(math.degrees(one.heading)) > 1.0


def test_a_camera_pitched_beyond_the_tolerance_is_told_once():
    """The correction held at its limit for improved.PITCH_NOTICE seconds says, once, that the
    camera is further off its mounting than pitch_tolerance lets it correct, which way, and
    what to do; a camera within the tolerance, or no correction at all, says nothing."""
    from lanelib.geometry import Mounting
    from lanelib.improved import PITCH_NOTICE

    w = DT.lane_width
    given = Mounting(0.108, 19.15, 0.066)
    matrix = np.array([[320.0, 0, 320], [0, 320.0, 240], [0, 0, 1]])
    mounted = dict(lane='duckietown', memory=0.0, camera_height=0.108, camera_pitch=19.15,
                   camera_forward=0.066, one_line_width='measured', smoothing=1.0)
    for off, tolerance, told in ((6.0, 4.0, True), (-6.0, 4.0, True), (2.0, 4.0, False),
                                 (6.0, 0.0, False)):
        camera = Mounting(0.108, 19.15 + off, 0.066)
        lines = (line_pieces(0.01 + w / 2, 'yellow', along=(0.15, 0.7), dashed=True) +
                 line_pieces(0.01 - w / 2, 'white', along=(0.15, 0.7)))
        seen = frame(seen_through(lines, matrix, camera, given))
        ctl = ImprovedController(LaneParams(), ImprovedParams(**mounted,
                                                              pitch_tolerance=tolerance))
        said, held = [], []
        for _ in range(60):  # 15 s at the lecture's 4 Hz
            ctl(seen, None)
            ctl.sent(SimpleNamespace(linear_x=0.0, angular_z=0.0))
            said.append(ctl.notice())
            held.append(ctl.at_limit)
        notices = [i for i, text in enumerate(said) if text]
        if not told:
            assert notices == [] and abs(ctl.pitch_error) < 4.0
            continue
        assert abs(ctl.pitch_error) == 4.0
        # once: on the first frame after PITCH_NOTICE seconds at the limit
        assert notices == [next(i for i, t in enumerate(held) if t >= PITCH_NOTICE)]
        text = said[notices[0]]
        assert ('further down' if off > 0 else 'less far down') in text
        assert f'({ctl.pitch_error:+g} deg' in text and '19.15 degrees' in text
        assert 'calibration.py --ground' in text and '--pitch-tolerance' in text


def test_follows_compares_the_headings_at_the_robot():
    from lanelib.estimate import follows

    ahead = LaneEstimate(0.0, 0.0, 0.0, 1.0)
    assert follows(ahead, LaneEstimate(0.05, -math.tan(0.49), 0.0, 1.0), 0.5)
    assert not follows(ahead, LaneEstimate(0.0, math.tan(0.51), 0.0, 1.0), 0.5)
    assert follows(ahead, LaneEstimate(0.0, math.tan(1.2), 0.0, 1.0), 0.0)  # 0: off


def path_pieces(arc, bend, side, colour, lengths=(0.12, 0.8), step=0.06):
    """Pieces of the lane's line on `side` (+1 left, -1 right) of the centre line arc + bend
    (lanefit.centre_path), between arc lengths lengths[0] and lengths[1]."""
    pieces, half = [], DT.lane_width / 2
    for s0 in np.arange(lengths[0], lengths[1], step):
        x, y, h = centre_path(arc, np.linspace(s0, s0 + step, 20), bend)
        x, y = x - side * half * np.sin(h), y + side * half * np.cos(h)
        pieces.append(Piece(x, y, float(np.mean(h)), colour, step, 0.03))
    return pieces


def test_the_bent_centre_line_is_the_arc_until_the_bend_and_goes_on_from_it():
    x, y = np.array([0.2, 0.5, 0.9]), np.array([0.05, -0.1, 0.3])
    arc = (0.02, 0.1, 1.5)
    # the same curvature after the bend: the one arc
    assert bent_distance(x, y, arc, (0.3, 1.5)) == pytest.approx(signed_distance(x, y, *arc))
    s = np.array([0.3 - 1e-6, 0.3 + 1e-6, 0.5])
    px, py, h = centre_path(arc, s, (0.3, -4.0))
    assert (px[1], py[1]) == pytest.approx((px[0], py[0]), abs=1e-5)  # no jump
    assert h[2] - h[1] == pytest.approx(-4.0 * 0.2, abs=1e-4)  # bending k2 after
    # a point on the second arc is at distance 0 from the bent line, not from the one arc
    assert bent_distance(px[2:], py[2:], arc, (0.3, -4.0)) == pytest.approx([0.0], abs=1e-9)
    assert abs(signed_distance(px[2:], py[2:], *arc)[0]) > 0.05


def test_bent_lines_measured_side_by_side_are_each_measured_alone():
    # the bend fit evaluates all its starts and their steps in one array (_bent_distances):
    # each row is the distance from the first arc up to s0 and from the second one after
    x, y = np.linspace(0.1, 1.0, 12), np.linspace(-0.2, 0.3, 12)
    lines = np.array([[0.02, 0.1, 1.5, -4.0, 0.3], [-0.05, -0.3, 0.0, 2.0, 0.5],
                      [0.0, 0.0, 5e-5, 0.0, 0.2], [0.1, 0.4, -2.0, -2.0, 0.7]])
    together = lanefit._bent_distances(x, y, lines)
    for (e, psi, k, k2, s0), row in zip(lines, together):
        (x0,), (y0,), (h0,) = centre_path((e, psi, k), [s0])
        after = lanefit._along(x, y, e, psi, k) > s0
        alone = np.where(after, signed_distance(x - x0, y, y0, h0, k2),
                         signed_distance(x, y, e, psi, k))
        assert row == pytest.approx(alone, abs=1e-9)
        assert bent_distance(x, y, (e, psi, k), (s0, k2)) == pytest.approx(row, abs=1e-12)
    assert np.abs(together[1] - signed_distance(x, y, *lines[1, :3])).max() > 0.05  # bent
    # with no line straight the straight forms are left out: the same numbers, to the bit
    assert np.array_equal(lanefit._bent_distances(x, y, lines[[0, 3]]), together[[0, 3]])


def test_the_centre_points_of_all_pieces_are_each_pieces_own():
    # _centre_points moves every piece's points in one array: each point as its piece alone
    # would be moved, straight or with a bend
    pieces = [Piece(np.linspace(0.2, 0.5, 9) + 0.1 * i, np.linspace(0.1, 0.15, 9) * (-1) ** i,
                    0.1, 'white', 0.3, 0.03) for i in range(4)]
    sides = np.array([1, -1, 0, 1])
    lane = np.array([0.01, 0.05, 1.2, 0.24])
    for bend in (None, (0.4, -2.0)):
        together = lanefit._centre_points(pieces, sides, lane, bend)
        alone = [lanefit._centre_points([p], [s], lane, bend) for p, s in zip(pieces, sides) if s]
        for got, want in zip(together, zip(*alone)):
            assert np.array_equal(got, np.concatenate(want))


def test_a_bend_ahead_of_a_straight_leaves_the_robot_aligned_with_its_lane(monkeypatch):
    """A Duckietown corner seen from its straight: straight for 0.35 m, then a right bend of
    radius 0.2 m, the yellow line alone in view (the white inside of the bend out of view).
    One arc through the robot fits it only turned far off the robot's heading; two arcs
    leave the robot where it is (aligned, 1 cm right of the centre) and the bend ahead."""
    arc, bend = (-0.01, 0.0, 0.0), (0.35, -5.0)
    pieces = path_pieces(arc, bend, +1, 'yellow')
    est, fit = measure(pieces, DT, P)
    assert est.bend is not None and est.bend[1] == pytest.approx(-5.0, rel=0.25)
    assert abs(math.degrees(est.heading)) < 4 and est.offset == pytest.approx(0.01, abs=0.01)
    assert est.lateral_at(0.6) < -DT.lane_width / 2  # the lane goes right
    monkeypatch.setattr(lanefit, 'BEND_GAIN', 0.0)  # no bend: the one arc
    one, _ = measure(pieces, DT, P)
    assert one.bend is None and abs(math.degrees(one.heading)) > 15


def test_a_bend_tighter_than_the_lane_allows_is_no_bend():
    # a line bending so tightly that the lane's centre would have a radius under half the
    # lane's width (its inner line turning back on itself): fitted, it would be such a bend
    k2 = -1.5 * 2 / DT.lane_width
    est, _ = measure(path_pieces((0.0, 0.0, 0.0), (0.35, k2), +1, 'yellow'), DT, P)
    assert est.bend is None or abs(est.bend[1]) * DT.lane_width / 2 < 1


def test_a_straight_lane_has_no_bend():
    half = DT.lane_width / 2
    est, _ = measure(line_pieces(half, 'yellow', dashed=True) + line_pieces(-half, 'white'),
                     DT, P)
    assert est.bend is None


@pytest.mark.parametrize('limits', [(0.2, 0.3), (0.25, 0.25), (0.2, 0.3, 0.1)])
def test_the_linearised_bend_is_the_weighted_least_squares_one(limits):
    """lanefit._bend_gain: what the one arc's derivatives (the width's and spread's where
    free) and a bend's (s - s0)^2 / 2 past the best knot take away from the weighted squared
    residuals, as np.linalg.lstsq solves it knot by knot."""
    rng = np.random.default_rng(len(limits) + int(limits[0] == limits[1]))
    lane = np.array([0.02, 0.1, 0.8, 0.25] + ([0.05] if len(limits) > 2 else []))
    x = rng.uniform(0.15, 0.9, 36)
    y = 0.1 * x + rng.normal(0, 0.02, 36)
    on, w = rng.choice([-1.0, 1.0], 36), rng.uniform(0.02, 0.1, 36)
    d, slopes = lanefit._distances(x, y, lane[None, :], jacobian=True)
    r = d[0] - on * lanefit._halves(lane[None, :], x)[0]
    knots = np.array([0.3, 0.5, 0.7])
    got = lanefit._bend_gain(x, y, on, w, lane, limits, r, slopes[0], knots)
    columns = [slopes[0]] + ([] if limits[0] == limits[1] else [-on[:, None] / 2]) + (
        [-on[:, None] * x[:, None] / 2] if len(limits) > 2 else [])
    s = lanefit._along(x, y, *lane[:3])
    left = []
    for s0 in knots:
        a = np.hstack(columns + [(np.maximum(s - s0, 0.0) ** 2 / 2)[:, None]])
        a, b = a * np.sqrt(w)[:, None], r * np.sqrt(w)
        left.append(((a @ np.linalg.lstsq(a, b, rcond=None)[0] - b) ** 2).sum())
    assert w @ r ** 2 - got == pytest.approx(min(left), rel=1e-6, abs=1e-12)


def test_the_bend_is_fitted_only_where_a_linearised_bend_fits_much_better(monkeypatch):
    """A bend seen from its straight passes the screen (BEND_SCREEN) and is fitted; a straight
    lane whose pieces lie a few millimetres off their line at random (more than BEND_FLOOR)
    does not: no two-arc evaluation is made for it, and fitted anyway it keeps no bend."""
    calls = []
    bent_distances = lanefit._bent_distances
    monkeypatch.setattr(lanefit, '_bent_distances', lambda *a: calls.append(1) or
                        bent_distances(*a))
    bend = path_pieces((-0.01, 0.0, 0.0), (0.35, -5.0), +1, 'yellow')
    est, _ = measure(bend, DT, P)
    assert est.bend is not None and calls
    rng = np.random.default_rng(4)
    half = DT.lane_width / 2
    pieces = [Piece(p.x, p.y + rng.normal(0, 0.006), p.phi, p.colour, p.length, p.width)
              for p in line_pieces(half, 'yellow', dashed=True) + line_pieces(-half, 'white')]
    _, fit = measure(pieces, DT, P)
    points = lanefit._points(pieces, 2.6 * DT.lane_width)
    on = np.repeat(fit.sides, lanefit.POINTS)
    lane = np.array([fit.e, fit.psi, fit.k, fit.width])
    d = lanefit._distances(*points[:2], lane[None, :])[0][0] - on * fit.width / 2
    assert ((on != 0) * points[2] @ d ** 2 / ((on != 0) * points[2]).sum()) ** 0.5 > (
        lanefit.BEND_FLOOR * DT.lane_width)  # beyond the floor: the screen decides
    calls.clear()
    est, _ = measure(pieces, DT, P)
    assert est.bend is None and not calls
    monkeypatch.setattr(lanefit, 'BEND_SCREEN', math.inf)
    est, _ = measure(pieces, DT, P)
    assert est.bend is None and calls


def test_robot_offset_is_the_distance_across_the_arc():
    assert robot_offset(0.2, math.radians(-60), 0.0) == pytest.approx(0.1)
    assert robot_offset(-0.2, math.radians(60), 0.0) == pytest.approx(-0.1)
    # a left bend of radius 0.5 through (0, 0.1): its centre (0, 0.6), the robot 0.6 from it
    assert robot_offset(0.1, 0.0, 2.0) == pytest.approx(0.1)
    assert robot_offset(-0.1, 0.0, 2.0) == pytest.approx(-0.1)  # centre (0, 0.4), robot 0.4
    assert robot_offset(0.0, 0.7, -3.0) == pytest.approx(0.0)  # on the arc


# ---------------------------------------------------------------- predict and blend

def test_predict_moves_the_lane_with_the_robot():
    straight = LaneEstimate(0.05, 0.0, 0.0, 1.0)
    turned = predict(straight, 0.2, math.radians(10))  # 20 cm on, turned 10 degrees left
    # the parallel lane 5 cm to the left, now crossed obliquely by the robot's sideways axis
    assert turned.a == pytest.approx(0.05 / math.cos(math.radians(10)))
    assert math.degrees(turned.heading) == pytest.approx(10)  # the lane to the right
    bend = LaneEstimate(0.0, 0.0, 0.5, 1.0)  # curvature 1 / m to the left: centre (0, 1)
    ahead = predict(bend, 0.2, 0.0)
    assert ahead.a == pytest.approx(1 - math.sqrt(1 - 0.2 ** 2))  # where x = 0.2 meets it
    assert ahead.b == pytest.approx(0.2 / math.sqrt(1 - 0.2 ** 2))  # its slope there
    assert ahead.curvature == pytest.approx(1.0)
    assert turned.confidence == pytest.approx(0.8)  # a prediction is less sure


def test_predict_keeps_the_lanes_curvature_as_the_robot_turns_to_follow_it():
    # a bend of radius 0.5 m turned 45 degrees right of the robot: the robot turns in place
    # to line up with it. The arc is the same arc; its curvature stays 2 / m (the parabola's
    # c, held, made it 2 (1 + 1)^1.5 = 5.7 / m once the robot was lined up)
    psi, k = math.radians(-45), 2.0
    lane = LaneEstimate(0.0, math.tan(psi), k * (1 + math.tan(psi) ** 2) ** 1.5 / 2, 1.0)
    assert lane.curvature == pytest.approx(k)
    lined_up = predict(lane, 0.0, psi)
    assert (lined_up.a, lined_up.b) == pytest.approx((0.0, 0.0), abs=1e-12)
    assert lined_up.curvature == pytest.approx(k)
    # 0.2 m straight on: the circle (centre 0.5 m to the left) meets the robot's sideways
    # axis where it has turned asin(0.2 / 0.5) left, and still bends 2 / m
    on = predict(lined_up, 0.2, 0.0)
    assert on.a == pytest.approx(0.5 - math.sqrt(0.5 ** 2 - 0.2 ** 2))
    assert on.heading == pytest.approx(-math.asin(0.2 / 0.5))  # the robot right of the lane
    assert on.curvature == pytest.approx(k)
    assert predict(lane, 0.0, math.radians(50)) is None  # turned away: the lane runs across


def test_predict_brings_the_bend_nearer_and_then_drives_into_it():
    ahead = LaneEstimate(0.0, 0.0, 0.0, 1.0, bend=(0.3, -4.0))
    nearer = predict(ahead, 0.1, 0.0)
    assert nearer.bend == pytest.approx((0.2, -4.0)) and nearer.curvature == 0.0
    inside = predict(nearer, 0.25, 0.0)
    assert inside.bend is None and inside.curvature == pytest.approx(-4.0, rel=0.05)


def test_blend_weighs_the_measurement_by_its_weight():
    pred, meas = LaneEstimate(0.0, 0.0, 0.0, 0.5), LaneEstimate(0.1, 0.2, 0.3, 1.0)
    assert blend(pred, meas, 0.0).a == 0.0
    half = blend(pred, meas, 0.5)
    # the lane's offset, heading and curvature each moved half way, and the confidence
    assert (half.a, half.heading, half.curvature, half.confidence) == pytest.approx(
        (0.05, meas.heading / 2, meas.curvature / 2, 0.75))
    assert blend(pred, meas, 1.0).b == pytest.approx(0.2)


def test_blend_moves_the_curvature_by_the_weight_whatever_the_headings():
    # small_loop seed 5 with domain rand, 4.1 s: a straight lane predicted; measured, a lane
    # turned 55 degrees across the view bending 4.76 / m, at weight 0.15. Blended as the
    # parabola's coefficients its c (4.76 (1 + b^2)^1.5 / 2 = 12.4) came over to a lane
    # nearly lined up, which then bent 4.3 / m; as the arc, 0.15 of the way: 0.71 / m
    pred = LaneEstimate(0.0, 0.0, 0.0, 0.5)
    b = math.tan(math.radians(-55))
    meas = LaneEstimate(0.02, b, 4.76 * (1 + b * b) ** 1.5 / 2, 0.25)
    blended = blend(pred, meas, 0.15)
    assert blended.curvature == pytest.approx(0.15 * 4.76)
    assert blended.heading == pytest.approx(0.15 * meas.heading)


def test_blend_takes_a_bend_seen_and_fades_one_not_seen():
    pred = LaneEstimate(0.0, 0.0, 0.0, 0.5, bend=(0.4, -4.0))
    seen = LaneEstimate(0.0, 0.0, 0.0, 1.0, bend=(0.5, 2.0))
    assert blend(pred, seen, 0.3).bend == (0.5, 2.0)  # as measured
    # a bend's entry out of the near view is measured as one arc bent less than the bend:
    # the bend stays where predicted, its curvature moved towards the arc's by the weight
    one_arc = LaneEstimate(0.0, 0.0, -0.5, 1.0)  # curvature -1 / m
    faded = blend(pred, one_arc, 0.25)
    assert faded.bend == pytest.approx((0.4, -4.0 + 0.25 * 3.0))
    assert blend(LaneEstimate(0.0, 0.0, 0.0, 0.5), one_arc, 0.25).bend is None


# ---------------------------------------------------------------- the memory

def test_the_memory_keeps_points_where_they_are_on_the_floor():
    memory = LaneMemory(10.0)
    seen = np.array([1.0, 1.2, 1.4]), np.array([0.1, 0.0, -0.1])
    memory.add(*seen, np.ones(3))
    pose = (0.0, 0.0, 0.0)
    for v, omega in [(0.2, 0.0), (0.2, 0.4), (0.1, -0.6), (0.0, 0.5)]:
        memory.move(v, omega, 0.25)
        pose = arc_step(*pose, v, omega, 0.25)
    x, y, _ = memory.local()
    dx, dy = seen[0] - pose[0], seen[1] - pose[1]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    assert np.allclose(x, c * dx + s * dy, atol=1e-9)
    assert np.allclose(y, -s * dx + c * dy, atol=1e-9)
    memory.move(0.0, 0.0, 10.0)  # older than `seconds`: forgotten
    assert memory.local()[0].size == 0


def test_points_added_to_the_memory_in_hand_are_the_bits_it_would_work_out_afresh():
    rng = np.random.default_rng(3)
    memory = LaneMemory(10.0)
    for step in range(6):
        memory.move(0.2, rng.uniform(-1, 1), 0.125)
        memory.local()  # in hand (the lane's guide asks for it before the frame's points come)
        memory.add(rng.uniform(0.1, 0.6, 50), rng.uniform(-0.2, 0.2, 50), rng.uniform(0, 1, 50))
        kept = memory.local()
        memory._local = None  # worked out afresh from every point
        afresh = memory.local()
        assert all(np.array_equal(a, b) for a, b in zip(kept, afresh))
        assert kept[0].size == 50 * (step + 1)


def test_the_memory_keeps_the_points_of_its_last_seconds_however_its_buffer_grows():
    """Points are added past the buffer's end, forgotten by moving its start, and moved into a
    bigger buffer when it is full: local() is always what the frames of the last `seconds`
    give, worked out from them afresh (each frame's points kept apart), and what it handed out
    before stays as it was."""
    rng = np.random.default_rng(5)
    memory = LaneMemory(1.0)
    frames, pose, t, handed = [], np.zeros(3), 0.0, []
    for _ in range(80):
        v, omega, dt = 0.2, rng.uniform(-1, 1), rng.uniform(0.05, 0.2)
        memory.move(v, omega, dt)
        pose, t = np.array(arc_step(*pose, v, omega, dt)), t + dt
        frames = [f for f in frames if t - f[0] <= 1.0]
        n = int(rng.integers(0, 200))
        x, y, w = rng.uniform(0.1, 0.6, n), rng.uniform(-0.2, 0.2, n), rng.uniform(0, 1, n)
        memory.add(x, y, w)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        frames.append((t, pose[0] + c * x - s * y, pose[1] + s * x + c * y, w))
        X, Y, W = (np.concatenate([f[i] for f in frames]) for i in (1, 2, 3))
        dx, dy = X - pose[0], Y - pose[1]
        got = memory.local()
        assert np.allclose(got[0], c * dx + s * dy) and np.allclose(got[1], -s * dx + c * dy)
        assert np.array_equal(got[2], W)
        handed.append((got[2], W))
    assert all(np.array_equal(a, b) for a, b in handed)  # nothing handed out was overwritten


def test_a_memory_told_most_keeps_that_many_of_a_frames_points_carrying_all_their_weight():
    rng = np.random.default_rng(11)
    x = np.sort(rng.uniform(0.1, 0.9, 1100))
    y = 0.05 + 0.1 * x + 0.3 * x ** 2 + rng.normal(0, 0.004, x.size)  # a bend's centre line
    w = rng.uniform(0.001, 0.003, x.size)
    every, thinned = LaneMemory(10.0), LaneMemory(10.0, most=200)
    for memory in (every, thinned):
        memory.add(x, y, w)
    kept = thinned.local()
    assert kept[0].size == 184 and every.local()[0].size == 1100  # every 6th: 1100 / 6
    assert np.array_equal(kept[0], x[::6]) and np.array_equal(kept[1], y[::6])
    assert kept[2].sum() == pytest.approx(w.sum(), rel=1e-12)  # the frame's whole weight
    # the fits the memory makes on the thinned points are those of all of them, within
    # millimetres on this centre line: at the look-ahead and about the robot
    for near, far in [(0.2, 0.54), (-0.14, 0.27)]:
        a, b, c = every.centre_line(near, far, 0.1)
        ta, tb, tc = thinned.centre_line(near, far, 0.1)
        for at in (near, (near + far) / 2, far):
            assert abs((ta + tb * at + tc * at * at) - (a + b * at + c * at * at)) < 0.002
    few = LaneMemory(10.0, most=200)  # a frame with fewer points than that keeps all of them
    few.add(x[:150], y[:150], w[:150])
    assert np.array_equal(few.local()[2], w[:150])


def test_the_memory_fits_the_centre_line_ahead_and_an_arc_round_a_u_turn():
    memory = LaneMemory(10.0)
    r = 0.5
    s = np.linspace(0.0, 0.5, 30)  # from the robot into a bend to the left
    memory.add(r * np.sin(s / r), r * (1 - np.cos(s / r)), np.ones_like(s))
    a, b, c = memory.centre_line(0.1, 0.3, 0.1)
    assert a + b * 0.2 + c * 0.04 == pytest.approx(r - math.sqrt(r * r - 0.04), abs=0.005)
    s = np.linspace(0.5, 1.5, 60)  # and on round a U-turn
    memory.add(r * np.sin(s / r), r * (1 - np.cos(s / r)), np.ones_like(s))
    arc, _ = memory.arc((0.0, 0.0, 1.5), 1.0, 0.06)  # from the bend as estimated
    assert arc[2] == pytest.approx(1 / r, rel=0.05) and abs(arc[0]) < 0.01
    assert memory.centre_line(2.0, 3.0, 0.1) is None  # nothing remembered there


def test_the_line_about_the_robot_takes_distances_square_to_it():
    """LaneMemory.line_about (memory_anchor 'line'): the weighted principal axis of the points
    within reach, as (offset at the robot, heading). On a lane turned 0.9 rad, its points
    1.2 cm either side of it, it is the lane; the parabola's distances, taken across the
    robot's heading, flatten it (what a corner's way out, running across the view, does to
    the lane at the robot)."""
    memory = LaneMemory(10.0)
    e, psi = -0.02, 0.9
    t = np.linspace(-0.12, 0.3, 60)
    side = np.where(np.arange(t.size) % 2, 0.012, -0.012)
    memory.add(t * math.cos(psi) - side * math.sin(psi),
               e + t * math.sin(psi) + side * math.cos(psi), np.ones_like(t))
    far = np.linspace(0.5, 0.8, 10)  # beyond reach: not used
    memory.add(far, np.full_like(far, 0.5), np.ones_like(far))
    offset, heading = memory.line_about(0.27, 0.1)
    assert offset == pytest.approx(e, abs=0.001) and heading == pytest.approx(psi, abs=0.001)
    a, b, _ = memory.centre_line(-0.135, 0.27, 0.135)
    assert psi - math.atan(b) > 0.01
    assert memory.line_about(0.27, 0.5) is None  # spans less than that along the line
    assert memory.line_about(0.015, 0.001) is None  # fewer than ENOUGH points within reach
    across = LaneMemory(10.0)  # a line across the robot's heading has no offset at the robot
    across.add(np.full(20, 0.1), np.linspace(-0.1, 0.1, 20), np.ones(20))
    assert across.line_about(0.27, 0.1) is None


def test_the_memory_anchor_reads_the_lane_at_the_robot_with_the_model_asked_for():
    """memory_anchor: the anchor is centre_line's parabola (offset, atan of its slope) or
    line_about's line, from the points about the robot (ANCHOR)."""
    w = DT.lane_width
    x = np.linspace(-0.5 * w, 1.1 * w, 40)
    y = -0.1 * w + 0.3 * x + 0.4 * x ** 2
    for model in ('parabola', 'line'):
        robot = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown',
                                                                memory_anchor=model))
        robot.memory.add(x, y, np.ones_like(x))
        memory = robot.memory
        if model == 'line':
            expected = memory.line_about(ANCHOR[1] * w, ANCHOR[2] * w)
        else:
            a, b, _ = memory.centre_line(*(v * w for v in ANCHOR))
            expected = (a, math.atan(b))
        assert robot.anchored() == pytest.approx(expected, abs=1e-12)
    empty = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown',
                                                            memory_anchor='line'))
    assert empty.anchored() is None


def test_the_centre_fit_is_the_ridged_least_squares_parabola():
    # fit_centre solves the normal equations from the points' moments: the same parabola as
    # least squares on the design matrix with the ridge's rows
    rng = np.random.default_rng(3)
    x = rng.uniform(0.2, 0.6, 400)
    y = 0.05 - 0.3 * x + 1.2 * x ** 2 + rng.normal(0.0, 0.01, x.size)
    w = rng.uniform(0.2, 1.0, x.size)
    u = x - 0.4
    rows = np.vstack([np.stack([np.ones_like(u), u, u ** 2], axis=1) * np.sqrt(w)[:, None],
                      np.diag(np.sqrt([0.0, 1e-4, 0.05]) * math.sqrt(w.sum()))])
    a, b, c = np.linalg.lstsq(rows, np.concatenate([y * np.sqrt(w), np.zeros(3)]), rcond=None)[0]
    assert fit_centre(x, y, w, x0=0.4) == pytest.approx(
        (a - 0.4 * b + 0.16 * c, b - 0.8 * c, c), abs=1e-9)


# ---------------------------------------------------------------- the steering law

@pytest.mark.parametrize('angle', [False, True])
@pytest.mark.parametrize('alpha', [1.0, 3.0])
@pytest.mark.parametrize('radius', [1.0, -1.5, 3.0])
def test_on_a_circle_the_law_commands_its_curvature(radius, alpha, angle):
    # the robot on the centre line of a bend, looking a little way ahead: both terms 1/R,
    # whether the line's direction is read as its slope or its angle
    x = 0.1 * abs(radius)
    y = radius - math.copysign(math.sqrt(radius * radius - x * x), radius)
    slope = x / math.copysign(math.sqrt(radius * radius - x * x), radius)
    assert curvature(x, y, slope, alpha, angle) == pytest.approx(1 / radius, rel=0.02)


@pytest.mark.parametrize('angle', [False, True])
@pytest.mark.parametrize('radius', [0.6, -0.75])
def test_far_round_a_tight_bend_the_slope_turns_against_it_and_its_angle_does_not(radius, angle):
    """The robot on the centre line of a bend, steering at a point 0.9 of the radius ahead
    (the Kobuki's 0.55 m on a 0.6 m bend): the slope there, weighed by 1 - alpha, outgrows the
    offset and the law turns the robot out of the bend; read as an angle it turns into it,
    harder than the bend (the over-steer that makes up for a bend read straighter than it is)."""
    x = 0.9 * abs(radius)
    root = math.copysign(math.sqrt(radius * radius - x * x), radius)
    y, slope = radius - root, x / root
    k = curvature(x, y, slope, 3.0, angle=angle)
    if angle:
        assert k * radius > 1.0  # into the bend, by more than 1/R
    else:
        assert k * radius < 0.0  # out of it
    # pure pursuit (alpha 1) reads only the point, and turns into the bend either way
    assert curvature(x, y, slope, 1.0, angle=angle) == curvature(x, y, 0.0, 1.0)
    assert curvature(x, y, slope, 1.0) * radius > 1.0


@pytest.mark.parametrize('alpha', [1.0, 3.0])
@pytest.mark.parametrize('c', [1.5, -2.0])
def test_a_bend_beginning_before_the_point_turns_the_robot_against_it_past_a_third(c, alpha):
    """The robot on the centre line of a straight that bends (y = c (x - s0)^2) s0 ahead: the
    law gives 2 c u (alpha u + 1 - alpha), u = (x - s0) / x; with alpha 3 it turns the robot
    against the bend wherever the bend begins beyond a third of the way to the point (the
    module doc's second limit); pure pursuit turns into it wherever it begins."""
    x = 0.45
    for s0 in (0.05, 0.1, 0.2, 0.3, 0.4):
        u = (x - s0) / x
        k = curvature(x, c * (x - s0) ** 2, 2 * c * (x - s0), alpha)
        assert k == pytest.approx(2 * c * u * (alpha * u + 1 - alpha))
        assert (k * c > 0) == (alpha == 1.0 or s0 < x / 3)


def test_steer_reads_the_direction_as_the_settings_say():
    p = ImprovedParams().in_metres(0.35)
    assert p.direction == 'slope'  # the default; 'angle' on request
    for direction, angle in (('angle', True), ('slope', False)):
        q = replace(p, direction=direction)
        assert steer(0.5, 0.02, 1.2, 1.0, q) == command(curvature(0.5, 0.02, 1.2, 3.0, angle),
                                                       1.0, q)
    assert steer(0.5, 0.02, 1.2, 1.0, p) != steer(0.5, 0.02, 1.2, 1.0,
                                                  replace(p, direction='angle'))


def test_alpha_1_is_pure_pursuit_and_alpha_weighs_the_offset():
    assert curvature(0.8, 0.1, 5.0, 1.0) == pytest.approx(2 * 0.1 / 0.8 ** 2)
    # parallel and 10 cm to the left: alpha 3 turns three times as hard as pure pursuit
    assert curvature(0.8, 0.1, 0.0, 3.0) == pytest.approx(3 * curvature(0.8, 0.1, 0.0, 1.0))
    assert curvature(0.0, 0.1, 0.0, 3.0) == 0.0  # a point not ahead: no turn


def test_speed_and_turn_rate_are_bounded():
    p = ImprovedParams(omega_max=0.5).in_metres(0.35)
    v, omega = command(0.0, 1.0, p)
    assert (v, omega) == (pytest.approx(p.v_max), 0.0)
    assert command(0.0, 0.0, p)[0] == pytest.approx(0.5 * p.v_max)  # unsure: half speed
    assert command(0.0, 0.5, p)[0] == pytest.approx(0.75 * p.v_max)
    calmer = replace(p, unsure_slowdown=0.25)  # a quarter off at confidence 0
    assert command(0.0, 0.0, calmer)[0] == pytest.approx(0.75 * p.v_max)
    assert command(0.0, 1.0, calmer)[0] == pytest.approx(p.v_max)
    v, omega = command(100.0, 1.0, p)
    assert v == pytest.approx(p.v_min) and omega == 0.5  # never below v_min, saturated
    assert command(-100.0, 1.0, p)[1] == -0.5
    assert steer(0.8, 0.1, 0.0, 1.0, p) == command(curvature(0.8, 0.1, 0.0, 3.0), 1.0, p)


def test_a_bend_ahead_slows_as_the_turn_asked_would_and_turns_nothing():
    """command's bend (slow_ahead: the sharpest curvature of the lane ahead) slows the robot
    as a turn asked of that curvature would, either way round, and leaves the turn rate the
    turn asked's; the sharper of the two slows it."""
    p = ImprovedParams().in_metres(0.35)
    assert command(0.5, 1.0, p, bend=0.0) == command(0.5, 1.0, p)
    v, omega = command(0.0, 1.0, p, bend=-4.0)
    assert v == pytest.approx(command(4.0, 1.0, p)[0]) and v < p.v_max and omega == 0.0
    assert command(0.0, 1.0, p, bend=4.0) == (v, omega)
    assert command(6.0, 1.0, p, bend=4.0) == command(6.0, 1.0, p)  # the turn asked is sharper
    assert steer(0.8, 0.1, 0.0, 1.0, p, bend=3.0) == command(curvature(0.8, 0.1, 0.0, 3.0), 1.0,
                                                              p, 3.0)


def test_the_sharpest_bend_within_a_distance_reads_the_arc_and_the_bend_begun_by_then():
    est = LaneEstimate(0.0, 0.0, -0.5, 1.0, bend=(0.4, 5.0))  # bends right 1 /m, then left 5
    assert est.bent_within(0.3) == pytest.approx(1.0)  # the bend begins beyond
    assert est.bent_within(0.5) == pytest.approx(5.0)
    assert LaneEstimate(0.0, 0.0, 0.5, 1.0).bent_within(10.0) == pytest.approx(1.0)


def test_slow_ahead_slows_the_controller_before_a_bend_it_does_not_yet_turn_for():
    """With slow_ahead (lane widths, like the distances) a lane straight at the robot that bends
    within that distance slows the robot as the bend would; beyond it, or without the setting,
    the speed is the straight's. The turn asked (its curvature: angular.z / linear.x) is the
    same."""
    w = DT.lane_width
    bend = LaneEstimate(0.0, 0.0, 0.0, 1.0, bend=(2.0 * w, -4.0))
    moves = {}
    for ahead in (0.0, 1.5, 2.57):
        c = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0,
                                                            slow_ahead=ahead))
        c.estimate, c.lost_for = bend, 0.0  # a lane in view
        moves[ahead] = c.command()
    assert moves[2.57].linear_x < moves[0.0].linear_x  # the bend begins within 2.57 w
    assert moves[2.57].linear_x == pytest.approx(
        command(-4.0, 1.0, ImprovedParams(lane='duckietown').in_metres(w))[0])
    assert moves[1.5].linear_x == moves[0.0].linear_x  # it begins beyond 1.5 w
    asked = [move.angular_z / move.linear_x for move in moves.values()]
    assert asked == pytest.approx([asked[0]] * 3)


def test_one_line_is_placed_half_the_width_last_measured_beside_it():
    """With both lines in view the width between them is measured (a camera pitched a little
    off, a track taped a little wider, make it more than the profile's); with one line left in
    view the lane lies half that width beside it, not half the profile's, so the robot's offset
    does not jump when a line leaves the view; a width given beyond width_tolerance is held at
    its bound."""
    w = DT.lane_width * 1.2
    both, _ = measure(line_pieces(w / 2, 'yellow', dashed=True) + line_pieces(-w / 2, 'white'),
                      DT, P)
    assert both.width == pytest.approx(w, abs=0.005) and abs(both.offset) < 0.005
    one, _ = measure(line_pieces(-w / 2, 'white'), DT, P, width=both.width)
    assert one.offset == pytest.approx(0.0, abs=0.005) and one.width == pytest.approx(w, abs=0.005)
    profile, _ = measure(line_pieces(-w / 2, 'white'), DT, P)  # no width measured yet
    assert profile.offset == pytest.approx((w - DT.lane_width) / 2, abs=0.005)
    held, _ = measure(line_pieces(-w / 2, 'white'), DT, P, width=3 * DT.lane_width)
    assert held.width == pytest.approx((1 + P.width_tolerance) * DT.lane_width, abs=0.005)


@pytest.mark.parametrize('one_line_width', ['measured', 'profile'])
def test_the_controller_carries_the_width_measured_into_frames_with_one_line(one_line_width):
    """With one_line_width 'measured' the controller gives measure the width last measured with
    both lines in view, and only such a frame changes it (a one-line fit's width is only what
    it was given, moved by the pull towards the lane expected: carried on, it crept to its
    bound, 1.3 lane widths, in the benchmark's lecture world); with 'profile' (the default)
    one line is placed half the profile's width from the lane."""
    w = DT.lane_width * 1.2
    both = frame(line_pieces(w / 2, 'yellow', dashed=True) + line_pieces(-w / 2, 'white'))
    white = frame(line_pieces(-w / 2, 'white'))
    controller = ImprovedController(LaneParams(), ImprovedParams(
        lane='duckietown', memory=0.0, one_line_width=one_line_width))
    controller(both, 0.0)
    assert controller.width == pytest.approx(w, abs=0.005)
    for t in (0.125, 0.25, 0.375):
        controller(white, t)
        assert controller.width == pytest.approx(w, abs=0.005)  # one line does not change it
        if one_line_width == 'measured':
            assert controller.estimate.width == pytest.approx(w, abs=0.005)
            assert abs(controller.estimate.offset) < 0.005
        else:  # the profile's width, not the one measured (the lane moves sideways)
            assert controller.estimate.width < w - 0.02


def test_a_lane_found_half_a_lane_beside_the_prediction_is_no_lane_until_the_estimate_is_stale():
    """The robot moves across its lane a few centimetres a frame: a lane found shift_gate lane
    widths or more beside the one predicted (the neighbour's lines, or one line taken for the
    other) is not taken, and the frame counts as one with no lane; a lane nearer is blended;
    once the estimate is stale (lost_timeout) a lane beside is taken."""
    w, lane = DT.lane_width, lane_beside

    def robot(**gate):  # the lane found, and followed for CONFIRMED frames
        r = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0,
                                                            **gate))
        for k in range(CONFIRMED + 1):
            r(lane(0.0), k * 0.125)
        assert abs(r.estimate.across) < 0.01 and r.lost_for == 0.0
        return r

    t = CONFIRMED * 0.125
    gated = robot(shift_gate=0.5)
    assert gated.p.shift_gate == pytest.approx(0.5 * w)  # in lane widths, like the distances
    gated(lane(w), t + 0.125)  # the next lane's lines a frame later: not the lane
    assert gated.lost_for == pytest.approx(0.125) and gated.sides is None
    assert abs(gated.estimate.across) < 0.01
    gated(lane(0.2 * w), t + 0.25)  # 0.2 lane widths over: the lane, blended
    assert gated.lost_for == 0.0 and 0.01 < gated.estimate.across < 0.2 * w
    t += 0.25
    while gated.lost_for <= 1.0:  # lost_timeout: the estimate is stale
        t += 0.125
        gated(lane(w), t)
    gated(lane(0.7 * w), t + 0.125)  # (within REGAINED of it: the lane lost)
    assert gated.lost_for == 0.0 and gated.estimate.across > 0.3 * w
    ungated = robot()  # off, the default: the next lane's lines are blended at once
    ungated(lane(w), CONFIRMED * 0.125 + 0.125)
    assert ungated.lost_for == 0.0 and ungated.estimate.across > 0.3 * w


def test_a_lane_only_just_found_gives_way_to_the_lane_found_next():
    """The gates defend a lane once CONFIRMED frames' lanes have followed it: a first frame (or
    the first after driving blind) can take the wrong lines for the lane, and defended at once
    it would refuse the true lane for a whole lost_timeout. Until then a lane found beyond the
    gates replaces it; after, it is refused."""
    w, lane = DT.lane_width, lane_beside

    # no start belief: the first lane is wherever the pieces put it, the next lane's here
    robot = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0,
                                                            shift_gate=0.5, turn_gate=0.5,
                                                            start_belief='none'))
    robot(lane(w), 0.0)  # the first frame's lane: the next lane's lines, taken for the robot's
    assert robot.estimate.across > 0.8 * w and robot.confirmed == 0
    robot(lane(0.0), 0.125)  # its own lane, beyond the shift gate: it replaces that one
    # (blended, the estimate would have moved at most smoothing = 0.6 of the way: 0.6 w left)
    assert robot.lost_for == 0.0 and robot.confirmed == 0 and robot.estimate.across < 0.45 * w
    t = 0.125
    for k in range(1, CONFIRMED + 1):  # followed, frame after frame
        t += 0.125
        robot(lane(0.0), t)
        assert robot.lost_for == 0.0 and robot.confirmed == k
    near = robot.estimate.across
    assert abs(near) < 0.25 * w
    robot(lane(w), t + 0.125)  # now confirmed: the next lane's lines are refused
    assert robot.lost_for == pytest.approx(0.125) and abs(robot.estimate.across - near) < 0.02


@pytest.mark.parametrize('lane', ['duckietown', 'lecture'])
def test_the_robot_drives_along_the_middle_of_the_floor_between_the_tapes(lane):
    """Between a 2.5 cm yellow tape and a 5 cm white one the middle of the floor lies 6.25 mm
    left of the middle between the tapes' centres: a robot there, parallel to the lane, goes
    straight, and one between the centres turns left; with tapes alike (the lecture's) the
    two are one."""
    p = ImprovedParams(lane=lane, memory=0.0)
    ctl = ImprovedController(LaneParams(), p)
    # (5 cm white - 2.5 cm yellow) / 4; the lecture's tapes are both 3 cm
    assert ctl.shift == pytest.approx({'duckietown': 0.00625, 'lecture': 0.0}[lane], abs=1e-12)
    shift = ctl.shift
    ctl.estimate = LaneEstimate(a=-shift, b=0.0, c=0.0, confidence=1.0)  # the robot there
    assert ctl.seen()[1] == pytest.approx(0.0, abs=1e-12)
    ctl.estimate = LaneEstimate(a=0.0, b=0.0, c=0.0, confidence=1.0)  # between the centres
    turn = ctl.seen()[1]
    assert turn == 0.0 if lane == 'lecture' else turn > 0.01
    # on a lane turned 30 degrees the middle of the floor lies `shift` across it, not along
    slope = math.tan(math.radians(30))
    ctl.estimate = LaneEstimate(a=-shift * math.hypot(1, slope), b=slope, c=0.0,
                                confidence=1.0)
    x = ctl.p.lookahead
    assert ctl.seen() == steer(x, slope * x, slope, 1.0, ctl.p)


# ---------------------------------------------------------------- the decision word

def test_bent_away_is_the_lanes_own_bending_not_the_robots_offset_or_heading():
    askew = LaneEstimate(0.03, math.tan(0.3), 0.0, 1.0)  # a straight lane, turned and aside
    assert abs(askew.lateral_at(0.8)) > 0.2 and askew.bent_away(0.8) == pytest.approx(0.0,
                                                                                        abs=1e-9)
    k = 2.0  # an arc from the robot: all of it is bending; at 0.5 m from the robot (a chord
    # of the circle) it has turned 2 asin(k d / 2)
    arc = LaneEstimate(0.0, 0.0, k / 2, 1.0)
    turned = 2 * math.asin(k * 0.5 / 2)
    assert arc.bent_away(0.5) == pytest.approx((1 - math.cos(turned)) / k, rel=0.02)
    ahead = LaneEstimate(0.0, 0.0, 0.0, 1.0, bend=(0.5, 3.0))  # straight, then bending left
    assert ahead.bent_away(0.4) == pytest.approx(0.0, abs=1e-9)
    assert ahead.bent_away(0.8) == pytest.approx(ahead.lateral_at(0.8)) and (
        ahead.bent_away(0.8) > 0.1)


def test_the_word_turns_for_a_bend_seen_beyond_the_look_ahead_and_not_for_one_unseen():
    robot = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown', memory=0.0))
    p = robot.p
    turn = p.turn_offset * p.lane_width
    # straight to just short of the look-ahead, then bending left: at the look-ahead the lane
    # has hardly left the robot's path, by the floor band's far end it has
    bend = (p.lookahead - 0.05, 4.0)
    lane = LaneEstimate(0.0, 0.0, 0.0, 1.0, bend=bend, seen=p.roi_far)
    assert abs(lane.lateral_at(p.lookahead)) < turn < lane.bent_away(p.roi_far)
    robot.estimate = lane
    assert robot.decision() == 'left'
    robot.estimate = replace(lane, bend=(bend[0], -4.0))
    assert robot.decision() == 'right'
    robot.estimate = replace(lane, seen=p.lookahead)  # the lines end at the look-ahead
    assert robot.decision() == 'straight'
    # a straight lane seen far, the robot turned off it: the look-ahead's reading stands
    robot.estimate = LaneEstimate(0.0, math.tan(0.05), 0.0, 1.0, seen=p.roi_far)
    assert robot.decision() == 'straight'
    robot.estimate = LaneEstimate(0.0, math.tan(-0.4), 0.0, 1.0, seen=p.roi_far)
    assert robot.decision() == 'right'


def test_the_estimate_says_how_far_ahead_its_lines_are_seen_and_keeps_it_moving():
    half = DT.lane_width / 2
    pieces = line_pieces(half, 'yellow', along=(0.15, 0.6)) + line_pieces(-half, 'white',
                                                                          along=(0.15, 0.6))
    est, _ = measure(pieces, DT, P)
    assert est.seen == pytest.approx(0.65, abs=0.01)  # the last piece runs 0.55 to 0.65
    assert predict(est, 0.1, 0.0).seen == pytest.approx(est.seen - 0.1, abs=1e-3)
    assert blend(predict(est, 0.1, 0.0), est, 0.5).seen == est.seen  # the measurement's
