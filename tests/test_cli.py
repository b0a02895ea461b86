"""kobuki_lane.py from the command line: dry runs, sources, outputs, bad input."""

import dataclasses
import glob
import os
import shutil
import signal
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest
from helpers import NODE, REPO, SAMPLES, read_jsonl, run_as_nobody

import kobuki_lane
from kobuki_lane import LaneParams, LectureRule, detect, main
from lanelib.camera import LECTURE_CAMERA
from lanelib.improved import ImprovedParams
from lanelib.safety import Safety

KEYS = ('frame', 'source', 'lines', 'theta', 'value', 'decision', 'linear_x', 'angular_z')


def cli(*args, timeout=60, env=None):
    return subprocess.run([sys.executable, NODE, *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout, env=env)


def expected(record, params=LaneParams()):
    """What the lecture's rule says for a record's theta and segment count."""
    if record['lines'] == 0 or abs(record['theta']) == params.threshold:
        return 'none'
    if record['theta'] > params.threshold:
        return 'left'
    return 'right' if record['theta'] < -params.threshold else 'straight'


def test_dry_run_on_the_samples_writes_the_rules_decisions(tmp_path):
    out = tmp_path / 'd.jsonl'
    assert main(['--source', SAMPLES, '--dry-run', '--calibration', 'lecture',
                 '--decisions', str(out), '--quiet']) == 0
    records = read_jsonl(out)
    names = sorted(os.listdir(SAMPLES))
    assert [r['source'] for r in records] == names
    p = LaneParams()
    for r in records[::5]:  # recompute from the frame itself
        d = detect(cv2.imread(os.path.join(SAMPLES, r['source'])), LECTURE_CAMERA, p)
        assert r['lines'] == len(d.lines)
        assert r['theta'] == pytest.approx(d.slopes.theta, abs=1e-6)
        assert r['decision'] == LectureRule(p)(d).decision
    for r in records:
        assert all(k in r for k in KEYS)
        assert r['decision'] == expected(r)


def test_calibration_none_on_any_folder(tmp_path):
    folder = tmp_path / 'imgs'
    folder.mkdir()
    img = np.full((240, 320, 3), 80, np.uint8)
    cv2.line(img, (20, 239), (150, 125), (255, 255, 255), 6)
    for i in range(3):
        cv2.imwrite(str(folder / f'{i}.png'), img)
    out = tmp_path / 'd.jsonl'
    proc = cli('--source', str(folder), '--dry-run', '--calibration', 'none', '--decisions',
               str(out))
    assert proc.returncode == 0, proc.stderr
    records = read_jsonl(out)
    assert len(records) == 3 and all(r['decision'] == expected(r) for r in records)
    assert 'frame 0 (0.png)' in proc.stdout  # decisions are printed
    assert 'kobuki_lane: 3 frames (0 skipped)' in proc.stderr


def test_video_pattern_and_single_image_sources(tmp_path):
    frames = [cv2.imread(os.path.join(SAMPLES, n)) for n in sorted(os.listdir(SAMPLES))[:5]]
    for i, f in enumerate(frames):
        cv2.imwrite(str(tmp_path / f'f{i:04d}.png'), f)
    video = tmp_path / 'clip.avi'
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*'MJPG'), 4, (640, 480))
    for f in frames:
        writer.write(f)
    writer.release()
    for k, (source, n) in enumerate(((str(video), 5), (str(tmp_path / 'f%04d.png'), 5),
                                     (str(tmp_path / 'f0002.png'), 1))):
        out = tmp_path / f'd{k}.jsonl'
        assert main(['--source', source, '--dry-run', '--decisions', str(out), '--quiet']) == 0
        records = read_jsonl(out)
        assert len(records) == n, source
        assert all(r['decision'] == expected(r) for r in records)


def test_annotated_video_has_one_frame_per_decision(tmp_path):
    video = tmp_path / 'a.avi'
    assert main(['--source', SAMPLES, '--dry-run', '--video', str(video), '--quiet']) == 0
    cap = cv2.VideoCapture(str(video))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == len(os.listdir(SAMPLES))
    ok, frame = cap.read()
    assert ok and frame.shape == (480, 640, 3)
    # green segments were drawn
    green = (frame[:, :, 1] > 200) & (frame[:, :, 0] < 80) & (frame[:, :, 2] < 80)
    assert green.sum() > 200


