"""ROS 1 bags for kobuki_lane, with the rosbags package (no ROS needed to read or write them).

    BagRecorder   --bag out.bag: every Twist the node sends, at the time it was sent, on
                  /mobile_base/commands/velocity; with --bag-images also the annotated frames as
                  sensor_msgs/CompressedImage (JPEG) on /kobuki_lane/debug_image/compressed
    BagSource     --source run.bag --image-topic T: sensor_msgs/Image (bgr8, rgb8, bgra8, rgba8,
                  mono8, mono16, 8UC1, 8UC3) or sensor_msgs/CompressedImage, in recorded order
    camera_from_bag  --calibration topic with such a source: the first sensor_msgs/CameraInfo
                  recorded beside the image topic, as on the robot

Bags written here open in Debian's `rosbag info` and `rosbag.Bag`; the tests check both ways.
"""

import contextlib
import os
import struct
import threading
import time

import numpy as np

from lanelib.cli import warning
from lanelib.imagemsg import DEBUG_IMAGE, ImageMessageError, decode_image, jpeg

IMAGE_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage')
DEBUG_TOPIC = '/kobuki_lane/' + DEBUG_IMAGE  # the node's, as a node named kobuki_lane has it


class BagError(ValueError):
    """A bag that cannot be used as asked; the message says what the bag has."""


def typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC)


def _describe(connections):
    topics = sorted({(c.topic, c.msgtype.replace('/msg/', '/')) for c in connections})
    return ', '.join(f'{t} ({m})' for t, m in topics) or 'no topics at all'


def _images(reader, path, topic=None):
    """(topic, connections) of the bag's images on `topic`, or on its one image topic; BagError
    saying what the bag has when that is not one."""
    conns = list(reader.connections)
    images = [c for c in conns if c.msgtype in IMAGE_TYPES]
    if topic is None:
        if len({c.topic for c in images}) != 1:
            raise BagError(f"'{path}': say which image topic with --image-topic; the bag "
                           f'has {_describe(conns)}')
        topic = images[0].topic
    chosen = [c for c in images if c.topic == topic]
    if not chosen:
        raise BagError(f"'{path}' has no sensor_msgs/Image or CompressedImage messages on "
                       f"'{topic}'; it has {_describe(conns)}")
    return topic, chosen


def _open(path):
    """An open rosbags Reader of `path`; BagError when it cannot be opened as a ROS 1 bag."""
    from rosbags.rosbag1 import Reader, ReaderError

    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, ValueError) as e:
        raise BagError(f"cannot open '{path}' as a ROS 1 bag: {e}") from None
    return reader


def _recorded(reader, topic, msgtype):
    """(stamp [ns], message) of each `msgtype` message on `topic`, in recorded order; none
    when the bag has none there (given no connections, rosbags reads them all)."""
    conns = [c for c in reader.connections if c.topic == topic and c.msgtype == msgtype]
    store = typestore()
    for conn, stamp, raw in reader.messages(connections=conns) if conns else ():
        yield stamp, store.deserialize_ros1(raw, conn.msgtype)


def camera_from_bag(path, image_topic=None):
    """(lanelib.camera.Camera, camera_info topic) from the bag's first sensor_msgs/CameraInfo
    beside its image topic (`image_topic`, or its only one): --calibration topic on a recorded
    run, as on the robot. BagError if the bag cannot be read or has none there; TopicError
    (lanelib.topics) if the one it has holds no usable calibration."""
    from lanelib.topics import camera_from_info, info_topic

    reader = _open(path)
    try:
        image_topic = _images(reader, path, image_topic)[0]
        topic = info_topic(image_topic)
        for _, info in _recorded(reader, topic, 'sensor_msgs/msg/CameraInfo'):
            where = f"the first camera_info on {topic} in '{path}'"
            return camera_from_info(info, where, topic), topic
        raise BagError(f"--calibration topic: '{path}' has no sensor_msgs/CameraInfo on {topic} "
                       f'(beside {image_topic}); it has {_describe(reader.connections)}: give '
                       '--calibration FILE (a camera_info YAML), or record the camera_info too')
    finally:
        reader.close()


class _Feed:
    """What lanelib.topics.Odometry needs of rospy, for messages handed to it from a bag: its
    one subscriber's callback kept, the node's logging."""

    def __init__(self, ros):
        self.loginfo, self.logwarn, self.callback = ros.loginfo, ros.logwarn, None

    def Subscriber(self, topic, msg_type, callback, queue_size=None):  # noqa: N802 (rospy's)
        self.callback = callback
        return self

    def unregister(self):
        self.callback = None


