"""Frame sources for kobuki_lane: everything --source accepts, behind one read() call.

    0, 1, ...            a camera index              cv2.VideoCapture(0)      live
    run.mp4              a video file                cv2.VideoCapture(path)
    frames/%04d.png      an image-sequence pattern   cv2.VideoCapture(pattern)
    rtsp://..., http://  any URL VideoCapture takes  cv2.VideoCapture(url)    live
    run.bag              a ROS 1 bag's image topic   bags.BagSource (--image-topic)
    samples/track/       a folder of images, read in name order
    picture.png          one image

read() returns (ok, frame, label): label is the file name for folders and images, the frame
index otherwise. Unreadable files in a folder are skipped with a warning and counted.
"""

import os
import queue
import sys
import threading

import cv2

IMAGE_EXTENSIONS = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.webp', '.pgm', '.ppm',
                    '.pnm')


class SourceError(Exception):
    """A source that cannot be opened; the message names it and says what to check."""


class CaptureSource:
    """Frames from cv2.VideoCapture: camera, video file, image-sequence pattern or URL."""

    def __init__(self, spec, capture_arg, live):
        self.name = str(spec)
        self.live = live
        self.skipped = 0
        self._index = 0
        self.total = None
        self._arg = capture_arg
        self._cap = cv2.VideoCapture(capture_arg)
        if not self._cap.isOpened():
            self._cap.release()
            what = f'camera {spec}' if isinstance(capture_arg, int) else f"'{spec}'"
            raise SourceError(f'cannot open {what} with OpenCV VideoCapture '
                              '(check the index, path or URL, and that the format is readable)')
        count = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        if not live and count > 0:
            self.total = count

    def read(self):
        ok, frame = self._cap.read()
        if not ok or frame is None:
            return False, None, self._index
        label = self._index
        self._index += 1
        return True, frame, label

    def reopen(self):
        """Open the camera or stream again (after it stopped giving frames); True if it opened."""
        self._cap.release()
        self._cap = cv2.VideoCapture(self._arg)
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
        self._warn = warn or (lambda msg: print(f'warning: {msg}', file=sys.stderr))

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


def open_source(spec, warn=None, image_topic=None):
    """Open what --source names; SourceError if it cannot be opened."""
    spec = str(spec)
    if spec.lower().endswith('.bag') and os.path.isfile(spec):
        from lanelib.bags import BagError, BagSource

        try:
            return BagSource(spec, image_topic)
        except BagError as e:
            raise SourceError(str(e)) from None
    if spec.isdigit():
        return CaptureSource(spec, int(spec), live=True)
    if '://' in spec:
        return CaptureSource(spec, spec, live=True)
    if '%' in spec:
        folder = os.path.dirname(spec) or '.'
        if not os.path.isdir(folder):
            raise SourceError(f"cannot open '{spec}': folder '{folder}' does not exist")
        return CaptureSource(spec, spec, live=False)
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
    return CaptureSource(spec, spec, live=False)
