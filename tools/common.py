"""What the maintainers' tools share: where the repository is, this machine, its memory."""

import json
import os
import platform

import cv2
import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = os.path.join(REPO, 'samples', 'track')


def rss_mb(field='VmRSS'):
    """This process's resident memory (VmRSS) or its peak (VmHWM) in MB, from /proc."""
    with open('/proc/self/status') as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field + ':')) / 1024


def machine():
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as f:
            cpu = next(line.split(':', 1)[1].strip() for line in f if 'model name' in line)
    except (OSError, StopIteration):
        pass
    return dict(cpu=cpu, cores=os.cpu_count(), python=platform.python_version(),
                opencv=cv2.__version__, numpy=np.__version__)


def write_json(path, data):
    """--json FILE: every figure of the run (nothing when path is None)."""
    if path:
        with open(path, 'w', encoding='utf-8') as f:
            json.dump(data, f, indent=1)


def whole_number(low, high=10 ** 9, why=''):
    """An argparse type: a whole number from low to high; `why` says what needs the bound."""
    import argparse

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"'{text}' is not a whole number from {low:,} to "
                                             f'{high:,}{why}')
        return value
    return parse
