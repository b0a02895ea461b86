"""evaluate_real.py on a small labelled folder rendered here (the real frames stay outside)."""

import csv
import json

import cv2
import pytest

from lanelib.geometry import Mounting
from lanelib.sim.world import FloorCamera, FloorMap, Scene, Track
from tools import evaluate_real


@pytest.fixture(scope='module')
def labelled(tmp_path_factory):
    folder = tmp_path_factory.mktemp('labelled')
    camera, ip = evaluate_real.profile('duckietown/x.jpg', 640, 480)
    fc = FloorCamera(camera, Mounting(ip.camera_height, ip.camera_pitch, ip.camera_forward))
    rows = []
    for label, angle in (('left', 90), ('right', -90), ('straight', 0)):
        bend = {'arc': {'radius': 0.4, 'angle_deg': angle}} if angle else {'straight': 2.0}
        track = Track(lane_width=0.22, segments=[{'straight': 0.3}, bend, {'straight': 1.0}],
                      start=(-0.5, 0.0, 0.0))
        img = fc.render(FloorMap(track), track.pose_at(0.5), Scene(noise=2, max_range=2.0))
        cv2.imwrite(str(folder / f'{label}.png'), img)
        rows.append(dict(file=f'{label}.png', expected_steering=label, confidence='high',
                         scene='rendered', notes=''))
    blank = fc.render(FloorMap(Track(segments=[{'straight': 0.1}], start=(50.0, 50.0, 0.0))),
                      (0.0, 0.0, 0.0), Scene(noise=2))
    cv2.imwrite(str(folder / 'empty.png'), blank)
    rows.append(dict(file='empty.png', expected_steering='no_lane', confidence='high',
                     scene='rendered', notes=''))
    with open(folder / 'labels.csv', 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return folder


def test_the_improved_perception_reads_rendered_bends(labelled, tmp_path, capsys):
    out = tmp_path / 'r.json'
    assert evaluate_real.main([str(labelled), '--json', str(out), '--details']) == 0
    results = {r['file']: r for r in json.loads(out.read_text())}
    for name in ('left', 'right', 'straight'):
        assert results[f'{name}.png']['improved'] == name
    assert results['empty.png']['improved'] == 'none'
    text = capsys.readouterr().out
    assert 'improved  agrees on 4/4 (100%)' in text


def test_a_folder_without_labels_is_an_error(tmp_path):
    with pytest.raises(SystemExit) as e:
        evaluate_real.main([str(tmp_path)])
    assert e.value.code == 2
