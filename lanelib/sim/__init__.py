"""The simulator: a floor of tape lines seen through a camera on a Kobuki-like base.

    world      the floor map, the camera that renders it, the scene (lighting, noise)
    tracks     track files and the built-in tracks
    base       the differential-drive base: limits, latency, the driver's timeout
    simulator  the robot on a track as a frame source for the node's loop; metrics, pictures
"""