def test_unreadable_files_are_skipped_and_counted(tmp_path):
    shutil.copy(os.path.join(SAMPLES, '000_A.jpg'), tmp_path / 'a.jpg')
    (tmp_path / 'b.jpg').write_bytes(b'not a jpeg')
    (tmp_path / 'c.png').write_bytes(b'')
    proc = cli('--source', str(tmp_path), '--dry-run', '--quiet')
    assert proc.returncode == 0
    assert 'skipped' in proc.stderr and 'b.jpg' in proc.stderr
    assert '1 frames (2 skipped)' in proc.stderr


@pytest.mark.parametrize('frame', [np.zeros((1, 1), np.uint8),
                                   np.full((100, 37, 4), 200, np.uint8),
                                   np.full((300, 500), 40000, np.uint16)])
def test_odd_images_are_processed(tmp_path, frame):
    cv2.imwrite(str(tmp_path / 'x.png'), frame)
    out = tmp_path / 'd.jsonl'
    assert main(['--source', str(tmp_path / 'x.png'), '--dry-run', '--decisions', str(out),
                 '--quiet']) == 0
    assert read_jsonl(out)[0]['decision'] in ('left', 'right', 'straight', 'none')


@pytest.mark.parametrize('source, message', [
    ('/no/such/folder', "cannot open '/no/such/folder': no such file or folder"),
    ('empty_dir', 'has no image files'),
    ('zero.avi', 'the file is empty'),
    ('junk.avi', 'cannot open'),
    ('bad.png', 'not a readable image'),
])
def test_a_source_that_cannot_be_opened_exits_2_naming_it(tmp_path, source, message):
    (tmp_path / 'empty_dir').mkdir()
    (tmp_path / 'zero.avi').write_bytes(b'')
    (tmp_path / 'junk.avi').write_bytes(b'\x00garbage' * 100)
    (tmp_path / 'bad.png').write_bytes(b'\x89PNG broken')
    spec = source if source.startswith('/') else str(tmp_path / source)
    proc = cli('--source', spec, '--dry-run')
    assert proc.returncode == 2
    assert message in proc.stderr and 'Traceback' not in proc.stderr


@pytest.mark.parametrize('args', [['--rate', '0'], ['--rate', '-4'], ['--threshold', 'nan'],
                                  ['--threshold', 'inf'], ['--algorithm', '2.0'],
                                  ['--hough-threshold', 'many'], ['--blur-kernel', '4'],
                                  ['--calibration', 'missing.yaml'], ['--progress', 'maybe']])
def test_bad_flag_values_are_argparse_errors(args):
    proc = cli('--source', SAMPLES, '--dry-run', *args)
    assert proc.returncode == 2
    assert 'error:' in proc.stderr and 'Traceback' not in proc.stderr


def test_outputs_in_a_missing_folder_are_refused_before_the_run(tmp_path):
    proc = cli('--source', SAMPLES, '--dry-run', '--decisions', str(tmp_path / 'no' / 'd.jsonl'))
    assert proc.returncode == 2 and 'does not exist' in proc.stderr
    assert 'frame 0' not in proc.stdout


@pytest.mark.parametrize('flag', ['--decisions', '--video', '--bag', '--stages'])
def test_outputs_in_a_read_only_folder_are_refused_before_the_run(flag):
    import tempfile

    folder = tempfile.mkdtemp(prefix='kobuki_lane_ro_')
    try:
        os.chmod(folder, 0o555)
        target = folder if flag == '--stages' else os.path.join(folder, 'out.x')
        status, output = run_as_nobody(main, ['--source', SAMPLES, '--dry-run', flag, target])
        assert status == 2, output
        assert 'not writable' in output and 'Traceback' not in output
        assert 'frame 0' not in output and os.listdir(folder) == []
    finally:
        os.chmod(folder, 0o755)
        shutil.rmtree(folder)


