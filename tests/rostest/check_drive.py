#!/usr/bin/env python3
"""rostest's check of the launched node (kobuki_lane.test): as the base, take the Twists on
mobile_base/commands/velocity; they come at ~rate (within 15 %); after `rosnode kill` of the
node, the last one is a zero Twist."""

import subprocess
import threading
import time
import unittest

import rospy
import rosunit
from geometry_msgs.msg import Twist


class Drive(unittest.TestCase):
    def setUp(self):
        self.got, self.lock = [], threading.Lock()
        self.sub = rospy.Subscriber('mobile_base/commands/velocity', Twist, self.received,
                                    queue_size=100)

    def received(self, msg):
        with self.lock:
            self.got.append((time.monotonic(), msg.linear.x, msg.angular.z))

    def wait_for(self, count, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if len(self.got) >= count:
                    return list(self.got)
            time.sleep(0.05)
        with self.lock:
            return list(self.got)

    def test_drives_at_its_rate_and_stops_on_shutdown(self):
        rate = rospy.get_param('~rate', 4.0)
        got = self.wait_for(int(6 * rate) + 2, timeout=60)
        self.assertGreaterEqual(len(got), 6 * rate, 'too few Twists: %d' % len(got))
        moving = [g for g in got[2:] if g[1] > 0]
        self.assertTrue(moving, 'the node never drove forward')
        times = [t for t, _, _ in got[2:]]
        measured = (len(times) - 1) / (times[-1] - times[0])
        self.assertLess(abs(measured - rate), 0.15 * rate, 'rate %.2f Hz' % measured)
        subprocess.run(['rosnode', 'kill', rospy.resolve_name('kobuki_lane')], check=True,
                       capture_output=True, timeout=30)
        time.sleep(2.0)
        with self.lock:
            last = self.got[-1]
        self.assertEqual(last[1:], (0.0, 0.0), 'the last Twist was not a stop: %r' % (last,))


if __name__ == '__main__':
    rospy.init_node('check_drive')
    rosunit.unitrun('kobuki_lane', 'drives', Drive)
