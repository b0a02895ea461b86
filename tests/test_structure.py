"""How the code is laid out: the library imports neither the node nor the tools, no import
goes round in a circle, nothing happens at import time, and kobuki_lane.py stays short."""

import ast
import os
import subprocess
import sys

from helpers import REPO

NODE_AND_USER_TOOLS = ('kobuki_lane', 'calibration', 'simulate')


def modules():
    """{module name: path} of every Python module of the project (tests aside)."""
    found = {name: os.path.join(REPO, f'{name}.py') for name in NODE_AND_USER_TOOLS}
    for package in ('lanelib', 'tools'):
        for folder, _, files in os.walk(os.path.join(REPO, package)):
            for file in files:
                if file.endswith('.py'):
                    path = os.path.join(folder, file)
                    name = os.path.relpath(path, REPO)[:-3].replace(os.sep, '.')
                    found[name[:-len('.__init__')] if name.endswith('__init__') else name] = path
    return found


def imports(path, known):
    """The project modules `path` imports, anywhere in it (functions included)."""
    found = set()
    for node in ast.walk(ast.parse(open(path, encoding='utf-8').read())):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module] + [f'{node.module}.{alias.name}' for alias in node.names]
        found |= {name for name in names if name in known}
    return found


def graph():
    known = modules()
    return {name: imports(path, known) - {name} for name, path in known.items()}


def test_the_import_graph_has_no_circle():
    edges = graph()
    done, path = set(), []

    def visit(name):
        assert name not in path, 'import circle: ' + ' -> '.join(path + [name])
        if name in done:
            return
        path.append(name)
        for other in edges[name]:
            visit(other)
        path.pop()
        done.add(name)

    for name in edges:
        visit(name)


def test_the_library_imports_neither_the_node_nor_the_tools():
    for name, imported in graph().items():
        if name.startswith('lanelib'):
            outside = {m for m in imported if not m.startswith('lanelib')}
            assert not outside, f'{name} imports {outside}'


def test_no_tool_imports_another_tool():
    helpers = {'tools', 'tools.common', 'tools.roslive'}
    for name, imported in graph().items():
        if name.startswith('tools.') and name not in helpers:
            others = {m for m in imported if m.startswith('tools') and m not in helpers}
            assert not others, f'{name} imports {others}'


def test_the_library_parses_no_command_line():
    for name, path in modules().items():
        if name.startswith('lanelib'):
            text = open(path, encoding='utf-8').read()
            assert 'import argparse' not in text and 'sys.argv' not in text, name


def test_importing_does_nothing():
    """No thread, no ROS, no window, no file: importing every module only defines things."""
    names = sorted(n for n in modules() if not n.startswith('tools'))
    script = ('import os, sys, threading\n'
              'before = set(os.listdir("."))\n'
              + ''.join(f'import {name}\n' for name in names) +
              'print(threading.active_count(), "rospy" in sys.modules, '
              'sorted(set(os.listdir(".")) - before))\n')
    out = subprocess.run([sys.executable, '-c', script], cwd=REPO, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ['1', 'False', '[]']


def test_kobuki_lane_py_reads_in_one_sitting():
    with open(os.path.join(REPO, 'kobuki_lane.py'), encoding='utf-8') as f:
        lines = f.read().splitlines()
    assert len(lines) < 600
    source = '\n'.join(lines)
    for call in ('calibration_camera(', 'cv2.cvtColor(', 'cv2.GaussianBlur(', 'cv2.Canny(',
                 'region_of_interest(', 'hough_lines(', 'slope_sum('):
        assert call in source[source.index('def detect('):source.index('def roi_picture(')], call


BLAS_THREADS = '''
import ctypes, sys
first = sys.argv[1]
__import__(first)
__import__(sys.argv[2])
paths = {line.split()[-1] for line in open('/proc/self/maps') if 'openblas' in line.lower()}
for path in sorted(paths):
    blas = ctypes.CDLL(path)
    for name in ('openblas_get_num_threads', 'openblas_get_num_threads64_',
                 'scipy_openblas_get_num_threads64_', 'scipy_openblas_get_num_threads'):
        if hasattr(blas, name):
            print(getattr(blas, name)())
            sys.exit(0)
print('none')
'''


def blas_threads(first, then):
    """How many threads numpy's OpenBLAS runs with after importing `first`, then `then`, with
    OPENBLAS_NUM_THREADS unset; 'none' when numpy's BLAS is not OpenBLAS."""
    env = {k: v for k, v in os.environ.items() if k not in ('OPENBLAS_NUM_THREADS',
                                                             'OMP_NUM_THREADS')}
    out = subprocess.run([sys.executable, '-c', BLAS_THREADS, first, then], cwd=REPO, env=env,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_the_node_and_the_measuring_tools_run_numpy_blas_on_one_thread():
    """OpenBLAS spreads a long sum over every core and spins waiting for them: beside one other
    busy process it made a frame's 95th percentile 100 ms instead of 13. The node, the
    simulator and the tools set one thread before numpy loads (a user's own setting stands)."""
    control = blas_threads('numpy', 'kobuki_lane')
    if control == 'none':
        import pytest
        pytest.skip("numpy's BLAS is not OpenBLAS here")
    if (os.cpu_count() or 1) > 1:
        assert control != '1', 'numpy loaded first keeps its threads: the check can tell'
    for entry in ('kobuki_lane', 'simulate', 'tools.bench', 'tools.evaluate_real'):
        assert blas_threads(entry, 'numpy') == '1', entry