class BagOdometry:
    """The nav_msgs/Odometry recorded in a bag, for the improved controller replaying the
    bag's frames: each message reaches a lanelib.topics.Odometry (its checks, its timeout) when
    the frames' recorded time reaches the time it was recorded, as it came on the robot.
    pose(now) takes `now` on the bag's clock (the frame's label: LaneFollower.frame_time)."""

    timed = True

    def __init__(self, path, topic, ros):
        from rosbags.rosbag1 import ReaderError

        from lanelib.topics import Odometry

        reader = _open(path)
        try:
            self._messages = [(stamp * 1e-9, msg) for stamp, msg in
                              _recorded(reader, topic, 'nav_msgs/msg/Odometry')]
        except (ReaderError, OSError, ValueError) as e:  # a bag cut short
            raise BagError(f"cannot open '{path}' as a ROS 1 bag: {e}") from None
        finally:
            reader.close()
        self.topic, self._next, self._now = topic, 0, -np.inf
        self._feed = _Feed(ros)
        self._odometry = Odometry(self._feed, topic, msg_type=object, clock=lambda: self._now)

    def __len__(self):
        return len(self._messages)

    def pose(self, now):
        while self._next < len(self._messages) and self._messages[self._next][0] <= now:
            self._now, msg = self._messages[self._next]
            self._next += 1
            if self._feed.callback is not None:
                self._feed.callback(msg)
        self._now = now
        return self._odometry.pose(now)

    def release(self):
        self._odometry.release()


def odometry_from_bag(path, topic, ros):
    """BagOdometry for --odom TOPIC (default /odom) over a --source bag, or None for 'none' or
    when the bag has no odometry there (said: the lane memory then dead-reckons)."""
    topic = topic or '/odom'
    if topic == 'none':
        return None
    odometry = BagOdometry(path, topic, ros)
    if not len(odometry):
        ros.loginfo('no nav_msgs/Odometry on %s in %s: the lane memory dead-reckons on the '
                    'commands', topic, path)
        return None
    return odometry


class BagSource:
    """Image messages from a ROS 1 bag as frames; labels are the message stamps' seconds."""

    live = False
    timed = True  # the labels are when the frames were recorded (LaneFollower.frame_time)

    def __init__(self, path, topic=None, warn=None):
        self.skipped = 0
        self._warn = warn or warning
        self.name = str(path)
        self._store = typestore()
        self._reader = _open(path)
        try:
            topic, chosen = _images(self._reader, path, topic)
        except BagError:
            self._reader.close()
            raise
        self.topic = topic
        self.total = sum(c.msgcount for c in chosen)
        self._messages = self._reader.messages(connections=chosen)
        self._started = False  # a bad first frame is an error (sources.Peeked reads it at start)

    def _decode(self, conn, raw):
        msg = self._store.deserialize_ros1(raw, conn.msgtype)
        try:
            return decode_image(msg, conn.msgtype.endswith('CompressedImage'),
                                f"'{self.topic}' in '{self.name}'")
        except ImageMessageError as e:
            raise BagError(str(e)) from None

    def read(self):
        first, self._started = not self._started, True
        for conn, stamp, raw in self._messages:
            try:
                return True, self._decode(conn, raw), round(stamp * 1e-9, 6)
            except BagError as e:
                if first:  # the first frame: the bag cannot be used as asked, said at start
                    raise
                self.skipped += 1  # later ones: skipped, said, counted, as unreadable files
                self._warn(f'skipped a frame at {stamp * 1e-9:.3f} s: {e}')
        return False, None, None

    def release(self):
        self._reader.close()


HEADER_AT = 13  # [bytes] the bag header record follows the '#ROSBAG V2.0' line


def bag_header(index_pos=0, connections=0, chunks=0):
    """The bag header record as Debian's rosbag writes it: the header padded with spaces to
    4096 bytes, 4104 with the two lengths. rosbags pads the record to 4096 in all, and
    `rosbag reindex`, rewriting the header its own way, then overwrote the first 8 bytes of the
    first chunk: a killed bag could not be mended."""
    fields = [(b'op', b'\x03'), (b'index_pos', struct.pack('<Q', index_pos)),
              (b'conn_count', struct.pack('<I', connections)),
              (b'chunk_count', struct.pack('<I', chunks))]
    header = b''.join(struct.pack('<I', len(k) + 1 + len(v)) + k + b'=' + v for k, v in fields)
    return (struct.pack('<I', len(header)) + header + struct.pack('<I', 4096 - len(header)) +
            b' ' * (4096 - len(header)))


def _write_header(f, index_pos=0, connections=0, chunks=0):
    f.seek(HEADER_AT)
    f.write(bag_header(index_pos, connections, chunks))


def _read_header_counts(f):
    """(index_pos, conn_count, chunk_count) of the header record at HEADER_AT."""
    f.seek(HEADER_AT)
    size = struct.unpack('<I', f.read(4))[0]
    data, values, at = f.read(size), {}, 0
    while at < size:
        n = struct.unpack('<I', data[at:at + 4])[0]
        name, value = data[at + 4:at + 4 + n].split(b'=', 1)
        values[name] = value
        at += 4 + n
    return (struct.unpack('<Q', values[b'index_pos'])[0],
            struct.unpack('<I', values[b'conn_count'])[0],
            struct.unpack('<I', values[b'chunk_count'])[0])


