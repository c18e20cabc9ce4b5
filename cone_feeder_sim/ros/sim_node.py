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
The ROS 2 node ``sim_node``: a thin adapter that runs a FeederEngine on a timer.

Run it with ``ros2 run cone_feeder_sim sim_node --ros-args --params-file
config/sim_node.yaml`` (or ``sim_node`` / ``python -m cone_feeder_sim.ros.sim_node`` in a
virtual environment with the ``ros-jazzy-*`` wheels). All physics, the drive and the feed
live in :class:`~cone_feeder_sim.feeder.engine.FeederEngine`; this module turns ROS input into
engine input and engine output into messages. Messages are built from numpy arrays,
encoded by :mod:`cone_feeder_sim.formats.cdr` and published as serialized bytes; every published
and received message passes through :meth:`SimNode.add_message_hook` callbacks with its
exact bytes (for MCAP recording).

Time: the engine's step is ``dt = 1 / update_rate`` of simulated time, paced against the
steady clock at ``real_time_factor`` (0: as fast as possible) by
:class:`~cone_feeder_sim.ros.pacing.Pacer`. Ticks run on a worker thread (the integration
releases the GIL and uses every core), so the executor keeps serving commands, services and
parameters while a long tick runs; the executor publishes each tick's messages, in tick
order, when the worker hands them over. A tick that takes longer than its period (a cone
reversal excites every piece at once) is caught up by the following ticks as long as the
lag stays within ``catch_up`` seconds; when the machine cannot keep up for longer, the
excess is given up: simulated time runs slower than ``real_time_factor`` asks and
``/diagnostics`` says so (level WARN). Header stamps are simulation time; ``/clock`` (when
``publish_clock``) carries the same time, never 0 (the first tick ends at ``dt``). The
node's own clock and ``use_sim_time`` do not drive it.

Topics (relative names, so namespaces and remapping apply; ``frame_id`` ``feeder`` by
default, fixed, z up, origin at the centre of the cone base):

=================  ==================================  ======================================
topic              type                                QoS
=================  ==================================  ======================================
rotation_cmd (in)  std_msgs/Float64 (rad/s, > 0 ccw)   reliable, keep last 10, volatile
spawn (in)         geometry_msgs/PoseArray             reliable, keep last 10, volatile
particles          geometry_msgs/PoseArray             reliable, keep last 10, volatile
particle_states    sensor_msgs/PointCloud2             reliable, keep last 10, volatile
exit_events        sensor_msgs/PointCloud2             reliable, keep last 1000, volatile
channel_mass       std_msgs/Float64MultiArray          reliable, keep last 1, transient local
cone_state         sensor_msgs/JointState              reliable, keep last 10, volatile
markers            visualization_msgs/MarkerArray      reliable, keep last 1, transient local
/diagnostics       diagnostic_msgs/DiagnosticArray     reliable, keep last 10, volatile
/clock             rosgraph_msgs/Clock                 reliable, keep last 1, volatile
~/events           std_msgs/String (JSON)              reliable, keep last 1000, volatile
=================  ==================================  ======================================

State topics are reliable (a reliable writer matches both reliable and best-effort readers,
so RViz, Foxglove and ``ros2 topic echo`` connect with their defaults) with a short
keep-last history: a slow reader loses old states instead of slowing the simulator down.
Exit events are reliable with a deep history because a lost event is lost product.
``channel_mass`` and ``markers`` are transient local with depth 1 so that late joiners get
the current totals and the static scene: every marker message holds the static markers
(cone surface, channel sectors and labels) besides the dynamic ones (pieces, cone angle).

``particle_states`` points: x, y, z (m), vx, vy, vz (m/s) FLOAT32, id UINT32, mass (kg)
FLOAT32; 32 bytes per point, little endian, height 1. ``exit_events`` points: x, y, z (m),
vx, vy, vz (m/s), exit_time (s, simulation time), angle (rad, atan2(y, x) in (-pi, pi]),
mass (kg) FLOAT64, id UINT32, channel UINT32 (1-based); 80 bytes per point; one message per
tick in which pieces left. Particle ids are unique over a run (they keep counting after a
reset) and wrap at 2**32 on the wire.

Spawn: poses in frame ``feeder`` or with an empty ``frame_id`` (taken as ``feeder``); other
frames are refused with a warning, as are poses outside the cone, below its surface or
non-finite; valid poses of a message are accepted. Orientations are ignored. New pieces get
the default product and start at rest in the world frame (dropped).

Services: ``~/reset`` (std_srvs/Trigger), ``~/pause`` (std_srvs/SetBool: true pauses, false
resumes), ``~/step`` (std_srvs/Trigger: one tick while paused; refused otherwise). Inputs
(commands, spawns, resets, parameter changes of the drive and feed) are applied at the start
of the next tick, so while paused they wait for ``~/step`` or the resume.

