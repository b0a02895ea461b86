"""kobuki_lane's library: everything the node needs besides the lecture itself.

kobuki_lane.py holds what the lecture shows (the defaults table, detect(), the rule, the loop);
this package holds the rest, one room each. Nothing here imports kobuki_lane.py or tools/, parses
a command line, or does anything at import time.

    settings       tables of defaults: unit, help and check per setting; flags and ROS params
    camera         the lecture's camera, camera_info YAML, undistortion maps
    stages         the lecture's stage functions: ROI triangle, HoughLinesP, the slope sum
    fast           a speed-up of kobuki_lane.detect(), proven identical to it
    robot          the Kobuki: Command, STOP, its speed limits, the unicycle step
    safety         watchdog, stop latch, limits, hold: every command goes through it
    outputs        decision records, annotated pictures, stage sheets, video, progress
    ros            ROS plumbing: connecting, the master watch, the debug image topic
    rospy_standin  a headless stand-in for rospy, for dry runs and tests
    sources        frame sources behind --source; bags: ROS 1 bags in and out
    geometry       the camera's mounting: pixels to floor points and back
    improved       the improved controller (--controller improved): estimate and steering
    lanes          lane profiles (--lane): what the lines look like, built in or from YAML
    colour         colour masks in each frame's light, and the tape pieces they make
    lanefit        which lines are the robot's lane, and the arc that lane follows
    cli            the command lines' shared conventions (exit status 2 on a usage error)
    sim/           the simulator's world, tracks, base and the simulator frame source
"""
