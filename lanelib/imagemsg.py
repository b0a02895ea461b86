"""sensor_msgs/Image and CompressedImage to OpenCV frames, for bags and live topics alike, and
the debug image's one name and encoding, for the debug topic and the bag alike.

Both rosbags' messages and rospy's have the fields used here (height, width, step, encoding,
is_bigendian, data; format and data for CompressedImage).
"""

import cv2
import numpy as np

ENCODINGS = {  # encoding: (dtype, channels, conversion to BGR or None)
    'bgr8': (np.uint8, 3, None), '8UC3': (np.uint8, 3, None),
    'rgb8': (np.uint8, 3, cv2.COLOR_RGB2BGR),
    'bgra8': (np.uint8, 4, cv2.COLOR_BGRA2BGR), 'rgba8': (np.uint8, 4, cv2.COLOR_RGBA2BGR),
    'mono8': (np.uint8, 1, None), '8UC1': (np.uint8, 1, None),
    'mono16': (np.uint16, 1, None), '16UC1': (np.uint16, 1, None),
}


DEBUG_IMAGE = 'debug_image/compressed'  # in the node's namespace: /kobuki_lane/debug_image/...
JPEG_QUALITY = 80


def jpeg(image):
    """A BGR image as JPEG bytes (the debug image's CompressedImage data)."""
    ok, data = cv2.imencode('.jpg', image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError('OpenCV could not encode the picture as JPEG')
    return data.tobytes()


class ImageMessageError(ValueError):
    """An image message that does not make a frame; the message says why."""


def decode_image(msg, compressed, where):
    """The frame (BGR, or one channel for mono) in an image message; `where` names the topic
    (and bag) in the error."""
    if compressed:
        frame = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_UNCHANGED)
        if frame is None:
            raise ImageMessageError(f"a CompressedImage on {where} ('{msg.format}') does not "
                                    'decode')
        return frame
    if msg.encoding not in ENCODINGS:
        raise ImageMessageError(f"images on {where} are '{msg.encoding}'; supported: "
                                f"{', '.join(ENCODINGS)}")
    dtype, channels, conversion = ENCODINGS[msg.encoding]
    dt = np.dtype(dtype).newbyteorder('>' if msg.is_bigendian else '<')
    data = bytes(msg.data)
    row = msg.width * channels * dt.itemsize
    if msg.height <= 0 or msg.width <= 0 or msg.step < row or len(data) < msg.height * msg.step:
        raise ImageMessageError(
            f'an Image on {where} says {msg.width}x{msg.height} {msg.encoding}, step '
            f'{msg.step}, but holds {len(data)} bytes (needs {msg.height} rows of at least '
            f'{row})')
    rows = np.frombuffer(data, np.uint8, count=msg.height * msg.step).reshape(msg.height,
                                                                              msg.step)
    frame = rows[:, :row].copy().view(dt).reshape(msg.height, msg.width, channels)
    frame = frame.astype(dtype)
    if channels == 1:
        frame = frame[:, :, 0]
    return cv2.cvtColor(frame, conversion) if conversion is not None else frame