def tool_mains(labels_folder, images_folder):
    """(name, main, argv before the output path) of every command line that writes a file."""
    import calibration
    import simulate
    from tools import bench, evaluate_real, soak

    return [('bench.py', bench.main, ['--quick', '--json']),
            ('soak.py', soak.main, ['--json']),
            ('simulate.py', simulate.main, ['--track', 'lecture', '--json']),
            ('evaluate_real.py', evaluate_real.main, [labels_folder, '--json']),
            ('calibration.py', calibration.main,
             ['--images', os.path.join(images_folder, '*.jpg'), '-o'])]


@pytest.mark.parametrize('read_only', [False, True], ids=['missing folder', 'read-only folder'])
def test_every_tool_refuses_an_unwritable_output_before_its_run(read_only):
    import tempfile

    labels = tempfile.mkdtemp(prefix='kobuki_lane_labels_')
    # the calibration's pictures where 'nobody' can read them (a checkout cloned into a private
    # folder, as mktemp -d makes, is not)
    images = tempfile.mkdtemp(prefix='kobuki_lane_images_')
    folder = tempfile.mkdtemp(prefix='kobuki_lane_ro_')
    try:
        os.chmod(labels, 0o755)
        open(os.path.join(labels, 'labels.csv'), 'w').close()
        os.chmod(images, 0o755)
        for picture in glob.glob(os.path.join(SAMPLES, '*.jpg')):
            shutil.copy(picture, images)
        os.chmod(folder, 0o555)
        target = os.path.join(folder if read_only else os.path.join(folder, 'no'), 'out.json')
        for name, tool, argv in tool_mains(labels, images):
            status, output = run_as_nobody(tool, [*argv, target])
            assert status == 2, (name, output)
            assert ('not writable' if read_only else 'does not exist') in output, (name, output)
            assert 'Traceback' not in output, (name, output)
        assert os.listdir(folder) == []
    finally:
        os.chmod(folder, 0o755)
        shutil.rmtree(folder)
        shutil.rmtree(labels)
        shutil.rmtree(images)


def test_show_without_a_display_is_a_clear_error():
    env = {k: v for k, v in os.environ.items() if k not in ('DISPLAY', 'WAYLAND_DISPLAY')}
    proc = cli('--source', SAMPLES, '--dry-run', '--show', env=env)
    assert proc.returncode == 2 and '--show needs a display' in proc.stderr


def test_private_params_and_flag_precedence(tmp_path):
    out = tmp_path / 'd.jsonl'
    # _threshold:=0.3 as a ROS private parameter makes curves turn ...
    assert main(['--source', SAMPLES, '--dry-run', '_threshold:=0.3', '--decisions', str(out),
                 '--quiet']) == 0
    with_param = read_jsonl(out)
    assert {r['decision'] for r in with_param} >= {'left', 'right'}
    # ... and a flag wins over the parameter
    assert main(['--source', SAMPLES, '--dry-run', '_threshold:=0.3', '--threshold', '6',
                 '--decisions', str(out), '--force', '--quiet']) == 0
    assert all(r['decision'] == expected(r) for r in read_jsonl(out))


def test_algorithm_1_0_is_the_unmasked_pipeline(tmp_path):
    out10, out11 = tmp_path / '10.jsonl', tmp_path / '11.jsonl'
    main(['--source', SAMPLES, '--dry-run', '--algorithm', '1.0', '--decisions', str(out10),
          '--quiet'])
    main(['--source', SAMPLES, '--dry-run', '--decisions', str(out11), '--quiet'])
    lines10 = sum(r['lines'] for r in read_jsonl(out10))
    lines11 = sum(r['lines'] for r in read_jsonl(out11))
    assert lines10 > 2 * lines11


