"""docs/WALKTHROUGH.md: its pictures are what make_walkthrough.py makes, small, and all there."""

import os
import re

from helpers import REPO

from tools import make_walkthrough

DOCS = os.path.join(REPO, 'docs')


def test_the_pictures_are_regenerated_exactly(tmp_path):
    names = make_walkthrough.make(str(tmp_path))
    for name in names:
        with open(tmp_path / name, 'rb') as new, \
                open(os.path.join(DOCS, 'img', name), 'rb') as checked_in:
            assert new.read() == checked_in.read(), f'{name}: run make_walkthrough.py'
    assert sorted(names) == sorted(os.listdir(os.path.join(DOCS, 'img')))
    total = sum(os.path.getsize(os.path.join(DOCS, 'img', n)) for n in names)
    assert total < 500 * 1024


def test_every_picture_the_walkthrough_shows_exists_and_is_shown():
    text = open(os.path.join(DOCS, 'WALKTHROUGH.md'), encoding='utf-8').read()
    shown = set(re.findall(r'\]\((img/[^)]+)\)', text))
    assert shown == {f'img/{n}' for n in os.listdir(os.path.join(DOCS, 'img'))}


def test_the_walkthroughs_figures_are_the_nodes(tmp_path):
    import cv2

    from kobuki_lane import LaneParams, LectureRule, detect
    from lanelib.camera import LECTURE_CAMERA

    text = open(os.path.join(DOCS, 'WALKTHROUGH.md'), encoding='utf-8').read()
    frame = cv2.imread(os.path.join(make_walkthrough.SAMPLES, make_walkthrough.FRAME))
    for algorithm, words, count in (('1.1', '+0.42 here', 1),
                                    ('1.0', 'segments and theta -5.55', 9)):
        d = detect(frame, LECTURE_CAMERA, LaneParams(algorithm=algorithm))
        assert words in text and f'{d.slopes.theta:+.2f}' in words
        assert len(d.lines) == count
        assert LectureRule(LaneParams())(d).decision == 'straight'
