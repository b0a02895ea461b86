"""kobuki_lane's library: everything the node needs besides the lecture itself.

kobuki_lane.py holds what the lecture shows (the defaults table, detect(), the rule, the loop);
this package holds the rest, one room each. Nothing here imports kobuki_lane.py or tools/, parses
a command line, or does anything at import time.

    settings       tables of defaults: unit, help and check per setting; flags and ROS params
    files          YAML read as YAML 1.2 reads numbers; can an output be written
    cli            the command lines' shared conventions (exit status 2 on a usage error)
    node           the node's wiring: arguments to a running loop and back to an exit status
    robots         robot presets (--robot kobuki|duckiebot|FILE, config/*.yaml)
    camera         the lecture's camera, camera_info YAML, undistortion maps
    stages         the lecture's stage functions: ROI triangle, HoughLinesP, the slope sum
    fast           a speed-up of kobuki_lane.detect(), proven identical to it
    robot          the Kobuki: Command, STOP, its speed limits, the unicycle step
    safety         watchdog, stop latch, limits, hold: every command goes through it
    outputs        decision records, annotated pictures, stage sheets, video, progress
    sources        frame sources behind --source
    bags           ROS 1 bags in and out (rosbags; no ROS needed)
    imagemsg       image messages to frames, and the debug image's name and JPEG
    ros            ROS plumbing: connecting, the master watch, names, the debug image topic
    topics         live topics read: a camera's images and camera_info, odometry
    watch          live topics written: decision, lane estimate; /diagnostics
    tuning         live tuning with dynamic_reconfigure (rqt_reconfigure)
    rospy_standin  a headless stand-in for rospy, for dry runs and tests
    standin_msgs   the message types it carries: Twist, Odometry
    improved       the improved controller (--controller improved): perceive, estimate, steer
    perception     its floor band, colour masks and tape pieces
    colour         colour masks in each frame's light, and the tape pieces they make
    lanes          lane profiles (--lane): what the lines look like, built in or from YAML
    lanefit        which lines are the robot's lane, and the arc that lane follows
    estimate       the lane estimate frame after frame: predict and blend
    memory         the lane memory: the centre line seen in the last seconds
    floorpitch     the camera's pitch read from the floor's motion, with odometry
    steering       one steering law from a point of the lane to a Twist
    lanedraw       the improved controller's pictures
    geometry       the camera's mounting: pixels to floor points and back
    mounting       the mounting measured from one picture of a chessboard (calibration.py)
    sim/           the simulator's world, tracks, base and the simulator frame source
"""
