"""Frame sources for kobuki_lane: everything --source accepts, behind one read() call.

    0, 1, ...            a camera index              cv2.VideoCapture(0)      live
    run.mp4              a video file                cv2.VideoCapture(path)
    frames/%04d.png      an image-sequence pattern   cv2.VideoCapture(pattern)
    rtsp://..., http://  any URL VideoCapture takes  cv2.VideoCapture(url)    live
    run.bag              a ROS 1 bag's image topic   bags.BagSource (--image-topic)
    ros:/camera/image    a live ROS image topic      topics.TopicSource              live
    samples/track/       a folder of images, read in name order
    picture.png          one image

read() returns (ok, frame, label): label is the file name for folders and images, the frame
index otherwise. Unreadable files in a folder are skipped with a warning and counted.
"""

import os
import queue
import threading

import cv2

from lanelib.camera import aspect_problem
from lanelib.cli import warning
from lanelib.files import is_bag
from lanelib.topics import topic_of, topic_problem

IMAGE_EXTENSIONS = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.webp', '.pgm', '.ppm',
                    '.pnm')


class SourceError(Exception):
    """A source that cannot be opened; the message names it and says what to check."""


class CaptureSource:
    """Frames from cv2.VideoCapture: camera, video file, image-sequence pattern or URL."""

    def __init__(self, spec, capture_arg, live, timeout=None, warn=None):
        self.name = str(spec)
        self.live = live
        self.skipped = 0
        self._index = 0
        self.total = None
        self._arg = capture_arg
        self._timeout = timeout  # [s] for a URL: give up opening or reading after this long
        self._warn = warn or warning
        if timeout is not None:
            self._warn(f"opening '{spec}': waiting up to {timeout:g} s for it to answer "
                       '(--open-timeout; Ctrl-C gives up)')
        self._cap = self._open()
        if not self._cap.isOpened():
            self._cap.release()
            what = f'camera {spec}' if isinstance(capture_arg, int) else f"'{spec}'"
            if timeout is not None:
                raise SourceError(f'cannot open {what}: no stream from it within {timeout:g} s '
                                  '(check the URL and that the server is up, or raise '
                                  '--open-timeout)')
            raise SourceError(f'cannot open {what} with OpenCV VideoCapture '
                              '(check the index, path or URL, and that the format is readable)')
        count = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        if not live and count > 0:
            self.total = count
        self._ahead = None
        self.cut_short = not live and riff_cut_short(str(capture_arg))

    def _open(self):
        """cv2.VideoCapture; for a URL with its open and read timeouts, on a thread of its own so
        that Ctrl-C is heard while OpenCV waits (KeyboardInterrupt in the caller)."""
        if self._timeout is None:
            return cv2.VideoCapture(self._arg)
        ms = int(self._timeout * 1000)
        opened, failed = [], []

        def open_url():
            try:
                opened.append(cv2.VideoCapture(
                    self._arg, cv2.CAP_FFMPEG, [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms,
                                                cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms]))
            except Exception as e:  # cv2.error: said as the source's error, not a traceback
                failed.append(e)

        worker = threading.Thread(target=open_url, name='open-url', daemon=True)
        worker.start()
        while worker.is_alive():
            worker.join(0.1)
        if not opened:  # before: an IndexError here, a traceback and exit status 1
            raise SourceError(f"cannot open '{self.name}': OpenCV failed while opening it "
                              f'({str(failed[0]).strip() if failed else "no reason given"})')
        return opened[0]

    def read(self):
        if self.live:
            return self._read()
        # a video file is read one frame ahead: the last frame of a file cut short (an AVI
        # whose RIFF header promises more bytes than there are) decodes only in part, and is
        # not handed out
        if self._ahead is None:
            self._ahead = self._read()
        item, self._ahead = self._ahead, self._read()
        if item[0] and not self._ahead[0] and self.cut_short:
            self.skipped += 1
            self._warn(f"'{self.name}' is cut short (truncated): its last frame, {item[2]}, "
                       'did not decode whole and is not used')
            return self._ahead
        return item

    def _read(self):
        ok, frame = self._cap.read()
        if not ok or frame is None:
            return False, None, self._index
        label = self._index
        self._index += 1
        return True, frame, label

    def reopen(self):
        """Open the camera or stream again (after it stopped giving frames); True if it opened."""
        self._cap.release()
        self._cap = self._open()
        return self._cap.isOpened()

    def release(self):
        self._cap.release()


