"""The improved controller on a slower base than the simulator's default, in the lecture's world.

Its lane memory rests on dead reckoning on the commands it sent; a base that accelerates slowly
and answers late moves differently from what was commanded. This runs every built-in track,
clean and with the benchmark's 20 cm gap, on two such bases, and prints a Markdown table:

    slow       0.5 m/s^2, 0.15 s from publish to wheels, starting 5 cm left and 0.1 rad askew
    slower     0.3 m/s^2, 0.25 s, starting 5 cm right and 0.15 rad askew

usage (from the repository root):
    python -m tools.slow_base [--jobs 2]
"""

import argparse
import sys
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
    base, track, variant = job
    result = run(apply_variant(load_track(track), variant), 'improved', **BASES[base])
    return base, track, variant, result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--jobs', type=int, default=2, help='processes (default 2)')
    args = parser.parse_args(argv)
    work = [(b, t, v) for b in BASES for v in ('clean', 'gap 20 cm') for t in LANE_TRACKS]
    with Pool(max(1, args.jobs)) as pool:
        results = pool.map(_job, work)
    print('| base | track | condition | completed | RMS offset | max offset | mean speed | '
          'departures | ended |')
    print('|---|---|---|---|---|---|---|---|---|')
    for base, track, variant, r in results:
        print(f"| {base} | {track} | {variant} | {'yes' if r['completed'] else 'no'} | "
              f"{r['rms_offset_m'] * 100:.1f} cm | {r['max_offset_m'] * 100:.1f} cm | "
              f"{r['mean_speed_mps']:.3f} m/s | {r['departures']} | {r['ended']} |")
    done = sum(r['completed'] for *_, r in results)
    print(f'\n{done} of {len(results)} runs completed')
    return 0


if __name__ == '__main__':
    sys.exit(main())
