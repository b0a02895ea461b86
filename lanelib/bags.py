"""ROS 1 bags for kobuki_lane, with the rosbags package (no ROS needed to read or write them).

    BagRecorder   --bag out.bag: every Twist the node sends, at the time it was sent, on
                  /mobile_base/commands/velocity; with --bag-images also the annotated frames as
                  sensor_msgs/CompressedImage (JPEG) on /kobuki_lane/debug_image/compressed
    BagSource     --source run.bag --image-topic T: sensor_msgs/Image (bgr8, rgb8, bgra8, rgba8,
                  mono8, mono16, 8UC1, 8UC3) or sensor_msgs/CompressedImage, in recorded order

Bags written here open in Debian's `rosbag info` and `rosbag.Bag`; the tests check both ways.
"""

import os
import time

import cv2
import numpy as np

IMAGE_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage')
ENCODINGS = {  # encoding: (dtype, channels, conversion to BGR or None)
    'bgr8': (np.uint8, 3, None), '8UC3': (np.uint8, 3, None),
    'rgb8': (np.uint8, 3, cv2.COLOR_RGB2BGR),
    'bgra8': (np.uint8, 4, cv2.COLOR_BGRA2BGR), 'rgba8': (np.uint8, 4, cv2.COLOR_RGBA2BGR),
    'mono8': (np.uint8, 1, None), '8UC1': (np.uint8, 1, None),
    'mono16': (np.uint16, 1, None), '16UC1': (np.uint16, 1, None),
}
DEBUG_TOPIC = '/kobuki_lane/debug_image/compressed'


class BagError(Exception):
    """A bag that cannot be used as asked; the message says what the bag has."""


def typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC)


def _describe(connections):
    topics = sorted({(c.topic, c.msgtype.replace('/msg/', '/')) for c in connections})
    return ', '.join(f'{t} ({m})' for t, m in topics) or 'no topics at all'


class BagSource:
    """Image messages from a ROS 1 bag as frames; labels are the message stamps' seconds."""

    live = False
    skipped = 0

    def __init__(self, path, topic=None):
        from rosbags.rosbag1 import Reader, ReaderError

        self.name = str(path)
        self._store = typestore()
        try:
            self._reader = Reader(path)
            self._reader.open()
        except (ReaderError, OSError, ValueError) as e:
            raise BagError(f"cannot open '{path}' as a ROS 1 bag: {e}") from None
        conns = list(self._reader.connections)
        images = [c for c in conns if c.msgtype in IMAGE_TYPES]
        if topic is None:
            if len({c.topic for c in images}) != 1:
                has = _describe(conns)
                self._reader.close()
                raise BagError(f"'{path}': say which image topic with --image-topic; the bag "
                               f'has {has}')
            topic = images[0].topic
        chosen = [c for c in images if c.topic == topic]
        if not chosen:
            has = _describe(conns)
            self._reader.close()
            raise BagError(f"'{path}' has no sensor_msgs/Image or CompressedImage messages on "
                           f"'{topic}'; it has {has}")
        self.topic = topic
        self.total = sum(c.msgcount for c in chosen)
        self._messages = self._reader.messages(connections=chosen)
        self._first = self._next_frame()  # fails here, not mid-run, on a bad encoding

    def _decode(self, conn, raw):
        msg = self._store.deserialize_ros1(raw, conn.msgtype)
        if conn.msgtype.endswith('CompressedImage'):
            frame = cv2.imdecode(np.asarray(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)
            if frame is None:
                raise BagError(f"'{self.name}': a CompressedImage on '{self.topic}' "
                               f"('{msg.format}') does not decode")
            return frame
        if msg.encoding not in ENCODINGS:
            raise BagError(f"'{self.name}': images on '{self.topic}' are '{msg.encoding}'; "
                           f"supported: {', '.join(ENCODINGS)}")
        dtype, channels, conversion = ENCODINGS[msg.encoding]
        dt = np.dtype(dtype).newbyteorder('>' if msg.is_bigendian else '<')
        rows = np.frombuffer(bytes(msg.data), np.uint8).reshape(msg.height, msg.step)
        frame = rows[:, :msg.width * channels * dt.itemsize].copy().view(dt)
        frame = frame.reshape(msg.height, msg.width, channels).astype(dtype)
        if channels == 1:
            frame = frame[:, :, 0]
        return cv2.cvtColor(frame, conversion) if conversion is not None else frame

    def _next_frame(self):
        for conn, stamp, raw in self._messages:
            return True, self._decode(conn, raw), round(stamp * 1e-9, 6)
        return False, None, None

    def read(self):
        if self._first is not None:
            item, self._first = self._first, None
            return item
        return self._next_frame()

    def release(self):
        self._reader.close()


class BagRecorder:
    """Writes what the node sends into a new ROS 1 bag; close() makes it complete."""

    def __init__(self, path, command_topic, images=False):
        from rosbags.rosbag1 import Writer

        if os.path.exists(path):
            raise BagError(f"bag '{path}' exists already; remove it or choose another name")
        self.path = path
        self._store = typestore()
        self._writer = Writer(path)
        self._writer.open()
        self._twist = self._writer.add_connection(command_topic, 'geometry_msgs/msg/Twist',
                                                  typestore=self._store)
        self._image = (self._writer.add_connection(DEBUG_TOPIC, 'sensor_msgs/msg/CompressedImage',
                                                   typestore=self._store) if images else None)
        self.images = images
        self._seq = 0
        self._epoch = None

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
        self._writer.write(self._twist, self._ns(t),
                           self._store.serialize_ros1(msg, 'geometry_msgs/msg/Twist'))

    def image(self, t, bgr):
        if self._image is None:
            return
        types = self._store.types
        ns = self._ns(t)
        ok, jpg = cv2.imencode('.jpg', bgr, [cv2.IMWRITE_JPEG_QUALITY, 80])
        header = types['std_msgs/msg/Header'](
            seq=self._seq, stamp=types['builtin_interfaces/msg/Time'](sec=ns // 10**9,
                                                                      nanosec=ns % 10**9),
            frame_id='camera')
        msg = types['sensor_msgs/msg/CompressedImage'](header=header, format='jpeg',
                                                       data=jpg.ravel())
        self._seq += 1
        self._writer.write(self._image, ns,
                           self._store.serialize_ros1(msg, 'sensor_msgs/msg/CompressedImage'))

    def close(self):
        self._writer.close()
