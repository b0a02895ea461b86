"""samples/: small, regenerable, and what docs/usage.md says the faithful rule decides on them."""

import collections
import json
import os
import re

import cv2
import numpy as np
import pytest
from helpers import REPO, SAMPLES

from kobuki_lane import main
from tools import make_samples

REGIONS = {'A': 'A straight', 'B': 'B left curve', 'C': 'C right curve'}


def test_samples_are_small_and_cover_regions_a_b_c():
    names = sorted(os.listdir(SAMPLES))
    size = sum(os.path.getsize(os.path.join(SAMPLES, n)) for n in names)
    assert size <= 3 * 1024 * 1024
    assert all(re.fullmatch(r'\d{3}_[ABC]\.jpg', n) for n in names)
    assert {n[4] for n in names} == set('ABC')


def test_make_samples_regenerates_them(tmp_path):
    out = tmp_path / 'track'
    assert make_samples.main(['--out', str(out)]) == 0
    names = sorted(os.listdir(SAMPLES))
    assert sorted(os.listdir(out)) == names
    for name in names[::7]:
        committed = cv2.imread(os.path.join(SAMPLES, name)).astype(float)
        fresh = cv2.imread(str(out / name)).astype(float)
        assert np.mean(np.abs(committed - fresh)) < 1.0, name


def decision_counts(algorithm, tmp_path):
    out = tmp_path / f'{algorithm}.jsonl'
    assert main(['--source', SAMPLES, '--dry-run', '--algorithm', algorithm, '--decisions',
                 str(out), '--quiet']) == 0
    counts = collections.defaultdict(collections.Counter)
    for line in out.read_text().splitlines():
        r = json.loads(line)
        counts[r['source'][4]][r['decision']] += 1
    return counts


def parse_cell(cell):
    pairs = re.findall(r'(left|right|straight|none) (\d+)', cell)
    return collections.Counter({word: int(n) for word, n in pairs})


@pytest.mark.parametrize('region', 'ABC')
def test_the_usage_docs_table_is_what_the_rule_decides(region, tmp_path):
    with open(os.path.join(REPO, 'docs', 'usage.md'), encoding='utf-8') as f:
        row = next(line for line in f if line.startswith(f'| {REGIONS[region]} |'))
    cells = [c.strip() for c in row.strip().strip('|').split('|')]
    for algorithm, cell in (('1.1', cells[2]), ('1.0', cells[4])):
        assert decision_counts(algorithm, tmp_path)[region] == parse_cell(cell), algorithm
