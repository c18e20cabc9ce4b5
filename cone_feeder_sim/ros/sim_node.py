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
config/sim_node.yaml``. doc/sim_node.md is the reference: topics, QoS and point layouts,
input handling, services, parameters, time and recording.

All physics, the drive, the feed and every rule on inputs live in
:class:`~cone_feeder_sim.feeder.engine.FeederEngine`. The node composes helpers that take it
or the engine and own their handles, as rclpy's own ``Node`` does (doc/sim_node.md lists
them): :class:`~.outputs.Outputs` (topics, hooks), :class:`~.inputs.Inputs` (received bytes to
engine input), :class:`~.ticker.Ticker` (ticks on a worker thread, paced),
:class:`~cone_feeder_sim.formats.messages.TickMessages` (a tick's messages, as the headless
runner writes them), :class:`~.recording.NodeRecording` and :class:`~.resim.Resimulation`.

Inputs (commands, spawns, resets, parameter changes of the drive and feed) are applied at
the start of the next tick; every input the engine applied is published on ``~/events``
with its tick index, so that a recording can be re-simulated exactly.
"""

from collections.abc import Callable
from functools import partial
from pathlib import Path
import sys
import time
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.parameter import Parameter
from std_srvs.srv import SetBool, Trigger

from .diagnostics import diagnostics_message, RunTotals
from .guarded_node import GuardedNode, run_node
from .inputs import Inputs, RefusalThrottle
from .outputs import MAX_RECORDED_INPUT_BYTES, MessageHook, Outputs, TopicInfo
from .pacing import Pacer
from .parameters import (
    declare, declare_recorded, drive_from_values, DRIVE_PARAMETERS, engine_config_from_values,
    feed_from_values, model_from_values, parameter_problem, parameter_specs, ParamSpec,
    warn_unknown_parameters)
from .recording import node_metadata, NodeRecording
from .resim import load_resim_plan, recorded_parameter, Resimulation
from .ticker import Ticker, Ticks
from ..errors import ConeFeederError, ParameterError
from ..feeder.engine import FeederEngine, TickResult
from ..formats.cdr import default_codec
from ..formats.messages import stamp_ns, TickMessages
from ..formats.parameter_file import load_model_params
from ..formats.runlog import engine_config_json, event_text, failure_event, input_event
from ..formats.topics import TOPICS
from ..physics.integrator import set_threads
from ..physics.params import ModelParams
from ..physics.simulation import kernel_cache_note

__all__ = ['SimNode', 'TopicInfo', 'main']

NODE_NAME = 'sim_node'


class SimNode(GuardedNode):
    """The cone feeder simulator as a ROS 2 node; see the module documentation."""

    def __init__(self, clock: Callable[[], float] = time.perf_counter, **kwargs: Any) -> None:
        """
        Declare the parameters, build the engine and create every ROS handle.

        clock: the steady wall clock (s) the pacing follows (the tests' is made up).
        """
        self._wall_clock = clock
        super().__init__(NODE_NAME, **kwargs)

    def _setup(self) -> None:
        specs = {s.name: s for s in parameter_specs()}
        self._resim: Resimulation | None = None
        replay = declare(self, specs['replay_commands']).value
        if replay:
            self._resim = Resimulation(load_resim_plan(replay))
        file_param = self._declare(specs['parameter_file']).value
        if self._resim is not None:
            # every model.<key> is recorded: the model does not depend on the file any more
            self._base_model = model_from_values(self._resim.plan.parameters, ModelParams())
        else:
            self._base_model = load_model_params(file_param or None)  # '' = table2.yaml
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
        codec = default_codec()
        self._outputs = Outputs(self, codec)
        self._inputs = Inputs(self._engine, codec, str(values['frame_id']))
        self._throttle = RefusalThrottle()
        self._messages = TickMessages(self._engine.model, str(values['frame_id']),
                                      float(values['markers.rate']),
                                      clock=bool(values['publish_clock']), codec=codec)
        self._ticker = Ticker(self._engine, Pacer(self._engine.dt,
                                                  float(values['real_time_factor']),
                                                  float(values['catch_up'])),
                              done=lambda: self._job_done.trigger(),
                              before_tick=self._before_tick, clock=self._wall_clock)
        #: marker rate changes (from tick index, rate): the worker may be ticks ahead of those
        self._marker_rates: list[tuple[int, float]] = []
        self._paused = False
        self._totals = RunTotals()
        # the worker may be ticks ahead: the node's time is that of the last published tick
        # (stamps of events, received messages and diagnostics, so log times never go back)
        self._published_t = self._engine.t
        self._published_index = self._engine.tick_index

        # the topic table's order: publishers, then subscriptions
        self._pub = {name: self._outputs.publisher(name) for name, spec in TOPICS.items()
                     if spec.direction == 'out' and (name != '/clock' or values['publish_clock'])}
        self._subs = [self._outputs.subscription(name, partial(self.inject, name))
                      for name, spec in TOPICS.items() if spec.direction == 'in']
        self._srv_reset = self.create_service(Trigger, '~/reset', self._on_reset)
        self._srv_pause = self.create_service(SetBool, '~/pause', self._on_pause)
        self._srv_step = self.create_service(Trigger, '~/step', self._on_step)
        self._job_done = self.create_guard_condition(self._on_job_done)

        self._recording = NodeRecording(values, self._outputs.topics(), lambda: node_metadata(
            values, self._engine, self.get_fully_qualified_name(), self.get_namespace(),
            self._outputs.names, self._outputs.input_topics()))
        if self._recording.recorder is not None:
            self._outputs.add_hook(self._recording.recorder.hook)
            self.get_logger().info(f'recording to {self._recording.path}')
        if self._resim is not None:
            for level, text in self._resim.notes(engine_config_json(self._engine.config)):
                getattr(self.get_logger(), level)(text)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        start_paused = bool(values['start_paused'])
        self._tick_timer = self.create_timer(self._ticker.timer_period, self._on_timer,
                                             clock=steady, autostart=not start_paused)
        self._paused = start_paused
        self._diag_timer = self.create_timer(float(values['diagnostics.period']),
                                             self._publish_diagnostics, clock=steady)
        self._recording_timer = (self.create_timer(0.25, self._check_recording, clock=steady)
                                 if self._recording.recorder is not None else None)
        warn_unknown_parameters(self)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(
            f'simulating {self._engine.piece_count} pieces, dt = {self._engine.dt:g} s, '
            f'real_time_factor = {self._ticker.pacer.rtf:g}, feed '
            f'{self._engine.feed.rate:g} pieces/s')
        self._end_resim_if_done()  # a recording of no tick

    def _declare(self, spec: ParamSpec) -> Parameter:
        """Declare a parameter; while re-simulating, take recorded values over given ones."""
        if self._resim is None:
            return declare(self, spec)
        return declare_recorded(self, spec, recorded_parameter(self._resim.plan, spec.name))

    def _values(self) -> dict[str, Any]:  # _or: a '[]' in a parameter file leaves NOT_SET
        return {name: self.get_parameter_or(name).value for name in self._specs}

    # ------------------------------------------------------------------ public surface

    def add_message_hook(self, hook: MessageHook) -> None:
        """Call hook with every published and received message (exact serialized bytes)."""
        self._outputs.add_hook(hook)

    def remove_message_hook(self, hook: MessageHook) -> None:
        """Stop calling hook."""
        self._outputs.remove_hook(hook)

    def topics(self) -> list[TopicInfo]:
        """Return the node's topics with types, directions and QoS."""
        return self._outputs.topics()

    @property
    def engine(self) -> FeederEngine:
        """Return the engine, for tests and tools; submit inputs from the node's thread."""
        return self._engine

    @property
    def ticker(self) -> Ticker:
        """Return the ticker: its pacer, its diagnostics window, the timer period it asks."""
        return self._ticker

    @property
    def tick_timer_period_ns(self) -> int:
        """Return the period of the tick timer (ns of the steady clock)."""
        return self._tick_timer.timer_period_ns

    @property
    def paused(self) -> bool:
        """Tell whether the tick timer is paused."""
        return self._paused

    @property
    def replaying(self) -> bool:
        """Tell whether the node is re-simulating a recording (until its last tick)."""
        return self._resim is not None and self._resim.active

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

    @property
    def recording(self) -> NodeRecording:
        """Return the recording of this run (its paths, and its error once it stopped)."""
        return self._recording

    @property
    def recording_path(self) -> Path | None:
        """Return the path of this run's MCAP file (None when not recording)."""
        return self._recording.path

    # ------------------------------------------------------------------ recording

    def _check_recording(self) -> None:
        """End a recording that stopped (its writer thread flushes and checks by itself)."""
        if self._recording.stopped:
            self.close_recording()  # the simulation goes on without it

    def close_recording(self) -> None:
        """Finish the MCAP file (summary, statistics); idempotent. destroy_node() calls it."""
        recording = getattr(self, '_recording', None)
        if recording is None or not recording.recording:
            return
        self._publish_results(self._ticker.finish())  # its ticks belong to the recording
        self._outputs.remove_hook(recording.recorder.hook)
        line = recording.close({
            'ticks': str(self._engine.tick_index), 'end_time': repr(self._engine.t),
            'exits': str(self._totals.exits), 'failures': str(self._totals.failures),
            'refused_inputs': str(self._totals.refused)})
        if line is not None:
            self.log_at_exit(*line)

    def destroy_node(self) -> None:
        """Finish the running tick and the recording, then destroy the node's handles."""
        try:
            ticker = getattr(self, '_ticker', None)
            if ticker is not None:
                self._publish_results(ticker.shutdown())
            self.close_recording()
        finally:
            super().destroy_node()

    # ------------------------------------------------------------------ events, refusals

    def _publish_event(self, event: dict[str, Any], time_ns: int | None = None) -> None:
        """Publish an event on ~/events (and so record it)."""
        self._outputs.publish(self._pub['~/events'], {'data': event_text(event)},
                              stamp_ns(self._published_t) if time_ns is None else time_ns)

    def _node_event(self, kind: str, **fields: Any) -> None:
        self._publish_event({'event': kind, 'tick': self._published_index,
                             't': self._published_t, **fields})

    def _refuse(self, what: str, count: int, reason: str, text: str | None = None) -> None:
        """
        Count, log and record refused input: ``count`` items of ``what``, and why.

        The log line (``text``, default ``<what> refused: <reason>``) is throttled.
        """
        self._totals.refused += count
        if self._throttle.due(what, reason):
            self.get_logger().warning(text or f'{what} refused: {reason}')
        self._node_event('refused', input=what, count=count, reason=reason)

    def _refuse_live(self, what: str) -> bool:
        """Refuse a live input while re-simulating; return whether it was refused."""
        if not self.replaying:
            return False
        self._refuse(what, 1, 're-simulating a recording')
        return True

    # ------------------------------------------------------------------ inputs

    def inject(self, name: str, data: bytes) -> None:
        """
        Take serialized bytes as if received on input topic ``name`` (its subscription's call).

        name: ``rotation_cmd``, ``spawn`` or ``channel_feed``. The message is recorded (up to
        MAX_RECORDED_INPUT_BYTES), then decoded and handed to the engine.
        """
        if not self._outputs.received(name, data, stamp_ns(self._published_t)):
            self._node_event('input_not_recorded', topic=self._outputs.names[name],
                             bytes=len(data),
                             reason=f'larger than {MAX_RECORDED_INPUT_BYTES} bytes')
        if self._refuse_live(name):
            return
        outcome = self._inputs.handle(name, data)
        for refusal, text in outcome.lines():
            self._refuse(refusal.kind, refusal.count, refusal.reason, text)
        if outcome.warning is not None:
            self.get_logger().warning(outcome.warning, throttle_duration_sec=5.0)

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
            self._publish_results(self._ticker.finish())
            self._node_event('pause')
            return f'paused at t = {self._engine.t:.6f} s'
        if not self._paused:
            return 'already running'
        self._paused = False
        self._ticker.restart()
        self._tick_timer.reset()
        self._node_event('resume')
        return f'resumed at t = {self._engine.t:.6f} s'

    def step(self) -> TickResult:
        """Run one tick now and publish it (what ~/step does while paused)."""
        self._publish_results(self._ticker.finish())
        self._node_event('step')
        result = self._ticker.tick_once()
        self._publish_results([result])
        self._end_resim_if_done()
        return result[0]

    # ------------------------------------------------------------------ parameters

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        reason = parameter_problem(self._values(), parameters, self._engine, self.replaying)
        if reason is None:
            return SetParametersResult(successful=True)
        self._node_event('refused', input='parameters', count=len(parameters), reason=reason,
                         values={p.name: p.value for p in parameters})
        return SetParametersResult(successful=False, reason=reason)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        names = {p.name for p in parameters}
        values = self._values()
        drive = drive_from_values(values) if names & set(DRIVE_PARAMETERS) else None
        feed = feed_from_values(values) if any(n.startswith('feed.') for n in names) else None
        if drive is not None or feed is not None:
            self._engine.reconfigure(drive=drive, feed=feed)
        if 'real_time_factor' in names:
            self._ticker.pacer.rtf = float(values['real_time_factor'])
            self._tick_timer.timer_period_ns = int(round(self._ticker.timer_period * 1e9))
            self._ticker.restart()
        if 'catch_up' in names:
            self._ticker.pacer.catch_up = float(values['catch_up'])
        index = self._engine.tick_index  # the next tick the worker starts
        if 'markers.rate' in names:
            self._marker_rates.append((index, float(values['markers.rate'])))
        if 'diagnostics.period' in names:
            self._diag_timer.timer_period_ns = int(round(values['diagnostics.period'] * 1e9))
        self._node_event('parameters', tick=index, values={p.name: p.value for p in parameters})

    # ------------------------------------------------------------------ the tick

    def _before_tick(self) -> None:
        """Submit the recorded inputs of the next tick while re-simulating (worker thread)."""
        if self._resim is not None:
            self._resim.submit_inputs(self._engine)

    def _start_ticks(self) -> None:
        limit = self._resim.remaining(self._engine.tick_index) if self.replaying else None
        self._ticker.start(limit)

    def _on_timer(self) -> None:
        if self._ticker.busy:
            self._on_job_done()  # a finished job whose wake-up has not been served yet
        # a re-simulation whose last ticks a pause or a close collected ends here
        elif not self._paused and not self._end_resim_if_done():
            self._start_ticks()

    def _on_job_done(self) -> None:
        """Start the next ticks if due, then publish the finished ones (executor)."""
        begin = time.perf_counter()
        results = self._ticker.collect()
        if results is None:
            return  # already handed over by finish()
        if not self._paused:
            self._start_ticks()  # the worker ticks on while these are published
        self._publish_results(results)
        if not self._ticker.busy:
            self._end_resim_if_done()
        window = self._ticker.window
        window.callback_max = max(window.callback_max, time.perf_counter() - begin)

    def _end_resim_if_done(self) -> bool:
        """End a re-simulation that made every recorded tick (pause); return whether it did."""
        if self._resim is None or not self._resim.due_to_end(self._engine.tick_index):
            return False
        text = self._resim.finish(self._engine.t)
        self.set_paused(True)
        self.get_logger().info(text)
        return True

    def _publish_results(self, results: Ticks) -> None:
        """Publish and count finished ticks, in tick order (executor thread)."""
        period = self._ticker.pacer.period
        for result, seconds in results:
            stepped = time.perf_counter()
            if self._resim is not None:
                self._marker_rates.extend(self._resim.marker_rates(result.index))
            while self._marker_rates and self._marker_rates[0][0] <= result.index:
                self._messages.schedule.rate = self._marker_rates.pop(0)[1]
            self._publish_tick(result)
            self._published_t, self._published_index = result.t, result.index + 1
            publish_s = time.perf_counter() - stepped
            self._ticker.window.count(result, seconds, publish_s, period)
            self._totals.count(result, seconds, publish_s)
            for failure in result.failures:
                self.get_logger().warning(
                    f'piece {failure.particle_id} removed at t = {failure.t:.6f} s: '
                    f'{failure.reason} (at {failure.position})')
                self._publish_event(failure_event(result.index, failure), stamp_ns(failure.t))
            for refusal in result.refusals:
                self._refuse(refusal.kind, refusal.count, refusal.reason)

    def _publish_tick(self, res: TickResult) -> None:
        t0_ns = stamp_ns(res.t0)
        for item in res.applied:
            self._publish_event(input_event(res.index, res.t0, item), t0_ns)
        t_ns = stamp_ns(res.t)
        for name, message in self._messages(res):
            self._outputs.publish(self._pub[name], message, t_ns)

    def _publish_diagnostics(self) -> None:
        now = self._wall_clock()
        self._outputs.publish(self._pub['/diagnostics'], diagnostics_message(
            self.get_fully_qualified_name(), self._ticker.window, now, self._engine,
            self._ticker.pacer, self._paused, self._totals, self._recording.recorder,
            self._recording.error, self._published_t), stamp_ns(self._published_t))
        if not self._paused:
            self._ticker.new_window()


def main(args: list[str] | None = None) -> int:
    """Run the node until shut down (the recording is finished in every path)."""
    return run_node(SimNode, NODE_NAME, args)


if __name__ == '__main__':
    sys.exit(main())
