"""The improved controller's steering law: one function from a point of the lane to a Twist.

The robot steers at a point of the centre line x [m] ahead and y [m] to its left, where the line
has slope dy/dx. The commanded path curvature is

    k_cmd = alpha * 2 y / x^2 + (1 - alpha) * slope / x

On a circle of radius R both terms are 1/R (to first order in x / R), so there is no steady-state
error. With offset e [m, + left of centre] and heading h [rad, + turned left], y ~ -e - x h +
x^2 / 2R and slope ~ -h + x / R, so this is PD on offset (gain 2 alpha / x^2) and heading
((1 + alpha) / x) with curvature feed-forward; alpha = 1 is pure pursuit, alpha = 3 (damping
ratio 0.82) closes in on the centre line about 1.7 times faster per metre.

Written exactly for the circle through the robot (2 y / (x^2 + y^2), and the heading over the
arc's length) it measured better on gentle bends (the oval's: 0.3 cm RMS against 1.4) and far
worse on Duckietown's tight corners, where the robot ran wide and left the lane in 11 of 12
episodes of its simulator (with this law, 0 of 4): the estimate of a bend seen briefly is
straighter than the bend, and this law's over-steer on bends is what makes up for it.

Its limit: both terms are 1/R only to first order in x / R. Where the point lies far round a
bend (x near R: the Kobuki's 0.55 m on a bend of 0.6 to 0.75 m), the slope there grows without
bound, and weighed by 1 - alpha it turns the robot against the bend: on a circle, at 0.7 of
the bend's curvature at x = 0.7 R, 0.4 of it at 0.8 R, against the bend from x = 0.87 R.
With `direction` 'angle' the law reads the line's direction as its angle, atan(slope): the
same to first order, on a circle 1/R + 0.42 x^2 / R^3 (the slope: 1/R - 0.25 x^2 / R^3), and
never against the bend for x up to R. An option, not the default (docs/benchmarks.md,
sixty-second session): on the Kobuki's S-bends drawn after tuning, started four ways a little
off the centre line, it completed 61 of 80 runs against 50; but its over-steer on a steady bend
cuts inside it: in `simulate.py --benchmark` the wood world's `tight` ran at RMS 3.1 cm, over
the 3 cm target, the lecture webcam's hairpin at 9.3 cm against at most 8.1, and in gym-duckietown's
corners a tile tight the Duckiebot left the road on loop_empty. There the point often lies
beyond the bend's radius (an inner lane's 0.18 m corner seen 0.37 m ahead), and on a real
Duckietown frame (316closed_0082: the point straight ahead, the line there turned 19 degrees
left) the slope turns the robot right. Written from the robot's offset and heading to the lane
where it is, with the curvature fed forward, the law is exact on any bend, but measured so it
ran wide on the outer lane's corners, for the reason above (docs/benchmarks.md, thirteenth
session).

A second limit: a bend that begins between the robot and the point. On a lane straight to s0
and bent beyond it (y = c (x - s0)^2), the law gives 2 c u (alpha u + 1 - alpha), u = (x - s0) /
x: with alpha 3, against the bend wherever it begins beyond a third of the way to the point.
Read instead as if the lane bent evenly from the robot to the point (pure pursuit plus PD on
the robot's own offset and heading), the law turned more real frames' first commands the
labelled way, but completed fewer of the Kobuki's S-bends and drove Duckietown's corners less
tightly: not kept (docs/benchmarks.md, sixty-third session).

Speed: v_max, divided by (1 + curve_slowdown |k_cmd|) on bends (with slow_ahead, the sharper of
|k_cmd| and the lane's sharpest bend ahead: on the inside of a corner's entry re-centring cancels
the bend in k_cmd, and the robot came to the corner at full speed), times
(1 - unsure_slowdown (1 - confidence)) (the lecture's Kobuki: half speed when the estimate is
unsure), never below v_min; angular.z = v k_cmd within omega_max.
"""

import math

import numpy as np


def curvature(x, y, slope, alpha, angle=False):
    """k_cmd [1/m] towards the point (x, y) [m] where the centre line has `slope` (module doc);
    with `angle`, the slope's angle atan(slope) in its place; 0 for a point not ahead."""
    if x <= 1e-9:
        return 0.0
    direction = math.atan(slope) if angle else slope
    return alpha * 2.0 * y / (x * x) + (1.0 - alpha) * direction / x


def command(k_cmd, confidence, p, bend=0.0):
    """(linear.x [m/s], angular.z [rad/s]) for a commanded curvature [1/m] and the estimate's
    confidence (0..1); p: ImprovedParams in metres (module doc); bend [1/m]: the lane's
    sharpest curvature ahead (slow_ahead), slowing as the turn asked would."""
    unsure = p.unsure_slowdown  # written so that 0.5 gives the bits 0.5 + 0.5 confidence gave
    sharpest = max(abs(k_cmd), abs(bend))
    v = p.v_max / (1.0 + p.curve_slowdown * sharpest) * ((1.0 - unsure) + unsure * confidence)
    v = float(np.clip(v, p.v_min, p.v_max))
    return v, float(np.clip(v * k_cmd, -p.omega_max, p.omega_max))


def steer(x, y, slope, confidence, p, alpha=None, bend=0.0):
    """(linear.x, angular.z) at the point (x, y) of the centre line with `slope` there, the
    law's alpha p.lateral_gain unless given (1: pure pursuit); bend: as in command."""
    return command(curvature(x, y, slope, p.lateral_gain if alpha is None else alpha,
                             p.direction == 'angle'), confidence, p, bend)
