"""The pitch read from the floor's motion (lanelib/floorpitch.py): tape on a known floor, drawn
by a camera pitched otherwise than its mounting says, seen from a robot driving along it."""

import math

import numpy as np
import pytest

from lanelib.colour import Piece
from lanelib.floorpitch import PitchFromMotion
from lanelib.geometry import Mounting, repitched
from lanelib.robot import moved_by, seen_from

MOUNTING = Mounting(height=0.108, pitch_deg=19.15, forward=0.066)  # the Duckiebot's
RATE = 8.0
LANE = 0.2375


def lane_points(radius, side):
    """Points of one tape every 5 mm, `side` lane halves left of the centre line, which starts
    at the origin heading +x: straight (radius None) or a circle turning left (radius > 0) or
    right (< 0), in the world frame."""
    s = np.arange(-0.5, 4.0, 0.005)
    offset = side * LANE / 2
    if radius is None:
        return s, np.full_like(s, offset)
    r = radius - offset  # the tape's own radius about the circle's centre (0, radius)
    angle = s / radius
    return r * np.sin(angle), radius - r * np.cos(angle)


def drawn_pieces(pose, error_deg, radius, dashed_yellow=True):
    """The pieces the camera draws from `pose` (x, y, yaw) with the mounting's pitch, the
    camera looking error_deg further down than that: the tape 0.1 to 0.8 m ahead, cut into 6 cm
    pieces."""
    pieces = []
    for side, colour in ((1, 'yellow'), (-1, 'white')):
        wx, wy = lane_points(radius, side)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        x, y = c * (wx - pose[0]) + s * (wy - pose[1]), -s * (wx - pose[0]) + c * (wy - pose[1])
        seen = (x > 0.1) & (x < 0.8) & (np.abs(y) < 0.6)
        if dashed_yellow and colour == 'yellow':
            seen &= (np.arange(len(x)) % 15) < 8  # 4 cm dashes, 3.5 cm gaps
        x, y = x[seen], y[seen]
        # where the camera, pitched error_deg further down than MOUNTING says, draws them
        x, y = repitched(x, y, MOUNTING.looking_down(error_deg), -error_deg)
        for start in np.arange(0, len(x), 12):
            px, py = x[start:start + 12], y[start:start + 12]
            if len(px) < 4:
                continue
            phi = math.atan2(py[-1] - py[0], px[-1] - px[0])
            pieces.append(Piece(px, py, phi, colour, math.hypot(py[-1] - py[0],
                                                                 px[-1] - px[0]), 0.025))
    return pieces


def drive(error_deg, radius, frames=40, speed=0.25, tolerance=4.0, odometry=True):
    """The reader's pitch after each frame of a robot driving along the lane's centre line."""
    reader = PitchFromMotion(MOUNTING, tolerance, lag=0.3)
    ds = speed / RATE
    turn = 0.0 if radius is None else ds / radius
    step = (ds, 0.0, 0.0) if radius is None else (radius * math.sin(turn),
                                                  radius * (1 - math.cos(turn)), turn)
    pose, values = (0.0, 0.0, 0.0), [0.0]
    for i in range(frames):
        if i:
            pose = moved_by(*pose, *step)
        values.append(reader.read(drawn_pieces(pose, error_deg, radius), 0.0,
                                  step if i and odometry else None, 1.0 / RATE, values[-1]))
    return values[1:]


def test_a_pose_seen_from_another_is_the_step_that_leads_there():
    # the robot at (1, 2) facing +y moves 0.3 m ahead and 0.1 m to its left (-x), turning 0.2
    origin = (1.0, 2.0, math.pi / 2)
    assert seen_from(origin, (0.9, 2.3, math.pi / 2 + 0.2)) == pytest.approx((0.3, 0.1, 0.2))
    for step in ((0.05, -0.01, 0.3), (-0.2, 0.4, -2.5), (0.0, 0.0, 0.0)):
        for start in ((0.0, 0.0, 0.0), (-3.0, 1.5, 2.9), (2.0, -1.0, -1.2)):
            assert seen_from(start, moved_by(*start, *step)) == pytest.approx(step)


def test_the_drawing_is_what_the_reader_undoes():
    """The test's camera: the floor it draws, put back with the true pitch, is the floor."""
    x, y = np.array([0.2, 0.5, 0.7]), np.array([0.1, -0.1, 0.05])
    drawn = repitched(x, y, MOUNTING.looking_down(2.0), -2.0)
    assert np.allclose(repitched(*drawn, MOUNTING, 2.0), (x, y), atol=1e-9)
    assert not np.allclose(drawn, (x, y), atol=1e-3)


