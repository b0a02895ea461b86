"""The improved controller on a slower base than the simulator's default, in the lecture's world.

Its lane memory rests on dead reckoning on the commands it sent; a base that accelerates slowly
and answers late moves differently from what was commanded. This runs every built-in track,
clean and with the benchmark's 20 cm gap, on two such bases, and prints a Markdown table:

    slow       0.5 m/s^2, 0.15 s from publish to wheels, starting 5 cm left and 0.1 rad askew
    slower     0.3 m/s^2, 0.25 s, starting 5 cm right and 0.15 rad askew

each twice: the lane memory dead-reckoning on the commands, and following the base's odometry
(/odom through the stand-in, as kobuki_node publishes it; with --slip and --odom-noise, the
wheels slipping and the odometry noisy).

usage (from the repository root):
    python -m tools.slow_base [--jobs 2] [--slip 0.03] [--odom-noise 0.02]
"""

import argparse
import sys
from dataclasses import replace
from multiprocessing import Pool

from lanelib.sim.base import BaseLimits
from lanelib.sim.simulator import apply_variant
from lanelib.sim.tracks import LANE_TRACKS, load_track
from simulate import run

BASES = {
    'slow': dict(limits=BaseLimits(accel=0.5, latency=0.15), start_offset=0.05, start_yaw=0.1),
    'slower': dict(limits=BaseLimits(accel=0.3, latency=0.25), start_offset=-0.05,
                   start_yaw=0.15),
}


def _job(job):
    base, track, variant, odometry, slip, noise = job
    setting = dict(BASES[base])
    setting['limits'] = replace(setting['limits'], slip=slip, odom_noise=noise)
    result = run(apply_variant(load_track(track), variant), 'improved', odometry=odometry,
                 **setting)
    return base, track, variant, odometry, result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--jobs', type=int, default=2, help='processes (default 2)')
    parser.add_argument('--slip', type=float, default=0.0,
                        help='with odometry: the wheels turn this fraction more than the robot '
                             'moves (default 0)')
    parser.add_argument('--odom-noise', type=float, default=0.0,
                        help="with odometry: sigma of its turn rate error [rad/s] (default 0)")
    args = parser.parse_args(argv)
    work = [(b, t, v, o, args.slip, args.odom_noise) for o in (False, True) for b in BASES
            for v in ('clean', 'gap 20 cm') for t in LANE_TRACKS]
    with Pool(max(1, args.jobs)) as pool:
        results = pool.map(_job, work)
    print('| memory | base | track | condition | completed | RMS offset | max offset | '
          'mean speed | departures | ended |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for base, track, variant, odometry, r in results:
        print(f"| {'odometry' if odometry else 'dead reckoning'} | {base} | {track} | "
              f"{variant} | {'yes' if r['completed'] else 'no'} | "
              f"{r['rms_offset_m'] * 100:.1f} cm | {r['max_offset_m'] * 100:.1f} cm | "
              f"{r['mean_speed_mps']:.3f} m/s | {r['departures']} | {r['ended']} |")
    for odometry in (False, True):
        runs = [r for *_, o, r in results if o == odometry]
        print(f"\n{'odometry' if odometry else 'dead reckoning'}: "
              f"{sum(r['completed'] for r in runs)} of {len(runs)} runs completed, "
              f"{sum(r['departures'] for r in runs)} departures", end='')
    print()
    return 0


if __name__ == '__main__':
    sys.exit(main())
