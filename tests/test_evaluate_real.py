"""tools/evaluate_real on a small labelled folder rendered here (the real frames stay outside)."""

import csv
import json

import cv2
import pytest

from lanelib.camera import DUCKIEBOT_CAMERA
from lanelib.geometry import Mounting
from lanelib.sim.world import WORLDS, ColourFloorMap, FloorCamera, Scene, Track
from tools import evaluate_real

PITCH = evaluate_real.DT_CORE_PITCH  # [deg] rendered as Duckietown's default mounting


@pytest.fixture(scope='module')
def labelled(tmp_path_factory):
    """A Duckiebot's view of a Duckietown lane bending left, right, and going straight, and of
    a floor with no lane, in a source folder of their own."""
    folder = tmp_path_factory.mktemp('labelled')
    (folder / 'rendered').mkdir()
    camera = FloorCamera(DUCKIEBOT_CAMERA, Mounting(0.10, PITCH, 0.0))
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


def test_the_improved_controller_reads_rendered_bends(labelled, tmp_path, capsys):
    out = tmp_path / 'r.json'
    assert evaluate_real.main([str(labelled), '--json', str(out), '--details']) == 0
    report = json.loads(out.read_text())
    results = {r['file']: r for r in report['results']}
    for name in ('left', 'right', 'straight'):
        assert results[f'rendered/{name}.png']['improved'] == name
    assert results['rendered/empty.png']['improved'] == 'none'
    # the camera's pitch, estimated from the three frames with lines, is the rendered one
    assert report['cameras']['rendered']['how'] == 'estimated'
    assert report['cameras']['rendered']['pitch_deg'] == pytest.approx(PITCH, abs=1.5)
    text = capsys.readouterr().out
    assert 'improved  4/4 (100%), turn direction 2/2 (100%)' in text
    assert 'straight  1/4 (25%), turn direction 0/2 (0%)' in text


def test_a_folder_without_labels_is_an_error(tmp_path):
    with pytest.raises(SystemExit) as e:
        evaluate_real.main([str(tmp_path)])
    assert e.value.code == 2
