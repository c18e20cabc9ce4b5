# Copyright 2026 The cone_feeder_sim Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Tests of sim_node's bounds on input and of failed pieces on the record.

Refused input and failed pieces are events on ``~/events`` (and so in the recording); the
mass on the cone, exited and failed adds up to the mass put on it.
"""

from collections.abc import Iterator
import json
import math
from typing import Any

from cone_feeder_sim.feeder.engine import MAX_PENDING_INPUTS
from cone_feeder_sim.formats.cdr import decode
from cone_feeder_sim.formats.topics import MessageRecord
from cone_feeder_sim.ros.sim_node import SimNode
from geometry_msgs.msg import PoseArray
import numpy as np
import pytest
from rclpy.parameter import Parameter
import sim_process
from std_msgs.msg import Float64
from std_srvs.srv import SetBool, Trigger


class Ros(sim_process.InProcess):
    """A private context, executor and helper node for one test."""

    def __init__(self) -> None:
        super().__init__('test_inputs', timeout=20.0, spin_step=0.02)

    def sim(self, **params: Any) -> SimNode:
        params.setdefault('record_path', '')
        overrides = [Parameter(k) if v == [] else Parameter(k, value=v)
                     for k, v in params.items()]
        return self.add(SimNode(context=self.context, parameter_overrides=overrides))


@pytest.fixture
def ros() -> Iterator[Ros]:
    with Ros() as harness:
        yield harness


def events(records: list[MessageRecord], kind: str) -> list[dict[str, Any]]:
    return [e for e in (json.loads(decode(r.type_name, r.data)['data'])
                        for r in records if r.topic.endswith('/events'))
            if e['event'] == kind]


def watch(sim: SimNode) -> list[MessageRecord]:
    records: list[MessageRecord] = []
    sim.add_message_hook(records.append)
    return records


def step(ros: Ros, sim: SimNode) -> None:
    response = ros.call(Trigger, '/sim_node/step', Trigger.Request(), timeout=20.0,
                        ready_timeout=10.0)
    assert response.success, response.message


def pause(ros: Ros) -> None:
    response = ros.call(SetBool, '/sim_node/pause', SetBool.Request(data=True), timeout=20.0,
                        ready_timeout=10.0)
    assert response.success


def grid(count: int, z: float = 0.06) -> PoseArray:
    """Return ``count`` poses on a ring inside the cone (or one flat array of them)."""
    angles = np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
    return sim_process.pose_array(*[(0.08 * math.cos(a), 0.08 * math.sin(a), z)
                                    for a in angles])


def test_a_spawn_beyond_max_pieces_is_refused_for_the_excess(ros: Ros) -> None:
    sim = ros.sim(**{'feed.rate': 0.0, 'feed.max_pieces': 8, 'initial_pieces.positions': [],
                     'initial_pieces.d': []})
    records = watch(sim)
    pause(ros)
    pub = ros.client.create_publisher(PoseArray, 'spawn', 10)
    pub.publish(grid(5))
    assert ros.spin_until(lambda: len(sim.engine.pending) == 1, 20.0)
    pub.publish(grid(12, z=0.12))  # more than feed.max_pieces at once: 4 refused; above
    assert ros.spin_until(lambda: sim.totals.refused >= 4, 20.0)
    step(ros, sim)
    # the second request (8 after the node's cut) meets 5 pieces: 5 refused when applied
    assert sim.last_tick.count == 8
    refused = events(records, 'refused')
    assert [e['count'] for e in refused] == [4, 5]
    assert all('feed.max_pieces' in e['reason'] for e in refused)
    assert sim.totals.refused == 9


def test_spawns_out_of_bounds_are_refused_and_recorded(ros: Ros) -> None:
    sim = ros.sim(**{'feed.rate': 0.0, 'spawn.max_height': 0.5})
    records = watch(sim)
    pause(ros)
    pub = ros.client.create_publisher(PoseArray, 'spawn', 10)
    pub.publish(sim_process.pose_array((0.05, 0.0, 1e300), (0.05, 0.0, math.inf),
                                       (0.05, 0.0, 0.3)))
    assert ros.spin_until(lambda: sim.totals.refused >= 2, 20.0)
    reasons = ' '.join(e['reason'] for e in events(records, 'refused'))
    assert 'above the highest start 0.5 m' in reasons and 'not finite' in reasons


def test_a_million_poses_are_bounded_and_the_node_goes_on(ros: Ros) -> None:
    # contact off: a thousand pieces spawned on one spot are half a million touching pairs,
    # a tick of minutes under the soft-contact coupling (not yet refused as overlapping)
    sim = ros.sim(**{'feed.rate': 0.0, 'feed.max_pieces': 1000, 'interactions.enabled': False})
    records = watch(sim)
    pause(ros)
    msg = PoseArray()
    msg.header.frame_id = 'feeder'
    msg.poses = grid(1).poses * 1_000_000
    ros.client.create_publisher(PoseArray, 'spawn', 10).publish(msg)
    assert ros.spin_until(lambda: sim.totals.refused >= 999_000, 60.0)
    step(ros, sim)
    assert sim.last_tick.count == 5 + 995  # the Table I pieces, then the room left
    refused = events(records, 'refused')
    assert sum(e['count'] for e in refused) == 1_000_000 - 995
    # 56 MB are not recorded whole; the applied spawn is (an input event)
    assert not [r for r in records if r.direction == 'in']
    assert events(records, 'input_not_recorded')[0]['bytes'] > 50_000_000
    assert len(events(records, 'spawn')[0]['positions']) == 1000  # cut to feed.max_pieces


def test_failed_pieces_are_events_and_the_mass_balances(ros: Ros) -> None:
    sim = ros.sim(**{'feed.rate': 50.0, 'solver.max_steps': 1, 'real_time_factor': 0.0})
    records = watch(sim)
    assert ros.spin_until(lambda: sim.engine.tick_index >= 20, 60.0)
    pause(ros)
    failures = events(records, 'failure')
    assert failures
    first = failures[0]
    assert {'id', 't', 'tick', 'position', 'velocity', 'mass', 'reason'} <= set(first)
    assert 'max_steps' in first['reason'] and first['mass'] > 0.0
    res = sim.last_tick
    assert res.failed_mass == pytest.approx(sum(f['mass'] for f in failures), rel=1e-12)
    assert res.mass_in == pytest.approx(
        float(res.masses.sum()) + float(res.channel_mass.sum()) + res.failed_mass, rel=1e-12)


def test_a_full_input_queue_refuses_commands_resets_and_parameters(ros: Ros) -> None:
    sim = ros.sim(**{'feed.rate': 0.0})
    records = watch(sim)
    pause(ros)
    for k in range(MAX_PENDING_INPUTS):
        sim.engine.command(float(k % 3))
    response = ros.call(Trigger, '/sim_node/reset', Trigger.Request(), timeout=20.0,
                        ready_timeout=10.0)
    assert not response.success and 'already waiting' in response.message
    result = sim.set_parameters([Parameter('feed.rate', value=1.0)])[0]
    assert not result.successful and 'already waiting' in result.reason
    ros.client.create_publisher(Float64, 'rotation_cmd', 10).publish(Float64(data=1.0))
    assert ros.spin_until(lambda: sim.totals.refused >= 2, 20.0)
    kinds = {e['input'] for e in events(records, 'refused')}
    assert {'reset', 'parameters', 'rotation_cmd'} <= kinds
    step(ros, sim)  # the queue empties with the tick; the node goes on
    assert sim.engine.pending == ()
    sim.set_paused(False)
    response = ros.call(Trigger, '/sim_node/step', Trigger.Request(), timeout=20.0,
                        ready_timeout=10.0)
    assert not response.success
    assert '~/step' in {e['input'] for e in events(records, 'refused')}
