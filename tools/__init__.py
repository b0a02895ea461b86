"""Maintainers' tools, run as modules from the repository root (python -m tools.bench).

    bench             the pipeline's speed against the lecture's literal code and the floor
    soak              thousands of frames with faults injected, on the stand-in or real ROS
    evaluate_real     agreement with hand-labelled real camera frames
    make_samples      regenerate samples/track
    make_walkthrough  regenerate docs/img for docs/WALKTHROUGH.md
    roslive           a real roscore that can be crashed and restarted (tests, soak)
"""

import os

# numpy's BLAS one thread, as the node runs it (see kobuki_lane.py): set before numpy loads.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