class FolderSource:
    """Image files from a folder (sorted by name) or a single image file."""

    live = False

    def __init__(self, spec, files, warn=None):
        self.name = str(spec)
        self.skipped = 0
        self._files = list(files)
        self.total = len(self._files)
        self._next = 0
        self._warn = warn or warning

    def read(self):
        while self._next < len(self._files):
            path = self._files[self._next]
            self._next += 1
            frame = None if truncated(path) else cv2.imread(path, cv2.IMREAD_UNCHANGED)
            if frame is None or frame.size == 0:
                self.skipped += 1
                self._warn(f'skipped {path}: not a readable image (corrupt or truncated)')
                continue
            return True, frame, os.path.basename(path)
        return False, None, None

    def release(self):
        pass


class ListSource:
    """Frames already in memory (tests, the simulator); labels are their indices."""

    live = False

    def __init__(self, frames, name='frames'):
        self.name = name
        self.skipped = 0
        self._frames = list(frames)
        self.total = len(self._frames)
        self._next = 0

    def read(self):
        if self._next >= len(self._frames):
            return False, None, None
        self._next += 1
        return True, self._frames[self._next - 1], self._next - 1

    def release(self):
        pass


class Peeked:
    """A source whose first frame has been read already (`first`: its read() result), so that
    its size can be checked before the run; read() hands it out first."""

    def __init__(self, source):
        self.source = source
        self.name, self.live, self.total = source.name, source.live, source.total
        self.first = source.read()
        self._first = self.first

    @property
    def skipped(self):
        return self.source.skipped

    def read(self):
        if self._first is not None:
            item, self._first = self._first, None
            return item
        return self.source.read()

    def __getattr__(self, name):  # reopen, release, silence: the source's own
        if name == 'source':
            raise AttributeError(name)
        return getattr(self.source, name)


BIG = 4_000_000  # [pixels] frames larger than this take long (an 8000x6000 one: 7.5 s, 1.1 GB)


def size_warning(frame):
    """A word for frames so large that each takes seconds, or None."""
    h, w = frame.shape[:2]
    if h * w <= BIG:
        return None
    return (f'frames are {w}x{h} ({h * w / 1e6:.0f} megapixels): each takes seconds and much '
            'memory (an 8000x6000 one took 7.5 s and 1.1 GB); the lecture used 640x480, so '
            'scale them down first (e.g. ffmpeg -vf scale=640:-1, or the camera driver)')


class Prefetch:
    """Reads a file source ahead on a second thread, so decoding overlaps processing; the
    loop gets the same frames in the same order. Not for live sources: a queue of frames
    read ahead would be a queue of stale views."""

    def __init__(self, source, depth=4):
        self.source = source
        self.name, self.live, self.total = source.name, source.live, source.total
        self._queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._last = None  # the end-of-input item, once seen
        self._thread = threading.Thread(target=self._fill, name='prefetch', daemon=True)
        self._thread.start()

    @property
    def skipped(self):
        return self.source.skipped

    def _put(self, item):
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    def _fill(self):
        try:
            while not self._stop.is_set():
                item = self.source.read()
                self._put(item)
                if not item[0]:
                    return
        except Exception as e:  # handed to the loop's thread, raised by read()
            self._put(e)

    def read(self):
        if self._last is not None:
            return self._last
        item = self._queue.get()
        if isinstance(item, Exception):
            self._last = (False, None, None)
            raise item
        if not item[0]:
            self._last = item
        return item

    def release(self):
        self._stop.set()
        self._thread.join(timeout=5)
        self.source.release()

    def __getattr__(self, name):  # cut_short and the like: the source's own
        if name == 'source':
            raise AttributeError(name)
        return getattr(self.source, name)


def riff_cut_short(path):
    """True if a RIFF file (AVI) is shorter than its header says: a recording cut off by a
    crash or a copy that stopped (cv2.VideoCapture reads it without a word)."""
    if not os.path.isfile(path):
        return False
    with open(path, 'rb') as f:
        head = f.read(12)
    if len(head) < 12 or head[:4] != b'RIFF' or head[8:12] != b'AVI ':
        return False
    return int.from_bytes(head[4:8], 'little') + 8 > os.path.getsize(path)


def is_image_file(path):
    return path.lower().endswith(IMAGE_EXTENSIONS)