def test_sigterm_in_a_realtime_dry_run_leaves_complete_outputs(tmp_path):
    out = tmp_path / 'd.jsonl'
    proc = subprocess.Popen([sys.executable, NODE, '--source', SAMPLES, '--dry-run',
                             '--realtime', '--decisions', str(out), '--quiet'], cwd=REPO,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20
    while (not out.exists() or len(out.read_text().splitlines()) < 3) and \
            time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 143
    records = read_jsonl(out)  # every line is whole JSON
    assert 3 <= len(records) < len(os.listdir(SAMPLES))
    assert 'ended: SIGTERM' in err


def test_help_explains_the_defaults():
    text = kobuki_lane.build_parser().format_help()
    for phrase in ('--source', 'lecture: 85', 'lecture: threshold = 6', '[m/s]',
                   'rospy.Rate(4)', 'exit status'):
        assert phrase in text


def test_progress_line_on_request():
    proc = cli('--source', SAMPLES, '--dry-run', '--quiet', '--progress', 'on')
    n = len(os.listdir(SAMPLES))
    assert f'frame {n}/{n}' in proc.stderr
    quiet = cli('--source', SAMPLES, '--dry-run', '--quiet', '--progress', 'off')
    assert 'frames/s \n' not in quiet.stderr.split('kobuki_lane:')[0]


def test_controller_and_its_gains_from_private_params(tmp_path):
    out = tmp_path / 'd.jsonl'
    assert main(['--source', SAMPLES, '--dry-run', '_controller:=improved', '_v_max:=0.5',
                 '--decisions', str(out), '--quiet']) == 0
    records = read_jsonl(out)
    assert all('offset_m' in r for r in records)
    assert max(r['linear_x'] for r in records) <= 0.5 * 0.35 + 1e-9  # [lane widths/s]
    proc = cli('--source', SAMPLES, '--dry-run', '_controller:=clever')
    assert proc.returncode == 2 and 'controller must be lecture or improved' in proc.stderr


def test_lane_memory_can_be_turned_off_but_not_made_negative(tmp_path):
    out = tmp_path / 'd.jsonl'
    assert main(['--source', SAMPLES, '--dry-run', '--controller', 'improved', '--memory', '0',
                 '--decisions', str(out), '--quiet']) == 0
    assert len(read_jsonl(out)) == len(os.listdir(SAMPLES))
    proc = cli('--source', SAMPLES, '--dry-run', '--controller', 'improved', '--memory', '-1')
    assert proc.returncode == 2 and 'memory = -1.0 is out of range' in proc.stderr
    assert 'Traceback' not in proc.stderr


def test_a_folder_of_nothing_readable_is_an_error_not_an_empty_run(tmp_path):
    """And no output is made (before: an emptied decisions file and a one-message bag, so the
    run again was refused as 'exists already')."""
    folder = tmp_path / 'frames'
    folder.mkdir()
    (folder / 'a.jpg').write_bytes(b'not a jpeg')
    (folder / 'b.png').write_bytes(b'\x89PNG\r\n')
    outputs = ['--decisions', str(tmp_path / 'd.jsonl'), '--bag', str(tmp_path / 'c.bag'),
               '--video', str(tmp_path / 'v.avi'), '--stages', str(tmp_path / 'st')]
    proc = cli('--source', str(folder), '--dry-run', '--quiet', *outputs)
    assert proc.returncode == 2 and 'no frame could be read' in proc.stderr
    assert 'Traceback' not in proc.stderr
    assert sorted(os.listdir(tmp_path)) == ['frames']


def test_truncated_images_are_refused_or_skipped(tmp_path):
    data = open(os.path.join(SAMPLES, '000_A.jpg'), 'rb').read()
    (tmp_path / 'cut.jpg').write_bytes(data[:len(data) // 2])
    shutil.copy(os.path.join(SAMPLES, '001_A.jpg'), tmp_path / 'whole.jpg')
    proc = cli('--source', str(tmp_path / 'cut.jpg'), '--dry-run')
    assert proc.returncode == 2 and 'truncated' in proc.stderr
    proc = cli('--source', str(tmp_path), '--dry-run', '--quiet')
    assert proc.returncode == 0 and '1 frames (1 skipped)' in proc.stderr
    assert 'cut.jpg' in proc.stderr


def test_a_truncated_video_is_read_as_far_as_it_goes(tmp_path):
    path = str(tmp_path / 'v.avi')
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*'MJPG'), 4, (640, 480))
    for name in sorted(os.listdir(SAMPLES))[:20]:
        writer.write(cv2.imread(os.path.join(SAMPLES, name)))
    writer.release()
    data = open(path, 'rb').read()
    cut = tmp_path / 'cut.avi'
    cut.write_bytes(data[:len(data) // 2])
    proc = cli('--source', str(cut), '--dry-run', '--quiet')
    assert proc.returncode == 1 and 'Traceback' not in proc.stderr
    assert 'is truncated: it ended after 10 of its 20 frames, 9 acted on' in proc.stderr


def test_the_half_decoded_last_frame_of_a_cut_video_is_not_acted_on(tmp_path):
    """A video cut inside its last frame: OpenCV decodes that frame in part without a word
    (270 rows wrong in the issue's case, and acted on); now it is left out, said before the
    summary, and the run ends with status 1."""
    path = str(tmp_path / 'v.avi')
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*'MJPG'), 4, (640, 480))
    names = sorted(os.listdir(SAMPLES))
    for name in names:
        writer.write(cv2.imread(os.path.join(SAMPLES, name)))
    writer.release()
    data = open(path, 'rb').read()
    last = data.rfind(b'\xff\xd8')  # the last frame's JPEG
    cut = tmp_path / 'cut.avi'
    cut.write_bytes(data[:last + (len(data) - last) // 3])
    out = tmp_path / 'd.jsonl'
    proc = cli('--source', str(cut), '--dry-run', '--quiet', '--decisions', str(out))
    assert proc.returncode == 1
    assert len(read_jsonl(out)) == len(names) - 1
    said = proc.stderr.index(f'its last frame, {len(names) - 1}, did not decode whole')
    assert said < proc.stderr.index('kobuki_lane: ')  # before the summary
    whole = cli('--source', path, '--dry-run', '--quiet')
    assert whole.returncode == 0 and 'truncated' not in whole.stderr


def test_a_folder_of_mixed_sizes_and_kinds(tmp_path):
    frame = cv2.imread(os.path.join(SAMPLES, '010_B.jpg'))
    folder = tmp_path / 'frames'
    folder.mkdir()
    cv2.imwrite(str(folder / 'a.png'), frame)
    cv2.imwrite(str(folder / 'b.png'), cv2.resize(frame, (320, 240)))
    cv2.imwrite(str(folder / 'c.png'), cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
    cv2.imwrite(str(folder / 'd.png'), cv2.resize(frame, (1280, 720)))
    cv2.imwrite(str(folder / 'e.png'), frame)
    out = tmp_path / 'd.jsonl'
    assert main(['--source', str(folder), '--dry-run', '--decisions', str(out),
                 '--quiet']) == 0
    records = read_jsonl(out)
    assert len(records) == 5 and 'error' not in str(records)
    assert records[0]['theta'] == records[4]['theta']  # the same frame after other sizes


@pytest.mark.parametrize('args', [['--watchdog', '0.7'], ['--watchdog', '0'],
                                  ['--controller', 'nope'], ['--camera-retry', 'nan'],
                                  ['--max-errors', '0'], ['--camera-retry', '-1'],
                                  ['--wait-for-base', 'nan'], ['--wait-for-base', '-1'],
                                  ['--watchdog', '0.2', '--rate', '4']])
def test_bad_safety_and_controller_values_are_errors(args):
    proc = cli('--source', SAMPLES, '--dry-run', *args)
    assert proc.returncode == 2
    assert 'error:' in proc.stderr and 'Traceback' not in proc.stderr


def test_stages_writes_every_stage_and_a_sheet(tmp_path):
    frames = tmp_path / 'frames'
    frames.mkdir()
    for name in sorted(os.listdir(SAMPLES))[:2]:
        shutil.copy(os.path.join(SAMPLES, name), frames / name)
    out = tmp_path / 'stages'
    out.mkdir()
    assert main(['--source', str(frames), '--dry-run', '--quiet', '--stages', str(out)]) == 0
    names = sorted(os.listdir(out))
    assert len(names) == 2 * 9 and '0001_sheet.png' in names
    edges = cv2.imread(str(out / '0000_4_edges.png'), cv2.IMREAD_GRAYSCALE)
    masked = cv2.imread(str(out / '0000_6_masked.png'), cv2.IMREAD_GRAYSCALE)
    assert edges.shape == (480, 640) and 0 < masked.sum() < edges.sum()
    sheet = cv2.imread(str(out / '0000_sheet.png'))
    assert sheet.shape[1] == 4 * 320
    made = tmp_path / 'made'  # a folder that does not exist yet is made, and its size said
    proc = cli('--source', str(frames), '--dry-run', '--quiet', '--stages', str(made))
    assert proc.returncode == 0 and len(os.listdir(made)) == 2 * 9
    size = sum(os.path.getsize(made / name) for name in os.listdir(made)) / 1e6
    assert f'--stages: 18 pictures, {size:.1f} MB in {made}' in proc.stderr
    proc = cli('--source', str(frames), '--dry-run', '--stages', str(tmp_path / 'no' / 'sub'))
    assert proc.returncode == 2 and 'does not exist' in proc.stderr


def test_an_output_never_destroys_an_input_or_another_output(tmp_path):
    """Issue 16, cases 1 and 2: refused at start, exit 2, the files untouched."""
    video = tmp_path / 'run.avi'
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*'MJPG'), 4, (640, 480))
    for name in sorted(os.listdir(SAMPLES))[:6]:
        writer.write(cv2.imread(os.path.join(SAMPLES, name)))
    writer.release()
    size = video.stat().st_size
    existing = tmp_path / 'old.jsonl'
    existing.write_text('{"kept": true}\n')
    frames = tmp_path / 'frames'
    frames.mkdir()
    for name in sorted(os.listdir(SAMPLES))[:3]:
        shutil.copy(os.path.join(SAMPLES, name), frames / name)
    cases = [
        (['--source', str(video), '--decisions', str(video)], 'is the --source itself'),
        (['--source', str(video), '--video', str(video)], 'is the --source itself'),
        (['--source', str(video), '--decisions', str(tmp_path / 'a.x'),
          '--video', str(tmp_path / 'a.x')], 'are the same file'),
        (['--source', str(video), '--decisions', str(existing)], 'exists already'),
        (['--source', str(frames), '--decisions', str(frames / 'd.jsonl')],
         'inside the --source folder'),
        (['--source', str(frames), '--stages', str(frames)], 'is the --source folder'),
        (['--source', str(video), '--decisions', str(tmp_path)], 'is a folder'),
        # issue 16, cases 8 and 9: found before the first frame, not at it, and no traceback
        (['--source', str(video), '--decisions', '/proc/x.jsonl'], 'cannot write it'),
        (['--source', str(video), '--video', str(tmp_path / 'novideo')],
         'ending in .avi or .mp4'),
    ]
    for args, message in cases:
        proc = cli(*args, '--dry-run', '--quiet')
        assert proc.returncode == 2, (args, proc.stderr)
        assert message in proc.stderr and 'Traceback' not in proc.stderr, proc.stderr
    assert video.stat().st_size == size
    assert existing.read_text() == '{"kept": true}\n'
    assert sorted(os.listdir(frames)) == sorted(os.listdir(SAMPLES))[:3]
    # --force replaces an existing output, and says so in --help
    proc = cli('--source', str(video), '--decisions', str(existing), '--force', '--dry-run',
               '--quiet')
    assert proc.returncode == 0, proc.stderr
    assert len(read_jsonl(existing)) == 6
    assert '--force' in cli('--help').stdout


LECTURE_NUMBERS = [f.name for f in dataclasses.fields(LaneParams) if f.name != 'algorithm']


@pytest.mark.parametrize('name', LECTURE_NUMBERS)
def test_every_lecture_setting_is_honoured_or_refused_at_start(name, tmp_path, capsys):
    """Issue 16: 0, negative, NaN, inf and huge values of every numeric setting either run
    (and exit 0) or are refused before any frame with exit 2 and the setting named; none
    crashes or hangs (--hough-rho 5000 segfaulted, --blur-kernel 99999 ran for minutes)."""
    frames = tmp_path / 'frames'
    frames.mkdir()
    for n in sorted(os.listdir(SAMPLES))[:2]:
        shutil.copy(os.path.join(SAMPLES, n), frames / n)
    flag = '--' + name.replace('_', '-')
    for k, value in enumerate(('0', '-1', 'nan', 'inf', '1e300', '5000', '99999')):
        out = tmp_path / f'{k}.jsonl'
        try:
            status = main(['--source', str(frames), '--dry-run', '--quiet', flag, value,
                           '--decisions', str(out)])
        except SystemExit as e:
            status = e.code
        err = capsys.readouterr().err
        if status == 0:
            assert len(read_jsonl(out)) == 2, (flag, value)
        else:
            named = name in err or flag in err
            assert status == 2 and named and 'Traceback' not in err, (flag, value, err)
            assert not out.exists(), (flag, value)


IMPROVED_AND_SAFETY_NUMBERS = [f.name for table in (ImprovedParams, Safety)
                               for f in dataclasses.fields(table) if f.name != 'lane']
SILLY = ('0', '-1', 'nan', 'inf', '1e300', '5000', '99999')


@pytest.mark.parametrize('name', IMPROVED_AND_SAFETY_NUMBERS)
def test_every_improved_and_safety_setting_is_honoured_or_refused_at_start(name, tmp_path,
                                                                         capsys):
    """The same for the improved controller's and the safety tables' numbers."""
    frames = tmp_path / 'frames'
    frames.mkdir()
    first = sorted(os.listdir(SAMPLES))[0]
    shutil.copy(os.path.join(SAMPLES, first), frames / first)
    flag = '--' + name.replace('_', '-')
    for k, value in enumerate(SILLY):
        out = tmp_path / f'{k}.jsonl'
        try:
            status = main(['--source', str(frames), '--dry-run', '--quiet', '--controller',
                           'improved', flag, value, '--decisions', str(out)])
        except SystemExit as e:
            status = e.code
        err = capsys.readouterr().err
        if status == 0:
            assert len(read_jsonl(out)) == 1, (flag, value)
        else:
            assert status == 2 and (name in err or flag in err), (flag, value, err)
            assert 'Traceback' not in err and not out.exists(), (flag, value)


def test_every_number_of_simulate_py_is_honoured_or_refused_at_start(tmp_path, capsys):
    """simulate.py's numeric flags through the same values: a run that ends (0 or 1), or
    exit 2 at start naming the flag; never a traceback or a NaN in the result."""
    import json
    import math

    import simulate

    parser = simulate.build_parser()
    numeric = [a for a in parser._actions if a.option_strings and a.type not in (None, str)
               and a.option_strings[0] not in ('--gap', '--dashes', '--time-limit', '--jobs')]
    assert len(numeric) >= 14
    for action in numeric:
        flag = action.option_strings[0]
        for value in SILLY:
            out = tmp_path / 'r.json'
            if out.exists():
                out.unlink()
            argv = ['--track', 'lecture', '--controller', 'improved', '--time-limit', '2',
                    '--json', str(out), flag, value]
            try:
                status = simulate.main(argv)
            except SystemExit as e:
                status = e.code
            err = capsys.readouterr().err
            if status in (0, 1):
                result = json.loads(out.read_text())
                assert all(math.isfinite(v) for v in result.values()
                           if isinstance(v, float)), (flag, value, result)
            else:
                assert status == 2 and flag in err and 'Traceback' not in err, (flag, value)


def test_the_ranges_are_in_the_help():
    text = ' '.join(cli('--help').stdout.split())
    assert 'odd, 1 to 31' in text and 'more than 0, at most 100' in text
    assert '3 to 100' in text  # the rate


def test_a_bad_private_parameter_is_named_with_where_it_came_from():
    """Before: '_rate:=0' said 'rate = 0.0 is out of range' with no word of the parameter,
    '_threshold:=abc' did not name it, and a typo was ignored without a word."""
    proc = cli('--source', SAMPLES, '--dry-run', '_rate:=0')
    assert proc.returncode == 2 and 'rate = 0.0 is out of range' in proc.stderr
    assert 'from the private ROS parameter ~rate' in proc.stderr
    assert "'rosparam delete /kobuki_lane/rate' removes it" in proc.stderr
    assert 'usage:' not in proc.stderr
    proc = cli('--source', SAMPLES, '--dry-run', '_threshold:=abc')
    assert proc.returncode == 2 and "threshold = 'abc' is not a number" in proc.stderr
    assert 'private ROS parameter ~threshold' in proc.stderr
    proc = cli('--source', SAMPLES, '--dry-run', '--quiet', '_thresold:=8')
    assert proc.returncode == 0
    assert 'unknown private parameter ~thresold, ignored (did you mean ~threshold?)' in proc.stderr
    proc = cli('--source', SAMPLES, '--dry-run', '--threshold', '-3')
    assert proc.returncode == 2 and 'from --threshold' in proc.stderr


def test_a_setting_above_the_kobukis_limits_is_warned_of_and_what_was_sent_recorded(tmp_path):
    """Before: --v-max 5 recorded linear_x 5.0 while 0.7 was published, without a word."""
    out = tmp_path / 'd.jsonl'
    proc = cli('--source', SAMPLES, '--dry-run', '--quiet', '--controller', 'improved',
               '--v-max', '5', '--decisions', str(out))
    assert proc.returncode == 0
    assert ("v_max = 1.75 m/s (5 lane widths/s) is above the Kobuki's 0.70 m/s: commands are "
            'clipped' in proc.stderr)
    records = read_jsonl(out)
    assert max(r['linear_x'] for r in records) == pytest.approx(0.7)


def test_a_url_that_never_answers_says_it_waits_times_out_and_hears_ctrl_c(silent_server):
    """Before: 30 s of silence, Ctrl-C ignored, then exit 2 with no word of a timeout."""
    import signal
    import time

    start = time.monotonic()
    proc = cli('--source', silent_server.url, '--dry-run', '--open-timeout', '1')
    assert proc.returncode == 2 and time.monotonic() - start < 15
    assert 'waiting up to 1 s for it to answer' in proc.stderr
    assert 'no stream from it within 1 s' in proc.stderr
    node = subprocess.Popen([sys.executable, NODE, '--source', silent_server.url, '--dry-run',
                             '--open-timeout', '60'], cwd=REPO, stderr=subprocess.PIPE,
                            text=True)
    line = node.stderr.readline()  # the word that it waits comes before the wait
    assert 'waiting up to 60 s' in line
    asked = time.monotonic()
    node.send_signal(signal.SIGINT)
    _, err = node.communicate(timeout=20)
    assert node.returncode == 130 and time.monotonic() - asked < 5, (node.returncode, err)
    assert 'interrupted while opening' in err and 'Traceback' not in err


def test_opencv_failing_while_it_opens_a_url_is_a_source_error(monkeypatch):
    """Before: an error raised by VideoCapture on the opening thread left nothing to return,
    and the node ended in an IndexError traceback, exit status 1."""
    from lanelib import sources

    def broken(*_args):
        raise cv2.error('the backend gave up')

    monkeypatch.setattr(sources.cv2, 'VideoCapture', broken)
    with pytest.raises(sources.SourceError, match="cannot open 'http://cam/x.mjpg': OpenCV "
                                                  'failed while opening it .*the backend gave up'):
        sources.CaptureSource('http://cam/x.mjpg', 'http://cam/x.mjpg', live=True, timeout=1.0,
                              warn=lambda _message: None)


@pytest.mark.parametrize('source, pipeline, runs', [
    ('samples/track', 'auto', 'fast'), ('run.mp4', 'auto', 'fast'), ('0', 'auto', 'slides'),
    ('rtsp://cam/stream', 'auto', 'slides'), ('ros:/camera/image_raw', 'auto', 'slides'),
    ('0', 'fast', 'fast'), ('samples/track', 'slides', 'slides')])
def test_a_live_source_runs_detect_itself_and_files_the_speed_up(source, pipeline, runs):
    from argparse import Namespace

    from lanelib.node import pipeline_for

    assert pipeline_for(Namespace(source=source, pipeline=pipeline)) == runs