class BagRecorder:
    """Writes what the node sends into a new ROS 1 bag; close() makes it complete. Every
    `flush_every` seconds what has come is written out as a chunk and flushed to the disk, so
    a run killed outright (SIGKILL, power loss) loses at most that last stretch, and
    `rosbag reindex` makes the rest readable."""

    def __init__(self, path, command_topic, images=False, flush_every=1.0):
        from rosbags.rosbag1 import Writer, WriterError

        self.path = path
        self._store = typestore()
        try:  # (made only if it does not exist: two runs given one --bag cannot share it)
            self._writer = Writer(path)
            self._writer.open()
        except (WriterError, FileExistsError):
            raise BagError(f"bag '{path}' exists already (another run writing it?); remove it "
                           'or choose another name') from None
        except OSError as e:
            self._abandon()
            raise BagError(f"cannot write bag '{path}': {e.strerror}") from None
        try:
            _write_header(self._writer.bio)  # Debian's layout, so rosbag reindex can mend it
        except OSError as e:
            self._abandon()
            raise BagError(f"cannot write bag '{path}': {e.strerror}") from None
        self._twist = self._writer.add_connection(command_topic, 'geometry_msgs/msg/Twist',
                                                  typestore=self._store)
        self._image = (self._writer.add_connection(DEBUG_TOPIC, 'sensor_msgs/msg/CompressedImage',
                                                   typestore=self._store) if images else None)
        self.images = images
        self._seq = 0
        self._epoch = None
        self._lock = threading.Lock()  # the watchdog's timer records its stops too
        self._flush_every, self._flushed = flush_every, time.monotonic()

    def _abandon(self):
        """The bag this made could not be begun (a full disk): closed and removed."""
        writer = getattr(self, '_writer', None)
        bio = getattr(writer, 'bio', None)
        if bio is not None:
            writer.bio = None
            with contextlib.suppress(OSError):  # (closing flushes: the disk is still full)
                bio.close()
        with contextlib.suppress(OSError):
            os.remove(self.path)

    def _flush(self):
        """The open chunk to the file, and the file to the disk (rosbag reindex cannot mend a
        chunk without messages: a chunk is written once it has some)."""
        # the next flush is due a stretch after this one began, not after the disk answered: a
        # slow fsync (a busy disk) must not lengthen the stretch a kill can lose
        self._flushed = time.monotonic()
        writer = self._writer
        if writer.chunks[-1].connections:
            writer.write_chunk(writer.chunks[-1])
        writer.bio.flush()
        os.fsync(writer.bio.fileno())

    def _write(self, connection, ns, data):
        with self._lock:
            self._writer.write(connection, ns, data)
            if time.monotonic() - self._flushed >= self._flush_every:
                self._flush()

    def _ns(self, t):
        # a dry run's simulated clock starts at 0: such times are put after the wall time the
        # run started, so the bag's times are real dates
        if t < 1e9:
            if self._epoch is None:
                self._epoch = time.time() - t
            t += self._epoch
        return int(round(t * 1e9))

    def twist(self, t, linear_x, angular_z):
        types = self._store.types
        vector = types['geometry_msgs/msg/Vector3']
        msg = types['geometry_msgs/msg/Twist'](linear=vector(x=float(linear_x), y=0.0, z=0.0),
                                               angular=vector(x=0.0, y=0.0,
                                                              z=float(angular_z)))
        self._write(self._twist, self._ns(t),
                    self._store.serialize_ros1(msg, 'geometry_msgs/msg/Twist'))

    def image(self, t, bgr):
        if self._image is None:
            return
        types = self._store.types
        ns = self._ns(t)
        header = types['std_msgs/msg/Header'](
            seq=self._seq, stamp=types['builtin_interfaces/msg/Time'](sec=ns // 10**9,
                                                                      nanosec=ns % 10**9),
            frame_id='camera')
        msg = types['sensor_msgs/msg/CompressedImage'](header=header, format='jpeg',
                                                       data=np.frombuffer(jpeg(bgr), np.uint8))
        self._seq += 1
        self._write(self._image, ns,
                    self._store.serialize_ros1(msg, 'sensor_msgs/msg/CompressedImage'))

    def close(self):
        """Write the index and Debian's header; OSError when they cannot be written (the file
        is closed all the same: the chunks flushed so far can be mended with rosbag reindex)."""
        with self._lock:
            try:
                self._writer.close()  # the index, and rosbags' own header: Debian's again
            except Exception:
                bio, self._writer.bio = self._writer.bio, None
                if bio is not None:
                    with contextlib.suppress(OSError):
                        bio.close()
                raise
            if not os.path.exists(self.path):
                raise OSError(f"the bag's folder was removed during the run: nothing of "
                              f"'{self.path}' is left")
            with open(self.path, 'r+b') as f:
                _write_header(f, *_read_header_counts(f))