def truncated(path):
    """True if a JPEG or PNG file stops before its end marker (OpenCV would decode the part
    that is there and fill the rest with grey, without a word)."""
    ending = {'.jpg': b'\xff\xd9', '.jpeg': b'\xff\xd9', '.png': b'IEND\xaeB`\x82'}
    marker = ending.get(os.path.splitext(path)[1].lower())
    if marker is None:
        return False
    with open(path, 'rb') as f:
        f.seek(0, os.SEEK_END)
        f.seek(max(f.tell() - 64, 0))
        return marker not in f.read()


def open_source(spec, warn=None, image_topic=None, rospy=None, fresh=0.4, timeout=10.0):
    """Open what --source names; SourceError if it cannot be opened. rospy: the real rospy,
    for a live image topic (ros:TOPIC), whose frames older than `fresh` seconds are not used;
    timeout [s]: how long a URL may take to answer (KeyboardInterrupt on Ctrl-C meanwhile)."""
    spec = str(spec)
    topic = topic_of(spec)
    if topic is not None:
        from lanelib.topics import TopicSource

        problem = topic_problem(topic)
        if problem or rospy is None:
            raise SourceError(problem or f"cannot open '{spec}': a live topic needs a ROS master")
        return TopicSource(rospy, topic, fresh=fresh, wait=fresh)
    if is_bag(spec):
        from lanelib.bags import BagError, BagSource

        try:
            return BagSource(spec, image_topic, warn)
        except BagError as e:
            raise SourceError(str(e)) from None
    if spec.isdigit():
        return CaptureSource(spec, int(spec), live=True)
    if '://' in spec:
        return CaptureSource(spec, spec, live=True, timeout=timeout, warn=warn)
    if '%' in spec:
        folder = os.path.dirname(spec) or '.'
        if not os.path.isdir(folder):
            raise SourceError(f"cannot open '{spec}': folder '{folder}' does not exist")
        return CaptureSource(spec, spec, live=False, warn=warn)
    if os.path.isdir(spec):
        files = sorted(os.path.join(spec, f) for f in os.listdir(spec) if is_image_file(f))
        if not files:
            raise SourceError(f"folder '{spec}' has no image files ({', '.join(IMAGE_EXTENSIONS)})")
        return FolderSource(spec, files, warn)
    if not os.path.exists(spec):
        raise SourceError(f"cannot open '{spec}': no such file or folder "
                          "(give a camera index, video, image folder, %04d pattern or URL)")
    if os.path.getsize(spec) == 0:
        raise SourceError(f"cannot open '{spec}': the file is empty")
    if is_image_file(spec):
        if cv2.imread(spec, cv2.IMREAD_UNCHANGED) is None:
            raise SourceError(f"cannot open '{spec}': not a readable image")
        if truncated(spec):
            raise SourceError(f"cannot open '{spec}': the image is truncated")
        return FolderSource(spec, [spec], warn)
    return CaptureSource(spec, spec, live=False, warn=warn)


class FrameError(ValueError):
    """A frame the node cannot use as it is; the message says why."""


class FrameCheck:
    """Looks at each frame whose size differs from the last one's (a camera can switch its
    resolution mid-run, a folder can hold pictures of several sizes): one that a calibration
    made at another aspect ratio would stretch is refused (FrameError: the loop stops the robot
    for it), and frames that would take seconds each are said to. camera: a calibration with
    a size (a file, the topic's), or None (the lecture's camera scales to any frame)."""

    def __init__(self, camera, warn):
        self.camera, self.warn = camera, warn
        self.size = None  # the last size seen

    def __call__(self, frame):
        h, w = frame.shape[:2]
        if (w, h) == self.size:
            return
        problem = self.camera is not None and aspect_problem(self.camera, w, h)
        if problem:
            raise FrameError(problem)  # (and so again for the next frame of this size)
        was, self.size = self.size, (w, h)
        if was is not None:
            self.warn('frames are %dx%d now (were %dx%d)', w, h, *was)
        said = size_warning(frame)
        if said:
            self.warn('%s', said)


def check_first_frame(source, check):
    """Before anything runs (no output made yet): a file source with no readable frame, or
    whose first frame `check` (a FrameCheck) refuses, is refused (SourceError)."""
    ok, frame, _ = source.first
    if not ok and not source.live:  # refused before any output is made
        source.release()
        raise SourceError(f"no frame could be read from '{source.name}' (corrupt, truncated or "
                          'an unsupported format?)')
    if not ok:
        return
    try:
        check(frame)
    except FrameError as e:
        source.release()
        raise SourceError(str(e)) from None
