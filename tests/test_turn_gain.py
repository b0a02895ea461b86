"""How much of a turn asked for the base turns (robot.TurnResponse, ImprovedParams.turn_gain):
measured from odometry, and a base that turns less than asked asked for more."""

import math
from dataclasses import replace

import pytest

from lanelib.robot import TurnResponse

RATE = 8.0


def drive(response, share, seconds, lag=1, swing=1.0):
    """Feed `response` a base that turns `share` of the turn rate asked `lag` frames earlier,
    asked for a turn rate swinging between -swing and +swing [rad/s] every 1.5 s."""
    dt = 1.0 / RATE
    asked = [0.0] * lag
    for i in range(int(seconds * RATE)):
        asked.append(swing * math.sin(2 * math.pi * i * dt / 3.0))
        response.update(share * asked[-1 - lag] * dt, asked[-1] * dt, dt)


@pytest.mark.parametrize('share', [0.6, 1.0, 1.3])
def test_the_share_of_the_turn_asked_is_measured_from_odometry(share):
    response = TurnResponse()
    drive(response, share, 2.0)
    assert response.gain == 1.0  # two blocks hold too little turn to say
    drive(response, share, 20.0)
    assert response.gain == pytest.approx(share, rel=0.08)


def test_the_share_measured_stays_within_its_limits_and_follows_a_change():
    response = TurnResponse()
    drive(response, 0.1, 20.0)
    assert response.gain == 0.5
    drive(response, 3.0, 60.0)
    assert response.gain == 2.0
    drive(response, 0.8, 100.0)  # five memory times on: the older blocks forgotten
    assert response.gain == pytest.approx(0.8, rel=0.08)


def test_driving_straight_says_nothing_of_the_turn():
    response = TurnResponse()
    drive(response, 0.6, 60.0, swing=0.0)
    assert response.gain == 1.0


def test_a_base_that_turns_less_is_asked_for_more_only_with_turn_gain_measured():
    """The duckiebot preset in the project's simulator (the inner lane's tight corners) on a
    base that turns 0.6 of the turn asked: with turn_gain 'measured' and the base's odometry
    the controller measures about 0.6 and asks for the turns divided by it, and the robot keeps
    closer to its lane than asking as if the base turned as asked; on a base that turns as
    asked it measures about 1; 'assumed', or no odometry, measures nothing. Frames read whole:
    there it drove closer on seeds 0 to 3; read at 320 x 240, as the preset now reads them, on
    2 of the 4, this seed not among them (docs/benchmarks.md, forty-fifth session)."""
    import simulate
    from lanelib.improved import ImprovedController
    from lanelib.sim.base import BaseLimits

    spec = simulate.load_track('tools/tracks/duckietown_small_loop_cw.yaml')
    params, preset = simulate.robot_settings('duckiebot', spec)
    preset = replace(preset, read_width=0)
    made, sent = [], []

    def factory(improved):
        def make(name, spec, params, odometry=None):
            made.append(simulate.preset_factory(improved)(name, spec, params,
                                                          odometry=odometry))
            return made[-1]
        return make

    def recorded(self, command):  # every turn rate sent to the wheels
        sent.append(command.angular_z)
        send(self, command)

    send = ImprovedController.sent

    def run(turn_gain, share, odometry=True, time_limit=None):
        sent.clear()
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(ImprovedController, 'sent', recorded)
            return simulate.run(spec, 'improved', seed=0, params=params, odometry=odometry,
                                controller_factory=factory(replace(preset,
                                                                   turn_gain=turn_gain)),
                                limits=BaseLimits(turn_response=share),
                                time_limit=time_limit)

    measured = run('measured', 0.6)
    assert made[-1].turning.gain == pytest.approx(0.6, abs=0.06)
    assert made[-1].extra()['turn_gain'] == pytest.approx(0.6, abs=0.06)  # in the records
    assert max(abs(w) for w in sent) > 1.2  # asked for more than the preset's corners need
    assumed = run('assumed', 0.6)
    assert made[-1].turning is None and made[-1].extra()['turn_gain'] is None
    assert measured['completed'] and assumed['completed']
    assert measured['rms_offset_m'] < assumed['rms_offset_m']
    run('measured', 1.0, time_limit=10.0)
    assert made[-1].turning.gain == pytest.approx(1.0, abs=0.06)
    run('measured', 0.6, odometry=False, time_limit=0.5)
    assert made[-1].turning is None