def test_several_pitches_at_once_are_each_pitch_alone():
    """The reader moves a frame's points to three pitches in one array: each pitch's part is
    the same numbers, to the last bit, as the points moved to that pitch alone."""
    x, y = np.array([0.2, 0.5, 0.7, 1.9]), np.array([0.1, -0.1, 0.05, 0.3])
    turns = np.array([[1.5], [-0.25], [3.0]])
    nx, ny = repitched(x, y, MOUNTING, turns)
    assert nx.shape == ny.shape == (3, 4)
    for turn, row_x, row_y in zip(turns[:, 0], nx, ny):
        alone = repitched(x, y, MOUNTING, float(turn))
        assert np.array_equal(row_x, alone[0]) and np.array_equal(row_y, alone[1])
    assert not np.array_equal(nx[0], nx[1])


@pytest.mark.parametrize('radius', [None, 0.3, -0.175, 1.0])
@pytest.mark.parametrize('error', [-3.0, -1.0, 0.0, 2.0, 3.5])
def test_the_pitch_is_read_on_straights_and_in_corners(radius, error):
    """Whatever the lane's shape (a straight, a 0.3 m left bend, the inner lane's 0.175 m right
    corner), within a quarter of a degree after 40 frames (5 s), and within 0.5 after 16 (2 s)."""
    values = drive(error, radius)
    assert values[-1] == pytest.approx(error, abs=0.25)
    assert values[15] == pytest.approx(error, abs=0.5)


def test_without_odometry_or_motion_nothing_is_read():
    """No motion known (odometry not coming), or none made: the pitch stays as it was."""
    assert drive(3.0, None, frames=20, odometry=False) == [0.0] * 20
    assert drive(3.0, None, frames=20, speed=0.0) == [0.0] * 20


def test_the_reading_stays_within_the_tolerance():
    values = drive(3.5, None, tolerance=2.0)
    assert max(values) == 2.0


def test_the_controller_reads_the_pitch_from_motion_only_while_odometry_comes():
    """The duckiebot preset with pitch_from 'motion' in the project's simulator (the inner
    lane's tight corners), its camera looking 2 degrees further down than it is told: with the
    base's odometry the correction is within a quarter of a degree of 2 after 5 s, corners and
    all, and the lane's lines are fitted parallel (no spread); without it, or with pitch_from
    'splay', no reader is made (the splay's correction, the lines fitted splayed)."""
    from dataclasses import replace

    import lanelib.improved as improved_module
    import simulate

    spec = simulate.load_track('tools/tracks/duckietown_small_loop_cw.yaml')
    told = Mounting(height=spec.mounting.height, pitch_deg=spec.mounting.pitch_deg,
                    forward=spec.mounting.forward)
    spec.mounting.pitch_deg += 2.0
    params, preset = simulate.robot_settings('duckiebot', spec, mounting=told)
    improved = replace(preset, pitch_from='motion')
    made = []

    def factory(name, spec, params, odometry=None):
        made.append(simulate.preset_factory(improved)(name, spec, params, odometry=odometry))
        return made[-1]

    spreads = []
    measure = improved_module.measure

    def measured(*args, **kwargs):
        meas, fit = measure(*args, **kwargs)
        spreads.append(None if meas is None else meas.spread)
        return meas, fit

    for odometry in (True, False):
        spreads.clear()
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(improved_module, 'measure', measured)
            simulate.run(spec, 'improved', seed=0, controller_factory=factory, params=params,
                         time_limit=5.0, odometry=odometry)
        assert (made[-1].floor_pitch is not None) == odometry
        seen = [s for s in spreads[2:] if s is not None]  # (the first frames have no motion)
        assert len(seen) > 20
        if odometry:
            assert all(s == 0.0 for s in seen)
        else:
            assert sum(s != 0.0 for s in seen) > len(seen) / 2
    assert made[0].pitch_error == pytest.approx(2.0, abs=0.25)
    improved = replace(preset, pitch_from='splay')
    simulate.run(spec, 'improved', seed=0, controller_factory=factory, params=params,
                 time_limit=0.5, odometry=True)
    assert made[-1].floor_pitch is None
