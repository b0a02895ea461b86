#!/usr/bin/env python3
"""A stand-in camera driver for rostest: the images of a folder, in name order and round again,
as sensor_msgs/Image (bgr8) on TOPIC at HZ, each stamped with the time it is sent.

    standin_camera.py FOLDER [TOPIC] [HZ]
"""

import os
import sys

import cv2
import rospy
from sensor_msgs.msg import Image


def main():
    args = rospy.myargv()[1:]
    folder = args[0]
    topic = args[1] if len(args) > 1 else 'camera/rgb/image_raw'
    hz = float(args[2]) if len(args) > 2 else 15.0
    rospy.init_node('camera')
    frames = [cv2.imread(os.path.join(folder, name), cv2.IMREAD_COLOR)
              for name in sorted(os.listdir(folder)) if name.endswith(('.png', '.jpg'))]
    if not frames:
        sys.exit(f'standin_camera.py: no .png or .jpg in {folder}')
    pub = rospy.Publisher(topic, Image, queue_size=1)
    h, w = frames[0].shape[:2]
    rate, i = rospy.Rate(hz), 0
    while not rospy.is_shutdown():
        frame = frames[i % len(frames)]
        msg = Image(height=h, width=w, encoding='bgr8', step=w * 3, data=frame.tobytes())
        msg.header.stamp, msg.header.frame_id = rospy.Time.now(), 'camera'
        pub.publish(msg)
        i += 1
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break


if __name__ == '__main__':
    main()