Parameters are listed by :func:`parameter_specs` (descriptions and ranges are declared with
them). Model parameters are ``model.<key>`` with the keys of ``config/table2.yaml``; their
defaults come from ``parameter_file`` ('' = the package's table2.yaml), so a parameter file
sets the base and ``model.<key>`` overrides single values. Model, solver, update rate, seed,
frame and initial pieces are read-only; the drive (limits, timeout, pattern), the feed, the
real-time factor, the marker rate and the diagnostics period can be changed at run time;
invalid values are refused with the reason. Double parameters need a decimal point in
parameter files (``2.0``, not ``2``); an empty array (``[]``) means "none".

Recording (``record_path``, see ``doc/recording.md``): every published and received
message goes to one MCAP file (log time = simulation time) through a writer thread; the
inputs the engine applied are published on ``~/events`` with their tick index, so that
``replay_commands`` can re-simulate the run exactly. ``main()`` finishes the file on a
normal end, SIGINT and SIGTERM.
"""

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
import datetime
import json
import math
import os
from pathlib import Path
import signal
import sys
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
import numpy as np
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMessage
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from .diagnostics import (
    DiagnosticsWindow, recording_status, RunTotals, simulation_status, weigher_status)
from .guarded_node import GuardedNode
from .pacing import Pacer
from .parameters import (
    changes_the_run, declare, drive_from_values, DRIVE_PARAMETERS, engine_config_from_values,
    feed_from_values, init_or_exit, LIVE_PARAMETERS, model_from_values, parameter_specs, ParamSpec,
    warn_unknown_parameters)
from .qos import rclpy_qos
from .resim import load_resim_plan, recorded_parameter, ResimPlan
from .. import __version__
from ..errors import ConeFeederError, ParameterError
from ..feeder.engine import ChannelFeed, FeederEngine, MAX_PENDING_INPUTS, TickResult
from ..feeder.feed import check_feed_fits
from ..formats.cdr import CdrError, default_codec
from ..formats.mcap_writer import COMPRESSIONS
from ..formats.messages import (
    channel_mass_message, clock_message, cone_state_message, exits_message, header,
    hopper_weights_message, MarkerBuilder, MarkerSchedule, packs_message, particles_message,
    pose_array_positions, stamp, stamp_ns, states_message)
from ..formats.parameter_file import load_model_params
from ..formats.run_recorder import RecordingLimits, RunRecorder
from ..formats.runlog import (
    engine_config_json, engine_input_from_event, event_text, expand_record_path, failure_event,
    FORMAT_VERSION, input_event, INPUT_EVENTS, METADATA_NAME, parameter_text, to_jsonable)
from ..formats.topics import MessageRecord, QosProfile, TOPICS
from ..physics.integrator import set_threads
from ..physics.params import ModelParams
from ..physics.simulation import kernel_cache_note, position_problems

__all__ = ['SimNode', 'TopicInfo', 'main']

NODE_NAME = 'sim_node'
#: Received messages larger than this (bytes) are not recorded whole (a million-pose spawn
#: is 56 MB); the inputs the engine applied from them are.
MAX_RECORDED_INPUT_BYTES = 4 * 1024 * 1024
#: Period (s) of the tick timer when running as fast as possible (real_time_factor 0): the
#: worker's ticks follow each other directly; the timer only restarts them after a resume.
FAST_TIMER_PERIOD = 0.02

# --------------------------------------------------------------------------- hooks


@dataclass(frozen=True)
class TopicInfo:
    """A topic of the node: resolved name, type, direction and QoS (for recorders)."""

    topic: str
    type_name: str
    direction: str
    qos: QosProfile


MessageHook = Callable[[MessageRecord], None]


@dataclass(frozen=True)
class _Output:
    """A publisher with its resolved topic, type name and CDR encoder."""

    publisher: Any
    topic: str
    type_name: str
    encode: Callable[[Any], bytes]


class SimNode(GuardedNode):
    """The cone feeder simulator as a ROS 2 node; see the module documentation."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, build the engine and create every ROS handle."""
        super().__init__(NODE_NAME, **kwargs)

    def _setup(self) -> None:
        self._codec = default_codec()
        self._hooks: list[MessageHook] = []
        self._topics: dict[str, TopicInfo] = {}
        self._topic_names: dict[str, str] = {}
        self._recorder: RunRecorder | None = None
        self._recording_error: str | None = None
        self._refusal_logged: dict[tuple[str, str], float] = {}
        self._resim: ResimPlan | None = None
        self._resim_active = False
        specs = {s.name: s for s in parameter_specs()}
        replay = declare(self, specs['replay_commands']).value
        if replay:
            self._resim = load_resim_plan(replay)
            self._resim_active = True
        file_param = self._declare(specs['parameter_file']).value
        if self._resim is not None:
            # every model.<key> is recorded: the model does not depend on the file any more
            self._base_model = model_from_values(self._resim.parameters, ModelParams())
        else:
            # '' = the package's table2.yaml
            self._base_model = load_model_params(file_param or None)
        self._specs = {s.name: s for s in parameter_specs(self._base_model)}
        for spec in self._specs.values():
            if spec.name not in ('parameter_file', 'replay_commands'):
                self._declare(spec)
        values = self._values()
        try:
            set_threads(int(values['threads']))
        except ValueError as exc:
            raise ParameterError(str(exc)) from exc
        loading = time.monotonic()
        self._engine = FeederEngine(engine_config_from_values(values, self._base_model))
        self.get_logger().info(kernel_cache_note(time.monotonic() - loading))
        self._frame = str(values['frame_id'])
        self._pacer = Pacer(self._engine.dt, float(values['real_time_factor']),
                            float(values['catch_up']))
        self._anchored = False  # the pacer is anchored at the first timer callback
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='sim_tick')
        self._job: Future[list[tuple[TickResult, float]]] | None = None
        self._markers = MarkerSchedule(float(values['markers.rate']))
        #: marker rate changes (from tick index, rate): the worker may be ticks ahead of the
        #: published ones, so a change takes effect from the tick its event names
        self._marker_rates: list[tuple[int, float]] = []
        self._paused = False
        self._totals = RunTotals()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._window = DiagnosticsWindow(time.perf_counter(), self._engine.t)
        # the worker may be ticks ahead: the node's time is that of the last published tick
        # (stamps of events, received messages and diagnostics, so log times never go back)
        self._published_t = self._engine.t
        self._published_index = self._engine.tick_index

        self._pub_particles = self._publisher(PoseArray, 'particles')
        self._pub_states = self._publisher(PointCloud2, 'particle_states')
        self._pub_exits = self._publisher(PointCloud2, 'exit_events')
        self._pub_channel = self._publisher(Float64MultiArray, 'channel_mass')
        self._pub_cone = self._publisher(JointState, 'cone_state')
        self._pub_hoppers = self._publisher(Float64MultiArray, 'hopper_weights')
        self._pub_packs = self._publisher(PointCloud2, 'pack_events')
        self._pub_markers = self._publisher(MarkerArray, 'markers')
        self._pub_diag = self._publisher(DiagnosticArray, '/diagnostics')
        self._pub_clock = (self._publisher(ClockMessage, '/clock')
                           if values['publish_clock'] else None)
        self._pub_events = self._publisher(String, '~/events')
        self._sub_cmd = self.create_subscription(
            Float64, 'rotation_cmd', self._on_rotation_cmd, rclpy_qos(TOPICS['rotation_cmd'].qos),
            raw=True)
        self._sub_spawn = self.create_subscription(
            PoseArray, 'spawn', self._on_spawn, rclpy_qos(TOPICS['spawn'].qos), raw=True)
        self._sub_feed = self.create_subscription(
            Float64MultiArray, 'channel_feed', self._on_channel_feed,
            rclpy_qos(TOPICS['channel_feed'].qos), raw=True)
        for sub, name in ((self._sub_cmd, 'rotation_cmd'), (self._sub_spawn, 'spawn'),
                          (self._sub_feed, 'channel_feed')):
            spec = TOPICS[name]
            self._topics[sub.topic_name] = TopicInfo(sub.topic_name, spec.type_name, 'in',
                                                     spec.qos)
            self._topic_names[name] = sub.topic_name
        self._srv_reset = self.create_service(Trigger, '~/reset', self._on_reset)
        self._srv_pause = self.create_service(SetBool, '~/pause', self._on_pause)
        self._srv_step = self.create_service(Trigger, '~/step', self._on_step)
        self._job_done = self.create_guard_condition(self._on_job_done)

        self._marker_builder = MarkerBuilder(self._engine.model, self._frame, self._codec)
        self._start_recording(values)
        if self._resim is not None:
            self._check_resim_config()
        start_paused = bool(values['start_paused'])
        self._tick_timer = self.create_timer(self._timer_period(), self._on_timer,
                                             clock=self._steady, autostart=not start_paused)
        self._paused = start_paused
        self._diag_timer = self.create_timer(float(values['diagnostics.period']),
                                             self._publish_diagnostics, clock=self._steady)
        self._recording_timer = (
            self.create_timer(0.25, self._check_recording, clock=self._steady)
            if self._recorder is not None else None)
        warn_unknown_parameters(self)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(
            f'simulating {self._engine.piece_count} pieces, dt = {self._engine.dt:g} s, '
            f'real_time_factor = {self._pacer.rtf:g}, feed {self._engine.feed.rate:g} pieces/s')
        if self._resim is not None and self._resim.ticks == 0:
            self._finish_resim()

    def _declare(self, spec: 'ParamSpec') -> Parameter:
        """Declare a parameter; while re-simulating, take recorded values over given ones."""
        plan = self._resim
        found, value = (False, None) if plan is None else recorded_parameter(plan, spec.name)
        if not found or spec.name in LIVE_PARAMETERS:
            return declare(self, spec)
        if value is None or value == []:
            value = spec.type_()  # an empty array: declared without a value, as '[]' does
        return declare(self, spec, value, ignore_override=True)

    # ------------------------------------------------------------------ recording

    def _start_recording(self, values: dict[str, Any]) -> None:
        """Open the MCAP file of this run (refused with a clear error if impossible)."""
        template = str(values['record_path'])
        if not template:
            return
        path = expand_record_path(template).absolute()
        topics = [(info.topic, info.type_name, info.qos) for info in self._topics.values()]
        compression = str(values['record_compression'])
        if compression not in COMPRESSIONS:
            raise ParameterError(f'record_compression must be one of {", ".join(COMPRESSIONS)}, '
                                 f'got {compression!r}')
        limits = RecordingLimits(
            max_file_size=int(values['record_max_file_size']),
            max_file_duration_ns=round(float(values['record_max_file_duration']) * 1e9),
            min_free_bytes=int(values['record_min_free_space']))
        self._recorder = RunRecorder(path, topics, {METADATA_NAME: self._metadata(values)},
                                     limits=limits, compression=compression)
        self.add_message_hook(self._recorder.hook)
        self.get_logger().info(f'recording to {path}')

    def _metadata(self, values: dict[str, Any]) -> dict[str, str]:
        """Return the cone_feeder_sim metadata: parameters and what re-simulation needs."""
        data = {name: parameter_text(value) for name, value in values.items()}
        data.update({
            'format': FORMAT_VERSION,
            'version': __version__,
            'source': 'sim_node',
            'node': self.get_fully_qualified_name(),
            'namespace': self.get_namespace(),
            'dt': repr(self._engine.dt),
            'seed': str(self._engine.config.seed),
            'model_options': json.dumps({
                'normal_force': self._engine.model.normal_force,
                'friction_direction': self._engine.model.friction_direction}),
            'engine_config': engine_config_json(self._engine.config),
            'parameters_json': json.dumps(to_jsonable(values)),
            'topics': json.dumps(self._topic_names),
            'input_topics': json.dumps(sorted(
                info.topic for info in self._topics.values() if info.direction == 'in')),
            'created': datetime.datetime.now().astimezone().isoformat(timespec='seconds'),
            'ros_distro': os.environ.get('ROS_DISTRO', ''),
        })
        return data

    def _check_recording(self) -> None:
        """End a recording that stopped (its writer thread flushes and checks by itself)."""
        recorder = self._recorder
        if recorder is not None and not recorder.closed and recorder.error is not None:
            self.close_recording()  # the simulation goes on without it

    def close_recording(self) -> None:
        """Finish the MCAP file (summary, statistics); idempotent. destroy_node() calls it."""
        recorder = getattr(self, '_recorder', None)
        if recorder is None or recorder.closed:
            return
        self._finish_job()  # its ticks belong to the recording
        if recorder.hook in self._hooks:
            self.remove_message_hook(recorder.hook)
        recorder.close(end_metadata={
            'ticks': str(self._engine.tick_index), 'end_time': repr(self._engine.t),
            'exits': str(self._totals.exits), 'failures': str(self._totals.failures),
            'refused_inputs': str(self._totals.refused)})
        files = ', '.join(str(p) for p in recorder.paths)
        if recorder.error is not None:
            self._recording_error = str(recorder.error)
            self._final_log('error', f'recording stopped: {recorder.error}; '
                            f'{recorder.message_count} messages are in {files}')
        else:
            self._final_log('info', f'recorded {recorder.message_count} messages to {files}')

    def _final_log(self, level: str, text: str) -> None:
        """Log at shutdown: after a signal the context is gone and /rosout with it."""
        if self.context.ok():
            getattr(self.get_logger(), level)(text)
        else:
            sys.stderr.write(f'[{level.upper()}] [{self.get_name()}]: {text}\n')

    @property
    def recording_path(self) -> Path | None:
        """Return the path of this run's MCAP file (None when not recording)."""
        return None if self._recorder is None else self._recorder.path

    def destroy_node(self) -> None:
        """Finish the running tick and the recording, then destroy the node's handles."""
        try:
            worker = getattr(self, '_worker', None)
            if worker is not None:
                self._finish_job()
                worker.shutdown(wait=True)
            self.close_recording()
        finally:
            super().destroy_node()

    # ------------------------------------------------------------------ re-simulation

    def _check_resim_config(self) -> None:
        plan = self._resim
        assert plan is not None
        if plan.engine_config and plan.engine_config != engine_config_json(self._engine.config):
            self.get_logger().warning(
                f'the engine configuration built from the parameters of {plan.path} differs '
                'from the recorded one (recorded by another version?): the re-simulation may '
                'differ')
        if plan.problem:
            self.get_logger().warning(f'{plan.path} is incomplete ({plan.problem}): '
                                      f're-simulating its {plan.ticks} readable ticks')
        count = sum(len(v) for v in plan.events.values())
        self.get_logger().info(
            f're-simulating {plan.path}: {plan.ticks} ticks, {count} recorded events; '
            'parameters, initial pieces and inputs come from the recording')

    @property
    def replaying(self) -> bool:
        """Tell whether the node is re-simulating a recording (until its last tick)."""
        return self._resim_active

    def _submit_recorded(self) -> None:
        """Submit the recorded inputs of the next tick (re-simulation; worker thread)."""
        plan = self._resim
        assert plan is not None
        for event in plan.events.get(self._engine.tick_index, ()):
            if event.get('event') in INPUT_EVENTS:
                self._engine.submit(engine_input_from_event(event))

    def _recorded_marker_rates(self, index: int) -> None:
        """Queue the recorded marker rate changes of tick ``index`` (re-simulation)."""
        plan = self._resim
        assert plan is not None
        for event in plan.events.get(index, ()):
            if event.get('event') == 'parameters' and 'markers.rate' in event.get('values', {}):
                self._marker_rates.append((index, float(event['values']['markers.rate'])))

    def _finish_resim(self) -> None:
        self._resim_active = False
        plan = self._resim
        assert plan is not None
        self.set_paused(True)
        self.get_logger().info(
            f're-simulation of {plan.path} done after {plan.ticks} ticks (t = '
            f'{self._engine.t:.6f} s); paused: resume with ~/pause false to go on live')

    def _refuse_live(self, what: str) -> bool:
        """Refuse a live input while re-simulating; return whether it was refused."""
        if not self._resim_active:
            return False
        self._refuse(what, 1, 're-simulating a recording')
        return True

    def _refuse(self, what: str, count: int, reason: str, text: str | None = None) -> None:
        """
        Count, log and record refused input: ``count`` items of ``what`` with the reason.

        The refusal is an event on ~/events (so it is in the recording); the log line
        (``text``, default ``<what> refused: <reason>``) is throttled.
        """
        self._totals.refused += count
        # at most one line a second per kind of refusal (rclpy throttles per call site)
        key = (what, reason.split(':')[0][:40])
        now = time.monotonic()
        if now - self._refusal_logged.get(key, -math.inf) >= 1.0:
            self._refusal_logged[key] = now
            self.get_logger().warning(text or f'{what} refused: {reason}')
        self._node_event('refused', input=what, count=count, reason=reason)

    # ------------------------------------------------------------------ plumbing

    def _publisher(self, msg_type: Any, name: str) -> '_Output':
        spec = TOPICS[name]
        pub = self.create_publisher(msg_type, name, rclpy_qos(spec.qos))
        self._topics[pub.topic_name] = TopicInfo(pub.topic_name, spec.type_name, 'out',
                                                 spec.qos)
        self._topic_names[name] = pub.topic_name
        return _Output(pub, pub.topic_name, spec.type_name, self._codec.encoder(spec.type_name))

    def _values(self) -> dict[str, Any]:
        # get_parameter_or: an empty list in a parameter file leaves an array NOT_SET
        return {name: self.get_parameter_or(name).value for name in self._specs}

    def _timer_period(self) -> float:
        # as fast as possible, the worker chains its hand-overs; the timer only restarts them
        return self._pacer.period or FAST_TIMER_PERIOD

    def _publish(self, out: '_Output', message: dict[str, Any], stamp_ns: int) -> None:
        data = out.encode(message)
        if self.context.ok():  # after a signal, the last ticks are still recorded
            out.publisher.publish(data)
        if self._hooks:
            self._emit(MessageRecord('out', out.topic, out.type_name, data, stamp_ns,
                                     time.time_ns()))

    def _emit(self, record: MessageRecord) -> None:
        for hook in list(self._hooks):
            try:
                hook(record)
            except Exception as exc:  # noqa: B902 - a broken hook must not stop the node
                self.get_logger().error(f'message hook {hook!r} failed: {exc}',
                                        throttle_duration_sec=5.0)

    def add_message_hook(self, hook: MessageHook) -> None:
        """Call hook with every published and received message (exact serialized bytes)."""
        self._hooks.append(hook)

    def remove_message_hook(self, hook: MessageHook) -> None:
        """Stop calling hook."""
        self._hooks.remove(hook)

    def topics(self) -> list[TopicInfo]:
        """Return the node's topics with types, directions and QoS."""
        return list(self._topics.values())

    @property
    def engine(self) -> FeederEngine:
        """Return the engine, for tests and tools; submit inputs from the node's thread."""
        return self._engine

    @property
    def paused(self) -> bool:
        """Tell whether the tick timer is paused."""
        return self._paused

    @property
    def timing(self) -> tuple[int, float, float]:
        """Return ticks run, wall seconds in engine ticks and in publishing, since the start."""
        return self._totals.ticks, self._totals.step_s, self._totals.publish_s

    @property
    def totals(self) -> RunTotals:
        """Return the counts since the start: ticks, exits, failures, refused inputs."""
        return self._totals

    @property
    def last_tick(self) -> TickResult | None:
        """Return the result of the last tick, if any."""
        return self._totals.last_tick

    def _now_ns(self) -> int:
        """Return the node's time (ns): that of the last published tick."""
        return stamp_ns(self._published_t)

    def _publish_event(self, event: dict[str, Any], time_ns: int | None = None) -> None:
        """Publish an event on ~/events (and so record it)."""
        self._publish(self._pub_events, {'data': event_text(event)},
                      self._now_ns() if time_ns is None else time_ns)

    def _node_event(self, kind: str, **fields: Any) -> None:
        self._publish_event({'event': kind, 'tick': self._published_index,
                             't': self._published_t, **fields})

    # ------------------------------------------------------------------ inputs

    def _received(self, topic: str, type_name: str, data: bytes) -> None:
        """
        Pass a received message to the hooks (the recording).

        A message larger than MAX_RECORDED_INPUT_BYTES is not passed on whole: an
        ``input_not_recorded`` event says so (what it changed is recorded as applied inputs).
        """
        if not self._hooks:
            return
        if len(data) > MAX_RECORDED_INPUT_BYTES:
            self._node_event('input_not_recorded', topic=topic, bytes=len(data),
                             reason=f'larger than {MAX_RECORDED_INPUT_BYTES} bytes')
            return
        self._emit(MessageRecord('in', topic, type_name, bytes(data), self._now_ns(),
                                 time.time_ns()))

    def _on_rotation_cmd(self, data: bytes) -> None:
        self._received(self._sub_cmd.topic_name, 'std_msgs/msg/Float64', data)
        if self._refuse_live('rotation_cmd'):
            return
        try:
            value = self._codec.decode('std_msgs/msg/Float64', data, strict=False)['data']
            self._engine.command(value)
        except (CdrError, ConeFeederError) as exc:
            self._refuse('rotation_cmd', 1, str(exc))
            return
        limit = self._engine.drive.max_angular_velocity
        if abs(value) > limit:
            self.get_logger().warning(
                f'rotation_cmd {value:g} rad/s clamped to the limit {limit:g} rad/s',
                throttle_duration_sec=5.0)

    def _on_channel_feed(self, data: bytes) -> None:
        self._received(self._sub_feed.topic_name, 'std_msgs/msg/Float64MultiArray', data)
        if self._refuse_live('channel_feed'):
            return
        try:
            values = self._codec.decode('std_msgs/msg/Float64MultiArray', data,
                                        strict=False)['data']
            self._engine.submit(ChannelFeed(tuple(values)))
        except (CdrError, ConeFeederError) as exc:
            self._refuse('channel_feed', 1, str(exc))

    def _on_spawn(self, data: bytes) -> None:
        self._received(self._sub_spawn.topic_name, 'geometry_msgs/msg/PoseArray', data)
        if self._refuse_live('spawn'):
            return
        try:
            frame, positions = pose_array_positions(data)
        except CdrError as exc:
            self._refuse('spawn', 1, f'cannot decode the message: {exc}')
            return
        total = positions.shape[0]
        if frame not in ('', self._frame):
            self._refuse('spawn', total, f'poses are in frame {frame!r}, expected '
                         f'{self._frame!r} (or an empty frame_id)')
            return
        valid, problems = position_problems(self._engine.model, positions,
                                            self._engine.config.spawn_max_height)
        if problems:
            reason = ('; '.join(problems[:5]) + (' ...' if len(problems) > 5 else '')
                      ).replace('position[', 'pose [')
            self._refuse('spawn', len(problems), reason,
                         f'spawn: refused {len(problems)} of {total} poses: {reason}')
        positions = positions[valid]
        limit = self._engine.feed.max_pieces
        if positions.shape[0] > limit:
            excess = positions.shape[0] - limit
            self._refuse('spawn', excess, f'{excess} of {total} poses beyond feed.max_pieces = '
                         f'{limit} pieces on the cone')
            positions = positions[:limit]
        if positions.shape[0]:
            try:
                self._engine.spawn(positions, velocities=np.zeros_like(positions))
            except ConeFeederError as exc:
                self._refuse('spawn', positions.shape[0], str(exc))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        if self._refuse_live('reset'):
            response.success = False
            response.message = 're-simulating a recording: live inputs are refused until its end'
            return response
        try:
            self._engine.reset()
        except ConeFeederError as exc:  # the input queue is full
            self._refuse('reset', 1, str(exc))
            response.success = False
            response.message = str(exc)
            return response
        response.success = True
        response.message = 'reset queued: applied at the start of the next tick'
        if self._paused:
            response.message += ' (paused: call ~/step or resume with ~/pause false)'
        self.get_logger().info('reset requested')
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response
                  ) -> SetBool.Response:
        response.success = True
        response.message = self.set_paused(bool(request.data))
        return response

    def _on_step(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        if not self._paused:
            response.success = False
            response.message = 'not paused: call ~/pause with data: true first'
            self._node_event('refused', input='~/step', count=1, reason=response.message)
            return response
        result = self.step()
        response.success = True
        response.message = f'stepped to t = {result.t:.6f} s ({result.count} pieces)'
        return response

    def set_paused(self, paused: bool) -> str:
        """Pause or resume the tick timer; return what happened (as ~/pause answers)."""
        if paused:
            if self._paused:
                return 'already paused'
            self._tick_timer.cancel()
            self._paused = True
            self._finish_job()
            self._node_event('pause')
            return f'paused at t = {self._engine.t:.6f} s'
        if not self._paused:
            return 'already running'
        self._paused = False
        self._anchored = False
        self._window = DiagnosticsWindow(time.perf_counter(), self._engine.t)
        self._tick_timer.reset()
        self._node_event('resume')
        return f'resumed at t = {self._engine.t:.6f} s'

    def step(self) -> TickResult:
        """Run one tick now and publish it (what ~/step does while paused)."""
        self._finish_job()
        self._node_event('step')
        result = self._tick_once()
        self._publish_results([result])
        if self._resim_active and self._engine.tick_index >= self._resim.ticks:
            self._finish_resim()
        return result[0]

    # ------------------------------------------------------------------ parameters

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        result = self._parameter_problem(parameters)
        if not result.successful:
            self._node_event('refused', input='parameters', count=len(parameters),
                             reason=result.reason,
                             values={p.name: p.value for p in parameters})
        return result

    def _parameter_problem(self, parameters: list[Parameter]) -> SetParametersResult:
        if self._resim_active:
            fixed = [p.name for p in parameters if changes_the_run(p.name)]
            if fixed:
                return SetParametersResult(
                    successful=False, reason=f're-simulating a recording: {", ".join(fixed)} '
                    'come from the recording until its end')
        values = self._values()
        for param in parameters:
            if param.name in self._specs:
                values[param.name] = param.value
        try:
            drive_from_values(values)
            check_feed_fits(self._engine.model, feed_from_values(values))
        except ConeFeederError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if len(self._engine.pending) >= MAX_PENDING_INPUTS and any(
                changes_the_run(p.name) for p in parameters):
            return SetParametersResult(
                successful=False, reason=f'{MAX_PENDING_INPUTS} inputs are already waiting for '
                'the next tick')
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        names = {p.name for p in parameters}
        values = self._values()
        drive = drive_from_values(values) if names & set(DRIVE_PARAMETERS) else None
        feed = feed_from_values(values) if any(n.startswith('feed.') for n in names) else None
        if drive is not None or feed is not None:
            self._engine.reconfigure(drive=drive, feed=feed)
        if 'real_time_factor' in names:
            self._pacer.rtf = float(values['real_time_factor'])
            self._tick_timer.timer_period_ns = int(round(self._timer_period() * 1e9))
            self._anchored = False
            self._window = DiagnosticsWindow(time.perf_counter(), self._engine.t)
        if 'catch_up' in names:
            self._pacer.catch_up = float(values['catch_up'])
        index = self._engine.tick_index  # the next tick the worker starts
        if 'markers.rate' in names:
            self._marker_rates.append((index, float(values['markers.rate'])))
        if 'diagnostics.period' in names:
            self._diag_timer.timer_period_ns = int(round(values['diagnostics.period'] * 1e9))
        self._node_event('parameters', tick=index, values={p.name: p.value for p in parameters})

    # ------------------------------------------------------------------ the tick

    def _on_timer(self) -> None:
        if self._job is None and not self._paused:
            self._start_job()

    def _start_job(self) -> None:
        """Hand the ticks that are due to the worker thread (executor thread)."""
        begin = time.perf_counter()
        engine = self._engine
        if not self._anchored:  # (re)started: the first tick is due now
            self._pacer.restart(begin - self._pacer.period, engine.t)
            self._anchored = True
        due = self._pacer.due(begin, engine.t)
        window = self._window
        window.given_up += due.given_up
        window.lag_max = max(window.lag_max, due.lag)
        count = due.ticks
        if self._resim_active:
            count = min(count, self._resim.ticks - engine.tick_index)
        if count > 0:  # the ticks due, within one period of work
            self._job = self._worker.submit(self._work, count, begin + self._pacer.period)

    def _work(self, count: int, deadline: float) -> list[tuple[TickResult, float]]:
        """Run up to ``count`` ticks, stopping after ``deadline`` (worker thread)."""
        results = []
        try:
            for _ in range(count):
                results.append(self._tick_once())
                if time.perf_counter() >= deadline:
                    break
        finally:
            self._job_done.trigger()  # the executor publishes them
        return results

    def _tick_once(self) -> tuple[TickResult, float]:
        """Run one engine tick; return it with its wall-clock duration (s)."""
        start = time.perf_counter()
        if self._resim_active:
            self._submit_recorded()
        result = self._engine.tick()
        return result, time.perf_counter() - start

    def _on_job_done(self) -> None:
        """Start the next ticks if due, then publish the finished ones (executor)."""
        job = self._job
        if job is None or not job.done():
            return  # already handed over by _finish_job
        begin = time.perf_counter()
        self._job = None
        results = job.result()
        if not self._paused:
            self._start_job()  # the worker ticks on while these are published
        self._publish_results(results)
        if (self._resim_active and self._job is None
                and self._engine.tick_index >= self._resim.ticks):
            self._finish_resim()
        self._window.callback_max = max(self._window.callback_max, time.perf_counter() - begin)

    def _finish_job(self) -> None:
        """Wait for the worker's running ticks and publish them (pause, step, shutdown)."""
        job, self._job = self._job, None
        if job is not None:
            self._publish_results(job.result())

    def _publish_results(self, results: list[tuple[TickResult, float]]) -> None:
        """Publish and count finished ticks, in tick order (executor thread)."""
        period = self._pacer.period
        for result, seconds in results:
            stepped = time.perf_counter()
            if self._resim is not None:
                self._recorded_marker_rates(result.index)
            while self._marker_rates and self._marker_rates[0][0] <= result.index:
                self._markers.rate = self._marker_rates.pop(0)[1]
            self._publish_tick(result)
            self._published_t, self._published_index = result.t, result.index + 1
            publish_s = time.perf_counter() - stepped
            self._window.count(result, seconds, publish_s, period)
            self._totals.count(result, seconds, publish_s)
            for failure in result.failures:
                self.get_logger().warning(
                    f'piece {failure.particle_id} removed at t = {failure.t:.6f} s: '
                    f'{failure.reason} (at {failure.position})')
                self._publish_event(failure_event(result.index, failure), stamp_ns(failure.t))
            for refusal in result.refusals:
                self._refuse(refusal.kind, refusal.count, refusal.reason)
            if result.reset:
                self._markers.restart()

    def _publish_tick(self, res: TickResult) -> None:
        if res.applied:
            t0_ns = stamp_ns(res.t0)
            for item in res.applied:
                self._publish_event(input_event(res.index, res.t0, item), t0_ns)
        head = header(res.t, self._frame)
        t_ns = stamp_ns(res.t)
        if self._pub_clock is not None:
            self._publish(self._pub_clock, clock_message(res.t), t_ns)
        self._publish(self._pub_particles, particles_message(head, res.positions), t_ns)
        self._publish(self._pub_states, states_message(
            head, res.ids, res.positions, res.velocities, res.masses), t_ns)
        if len(res.exits):
            self._publish(self._pub_exits, exits_message(head, res.exits), t_ns)
        self._publish(self._pub_channel, channel_mass_message(res.channel_mass), t_ns)
        self._publish(self._pub_cone, cone_state_message(head, res.angle, res.omega), t_ns)
        if res.hoppers is not None:
            self._publish(self._pub_hoppers, hopper_weights_message(res.hoppers), t_ns)
        if res.packs:
            self._publish(self._pub_packs, packs_message(head, res.packs), t_ns)
        if self._markers.due(res.t, res.reset):
            self._publish(self._pub_markers, self._marker_builder.message(
                head, res.angle, res.positions), t_ns)

    # ------------------------------------------------------------------ diagnostics

    def _publish_diagnostics(self) -> None:
        now = time.perf_counter()
        name = self.get_fully_qualified_name()
        res = self._totals.last_tick
        statuses = [
            simulation_status(name, self._window, now, self._engine, self._pacer,
                              self._paused, res, self._totals.exits, self._totals.failures,
                              self._totals.refused),
            recording_status(name, self._recorder, self._recording_error)]
        if res is not None and res.weigher_stats is not None:
            statuses.append(weigher_status(name, res.weigher_stats))
        self._publish(self._pub_diag, {
            'header': {'stamp': stamp(self._published_t), 'frame_id': ''},
            'status': statuses}, self._now_ns())
        if not self._paused:
            self._window = DiagnosticsWindow(now, self._engine.t)


def main(args: list[str] | None = None) -> int:
    """
    Run the node until shut down; return the process exit status.

    SIGINT and SIGTERM (rclpy's handlers shut the context down) end the spin; the recording
    is finished in every path by destroy_node(), with both signals blocked meanwhile so that
    a second Ctrl-C cannot cut the file short.
    """
    if not init_or_exit(args, NODE_NAME):
        return 1
    node = None
    status = 0
    try:
        node = SimNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConeFeederError, ParameterException) as exc:
        rclpy.logging.get_logger(NODE_NAME).fatal(f'cannot start: {exc}')
        status = 1
    except Exception:  # noqa: B902 - only to tell a shutdown race from a real error
        if rclpy.ok():
            raise
        # SIGINT/SIGTERM shut the context down while the executor built its wait set
    finally:
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        try:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        finally:
            # a second Ctrl-C that arrived meanwhile is dropped, not raised on unblocking
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    return status


if __name__ == '__main__':
    sys.exit(main())
