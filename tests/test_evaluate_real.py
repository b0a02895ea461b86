"""tools/evaluate_real on a small labelled folder rendered here (the real frames stay outside)."""

import csv
import json

import cv2
import pytest

from kobuki_lane import LaneParams
from lanelib.camera import DUCKIEBOT_CAMERA
from lanelib.geometry import Mounting
from lanelib.improved import ImprovedParams
from lanelib.mounting import read_mounting
from lanelib.robots import load_robot
from lanelib.safety import Safety
from lanelib.sim.world import WORLDS, ColourFloorMap, FloorCamera, Scene, Track
from tools import evaluate_real

# rendered as the duckiebot preset's camera is mounted: what --robot duckiebot assumes
PRESET = load_robot('duckiebot', {f for table in (LaneParams, ImprovedParams, Safety)
                                  for f in table.__dataclass_fields__}).settings


@pytest.fixture(scope='module')
def labelled(tmp_path_factory):
    """A Duckiebot's view of a Duckietown lane bending left, right, and going straight, and of
    a floor with no lane, in a source folder of their own."""
    folder = tmp_path_factory.mktemp('labelled')
    (folder / 'rendered').mkdir()
    camera = FloorCamera(DUCKIEBOT_CAMERA, Mounting(PRESET['camera_height'],
                                                    PRESET['camera_pitch'],
                                                    PRESET['camera_forward']))
    world = WORLDS['duckietown']
    rows = []
    for label, angle in (('left', 90), ('right', -90), ('straight', 0)):
        bend = {'arc': {'radius': 0.4, 'angle_deg': angle}} if angle else {'straight': 2.0}
        track = Track(lane_width=world.lane_width, tape_width=0.03,
                      segments=[{'straight': 0.3}, bend, {'straight': 1.0}],
                      start=(-0.5, 0.0, 0.0))
        img = camera.render(ColourFloorMap(track, world), track.pose_at(0.5),
                            Scene(noise=2, max_range=2.0))
        cv2.imwrite(str(folder / 'rendered' / f'{label}.png'), img)
        rows.append(dict(file=f'rendered/{label}.png', expected_steering=label,
                         confidence='high', scene='rendered', notes=''))
    empty = Track(segments=[{'straight': 0.1}], start=(50.0, 50.0, 0.0))
    blank = camera.render(ColourFloorMap(empty, world), (0.0, 0.0, 0.0), Scene(noise=2))
    cv2.imwrite(str(folder / 'rendered' / 'empty.png'), blank)
    rows.append(dict(file='rendered/empty.png', expected_steering='no_lane', confidence='high',
                     scene='rendered', notes=''))
    with open(folder / 'labels.csv', 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return folder


def test_the_node_with_the_preset_reads_rendered_bends(labelled, tmp_path, capsys):
    """Each picture decided by kobuki_lane.py itself with --robot duckiebot, a fresh node per
    picture: the bends and the straight as they are, and no lane on a bare floor."""
    out = tmp_path / 'r.json'
    assert evaluate_real.main([str(labelled), '--robot', 'rendered=duckiebot', '--json',
                               str(out), '--details']) == 0
    report = json.loads(out.read_text())
    results = {r['file']: r for r in report['results']}
    for name in ('left', 'right', 'straight'):
        assert results[f'rendered/{name}.png']['improved'] == name
        assert results[f'rendered/{name}.png']['flags'] == ('--controller improved --robot '
                                                            'duckiebot')
    assert results['rendered/empty.png']['improved'] == 'none'
    text = capsys.readouterr().out
    assert ('improved  4/4 (100%), turn direction 2/2 (100%), command turned 2/2 (100%)'
            in text)
    assert 'straight  1/4 (25%), turn direction 0/2 (0%)' in text


def test_a_label_whose_notes_say_doubtful_is_counted_apart(labelled, tmp_path, capsys):
    """A labels file may mark a label doubtful itself ('doubtful: why' in its notes, as
    tools/heldout_dtcore_labels.csv does where tools.askew measures the robot askew): the
    figures are given with and without it, and why is listed."""
    import shutil

    folder = tmp_path / 'copy'
    shutil.copytree(labelled, folder)
    with open(folder / 'labels.csv', newline='') as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        if row['file'] == 'rendered/left.png':
            row['notes'] = 'by eye; doubtful: the robot stands askew'
    with open(folder / 'labels.csv', 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    out = tmp_path / 'r.json'
    assert evaluate_real.main([str(folder), '--robot', 'rendered=duckiebot', '--json',
                               str(out)]) == 0
    doubt = {r['file']: r['doubtful'] for r in json.loads(out.read_text())['results']}
    assert doubt['rendered/left.png'] == 'the robot stands askew'
    assert [v for k, v in doubt.items() if k != 'rendered/left.png'] == [None] * 3
    text = capsys.readouterr().out
    assert 'without the 1 doubtful labels' in text
    assert 'rendered/left.png (left): the robot stands askew' in text
    assert evaluate_real.noted_doubt({'notes': 'labelled by eye'}) is None
    assert evaluate_real.noted_doubt({'notes': 'doubtful:'}) == 'doubtful'


def test_the_command_is_counted_by_the_way_it_turns_apart_from_the_word():
    """A bend decided 'left' whose command turns right (a robot left of its lane's centre
    before a left bend re-centres first) counts for the word, not for the command."""
    def result(expected, word, omega):
        return dict(expected=expected, improved=word, improved_detail=dict(angular_z=omega))
    rows = [result('left', 'left', -0.4), result('right', 'straight', -0.6),
            result('straight', 'straight', 0.0)]
    assert evaluate_real.figures(rows, 'improved') == (
        '2/3 (67%), turn direction 1/2 (50%), command turned 1/2 (50%)')
    assert [evaluate_real.turned_by(r) for r in rows] == ['right', 'right', 'straight']


def test_a_source_with_no_preset_is_refused_before_the_work(labelled):
    with pytest.raises(SystemExit) as e:
        evaluate_real.main([str(labelled)])
    assert e.value.code == 2


def test_a_folder_without_labels_is_an_error(tmp_path):
    with pytest.raises(SystemExit) as e:
        evaluate_real.main([str(tmp_path)])
    assert e.value.code == 2


def test_pictures_published_with_their_calibration_are_decided_with_it():
    """duckietown-lx's visual_control pictures get the mounting made from the homography
    published with them (tools/robots/visual_control_mounting.yaml), as their robot's user
    would give it; the source's other pictures, and every other source, the preset's."""
    def mounting(relpath):
        flags = evaluate_real.flags_for(relpath, evaluate_real.PRESETS)
        return flags[flags.index('--mounting') + 1] if '--mounting' in flags else None
    given = mounting('duckietown_duckietown-lx/visual_control_pic11.png')
    assert given.endswith('tools/robots/visual_control_mounting.yaml')
    assert read_mounting(given).pitch_deg < PRESET['camera_pitch'] - 5  # not the preset's
    rectified = evaluate_real.flags_for('duckietown_duckietown-lx/visual_control_pic1_rect.png',
                                        evaluate_real.PRESETS)
    assert rectified[-4:] == ['--calibration', 'duckiebot-rectified', '--mounting', given]
    for other in ('duckietown_duckietown-lx/state-estimation_pic1.png',
                  'duckietown_dt-core_anti_instagram/316closed_0031.jpg'):
        assert mounting(other) is None
