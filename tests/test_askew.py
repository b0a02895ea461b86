"""tools/askew: how far askew a robot stands on a straight lane, from the picture alone."""

import csv

import pytest

from lanelib.camera import DUCKIEBOT_CAMERA
from lanelib.geometry import Mounting
from lanelib.sim.world import WORLDS, ColourFloorMap, FloorCamera, Scene, Track
from tools import askew

# the duckiebot preset's camera as mounted (config/duckiebot.yaml)
CAMERA = FloorCamera(DUCKIEBOT_CAMERA, Mounting(0.108, 21.6, 0.066))
WORLD = WORLDS['duckietown']


def view(yaw_deg, offset=0.0):
    """A Duckiebot on a long straight Duckietown lane, turned yaw_deg left of it."""
    import math

    track = Track(lane_width=WORLD.lane_width, tape_width=0.03,
                  segments=[{'straight': 4.0}], start=(-1.0, 0.0, 0.0))
    x, y, theta = track.pose_at(1.0)
    return CAMERA.render(ColourFloorMap(track, WORLD),
                         (x, y + offset, theta + math.radians(yaw_deg)),
                         Scene(noise=2, max_range=3.0))


@pytest.mark.parametrize('yaw', [0.0, 8.0, -8.0, 15.0, -15.0])
def test_the_lines_meet_as_far_aside_as_the_robot_is_turned(yaw):
    # turned left, the lane runs to the right of its heading: + degrees
    angle, _, _ = askew.askew_deg(view(yaw))
    assert angle == pytest.approx(yaw, abs=1.0)


def test_where_the_robot_stands_across_the_lane_does_not_move_where_the_lines_meet():
    angle, _, _ = askew.askew_deg(view(10.0, offset=0.04))
    assert angle == pytest.approx(10.0, abs=1.0)


def test_a_floor_with_no_lane_has_no_angle():
    import numpy as np

    angle, _, lines = askew.askew_deg(np.full((480, 640, 3), 90, np.uint8))
    assert angle is None and lines == (None, None)


def test_the_limit_is_where_the_lane_at_the_look_ahead_lies_half_a_lane_aside():
    # the duckiebot preset: turn_offset 0.5 lane widths at the look-ahead of 2.571
    assert askew.limit_deg() == pytest.approx(11.0, abs=0.05)


def test_the_tool_reads_the_straight_duckietown_labels_of_a_folder(tmp_path, capsys):
    import cv2

    (tmp_path / 'duckietown_x').mkdir()
    rows = []
    for name, yaw, label in (('a', 0.0, 'straight'), ('b', -15.0, 'straight'),
                             ('c', 15.0, 'left')):
        cv2.imwrite(str(tmp_path / 'duckietown_x' / f'{name}.png'), view(yaw))
        rows.append(dict(file=f'duckietown_x/{name}.png', expected_steering=label,
                         confidence='high', scene='rendered', notes=''))
    with open(tmp_path / 'labels.csv', 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    assert askew.main([str(tmp_path), '--pictures', str(tmp_path / 'out')]) == 0
    out = list(csv.reader(capsys.readouterr().out.splitlines()))
    assert out[0] == ['file', 'askew_deg', 'beyond_11.0_deg']
    got = {r[0]: r for r in out[1:]}
    assert set(got) == {'duckietown_x/a.png', 'duckietown_x/b.png'}  # only the straight ones
    assert abs(float(got['duckietown_x/a.png'][1])) < 1.0 and got['duckietown_x/a.png'][2] == 'no'
    assert float(got['duckietown_x/b.png'][1]) < -14.0 and got['duckietown_x/b.png'][2] == 'yes'
    assert len(list((tmp_path / 'out').iterdir())) == 2


def test_a_folder_without_labels_is_a_clear_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        askew.main([str(tmp_path)])
    assert e.value.code == 2
    assert 'cannot read' in capsys.readouterr().err
