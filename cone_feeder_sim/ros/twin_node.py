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
``twin_node``: the digital twin of a running feeder; detections in, forecasts out.

Run it beside the feeder (or beside ``sim_node`` standing in for one)::

    ros2 run cone_feeder_sim twin_node --ros-args -r detections:=particle_states

It subscribes ``detections`` (sensor_msgs/PointCloud2 in the feeder frame: fields x, y, z,
optionally track_id and mass; ``sim_node``'s ``particle_states`` has this layout) and
``cone_state`` (sensor_msgs/JointState, joint ``cone``: the measured speed), and takes the
exits a channel's sensors measure where they are published: ``exit_events``
(sensor_msgs/PointCloud2: a field channel, optionally exit_time and mass, a load cell's
step; ``sim_node``'s has all three).
It publishes

- ``twin/pieces`` (PointCloud2: each piece's position, spread, most likely channel, its
  probability, the time to its exit and the camera's track id last associated with it),
- ``twin/channel_forecast`` (Float64MultiArray: per horizon and channel, the expected mass
  and its spread, kg),
- ``twin/parameters`` (Float64MultiArray: d, its spread, mu_C, its spread),
- ``/diagnostics`` (the NIS against its degrees of freedom, the association rate, the
  ensemble's spread, the real-time factor, the latency from a frame's arrival to its
  publication, the share of the measured exits the twin explained, the mean piece mass
  the weighed exits give (:attr:`~..twin.estimator.Twin.piece_mass`), and the state:
  following, open loop or lost),

and records them with its inputs to MCAP (``record_path``). The model is sim_node's
(``parameter_file``, ``model.*``, ``solver.*``), so a parameter file made for sim_node with
the key ``/**:`` serves both. The twin itself is :class:`~..twin.live.Follower`; this node
only turns messages into its inputs and its results into messages. A refused input (a
coordinate that is not finite, a frame of more than 10,000 points, a wrong frame_id, a stamp
from the future, a joint of another name) is logged in one line and the twin goes on.
"""

from dataclasses import replace
import sys
import threading
import time
from typing import Any

import numpy as np

from .diagnostics import diagnostic_status
from .guarded_node import GuardedNode, run_node
from .outputs import Outputs
from .parameters import declare, model_and_solver_from_values, parameter_specs, ParamSpec, \
    warn_unknown_parameters
from .recording import NodeRecording
from ..errors import ConeFeederError, Stopped, TwinError
from ..formats.cdr import CdrCodec
from ..formats.messages import header, stamp, stamp_seconds
from ..formats.parameter_file import load_model_params
from ..formats.pointcloud import cloud_points
from ..formats.runlog import run_metadata
from ..formats.topics import TWIN_TOPICS
from ..physics.params import Limit
from ..physics.simulation import SimParams
from ..twin.estimator import parameter_note, TUNING, TwinSettings
from ..twin.frames import cone_speed, detection_frame, measured_exits, not_ahead
from ..twin.live import Follower, LiveSettings
from ..twin.messages import channel_forecast_message, parameters_message, pieces_message

__all__ = ['main', 'TwinNode']

#: The twin's own parameters (the model, solver and recording ones are sim_node's).
TWIN_PARAMETERS = (
    ParamSpec('members', 4, 'ensemble size M (simulations the twin runs side by side; 4 '
              'about keeps up with 30 pieces at 30 frames/s on 2 cores, 8 does not: '
              'doc/twin.md)',
              limit=Limit(2, 10_000, '')),
    ParamSpec('sigma', 0.002, "the detections' noise (m, each of x and y)",
              limit=Limit(0.0, 1.0, 'm', lo_open=True)),
    ParamSpec('d_spread', 0.5, "the prior's relative spread of d (log scale)",
              limit=Limit(0.0, 10.0, '')),
    ParamSpec('mu_C_spread', 0.05, "the prior's spread of mu_C", limit=Limit(0.0, 5.0, '')),
    ParamSpec('horizons', [0.5, 1.0, 2.0], 'forecast horizons (s)'),
    ParamSpec('forecast_period', 0.5, 's of stream time between forecasts (each costs M '
              'simulations over the longest horizon)',
              limit=Limit(0.0, 3600.0, 's', lo_open=True)),
    ParamSpec('forecast_thread', True, 'forecasts on a thread of their own: a frame is '
              'answered after its analysis, not after a forecast (false: in turn, as headless)'),
    ParamSpec('open_loop_after', 1.0, 's without a frame after which the twin goes on open '
              'loop', limit=Limit(0.0, 3600.0, 's', lo_open=True)),
    ParamSpec('max_delay', 0.2, 'how late (s) a frame may arrive: the twin goes back to itself '
              'before it and analyses again', limit=Limit(0.0, 10.0, 's')),
    ParamSpec('death_after', 1.0, 'a piece not seen for this long (s) is dropped',
              limit=Limit(0.0, 3600.0, 's', lo_open=True)),
    ParamSpec('loosen', 100.0, "the solver's tolerances times this for the members (100, "
              "not the twin file's 10: the p95 latency at 30 pieces 20-49 ms in 7 runs of 9 "
              'against 74-403 ms, the forecasts a few pieces in 100 less often right: '
              'doc/twin.md)',
              limit=Limit(1.0, 1.0e6, '')),
    ParamSpec('seed', 0, "the ensemble's seed", limit=Limit(0, 2 ** 31 - 1, '')),
    ParamSpec('drift', 0.05, "d's and mu_C's random walk per sqrt(s) (relative for d)",
              limit=Limit(0.0, 10.0, '')),
    ParamSpec('inflation', 1.1, "the pieces' deviations from the members' mean times this "
              'before each analysis', limit=Limit(1.0, 10.0, '')),
    ParamSpec('window', 0.5, 'd and mu_C weighed once per window of this many s (0: frame '
              'by frame)', limit=Limit(0.0, 60.0, 's')),
    ParamSpec('confirm', 2, 'the frames a new piece must be seen in before it counts',
              limit=Limit(1, 1000, '')),
    ParamSpec('tentative_after', 0.1, 'a piece not yet confirmed and not seen for this long '
              '(s) is dropped', limit=Limit(0.0, 3600.0, 's')),
    ParamSpec('localize_below', 16, 'the analysis is localized by piece when members is '
              'below this (doc/twin.md)', limit=Limit(0, 1_000_000, '')),
    ParamSpec('particles', 32, 'the values of d and mu_C each window weighs (at least '
              'members: the members run with some of them)', limit=Limit(2, 10_000, '')),
    ParamSpec('smoother_pieces', 6, 'the pieces whose detections weigh them, the fastest '
              'sliding (each frame integrates (particles + members) x these more)',
              limit=Limit(1, 10_000, '')),
)
#: How often (s) the watcher looks whether the context was shut down.
STOP_POLL = 0.05
#: sim_node's parameters that mean the same here.
SHARED = ('parameter_file', 'frame_id', 'diagnostics.period', 'record_path',
          'record_compression', 'record_max_file_size', 'record_max_file_duration',
          'record_min_free_space')


def twin_parameter_specs(base: Any = None) -> list[ParamSpec]:
    """Return every parameter of the node: its own, sim_node's shared, model and solver."""
    specs = []
    for spec in parameter_specs(base):
        if spec.name == 'record_path':
            spec = replace(spec, default=spec.default.replace('sim_node', 'twin_node'))
        if spec.name == 'interactions.enabled':  # sim_node's is on: the twin cannot afford it
            spec = replace(spec, default=False, description=(
                "contact between pieces in the twin's members (off: at 30 pieces and 4 "
                'members the twin fell from 30 frames/s to under 1, doc/twin.md; the pair '
                "law's other parameters are sim_node's)"))
        if spec.name in SHARED or spec.name.startswith(('model.', 'solver.', 'interactions.')):
            specs.append(spec)
    return list(TWIN_PARAMETERS) + specs


class TwinNode(GuardedNode):
    """Follow a feeder from its detections; see the module documentation."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, build the twin, create the topics and the recording."""
        super().__init__('twin_node', **kwargs)

    def _setup(self) -> None:
        specs = {s.name: s for s in twin_parameter_specs()}
        file_param = declare(self, specs['parameter_file']).value
        base = load_model_params(file_param or None)
        values: dict[str, Any] = {'parameter_file': file_param}
        for spec in twin_parameter_specs(base):
            if spec.name != 'parameter_file':
                values[spec.name] = declare(self, spec).value
        warn_unknown_parameters(self)
        horizons = tuple(float(h) for h in values['horizons'])
        if not horizons or not all(0.0 < h <= 60.0 for h in horizons):
            raise TwinError(f'horizons must be numbers in (0, 60] s, got {list(horizons)}')
        model, solver = model_and_solver_from_values(values, base)
        settings = TwinSettings(
            members=int(values['members']), sigma=float(values['sigma']), d=model.product.d,
            mu_C=model.product.mu_C, seed=int(values['seed']),
            **{key: type(low)(values[key]) for key, low in TUNING.items()})
        self._model = model
        self._follower = Follower(SimParams(model=model, solver=solver), LiveSettings(
            twin=settings, horizons=horizons, forecast_period=float(values['forecast_period']),
            open_loop_after=float(values['open_loop_after']),
            max_delay=float(values['max_delay']), background=bool(values['forecast_thread'])))
        self._frame_id = str(values['frame_id'])
        self._codec = CdrCodec()
        self._outputs = Outputs(self, self._codec, TWIN_TOPICS)
        self._pub = {name: self._outputs.publisher(name) for name, spec in TWIN_TOPICS.items()
                     if spec.direction == 'out'}
        self._outputs.subscription('detections', self._on_detections)
        self._outputs.subscription('cone_state', self._on_cone_state)
        self._outputs.subscription('exit_events', self._on_exits)
        self._lead: float | None = None  # stamps minus their arrival times (s): the largest
        self._latencies: list[float] = []
        self._arrivals: dict[float, int] = {}  # a waiting frame's stamp (s): arrival (ns)
        self._published_outlook: Any = None
        self._refused = 0
        self._recording = NodeRecording(values, self._outputs.topics(), lambda: run_metadata(
            values, 'twin_node', self._outputs.names, self._outputs.input_topics(),
            node=self.get_fully_qualified_name(), namespace=self.get_namespace()))
        if self._recording.recorder is not None:
            self._outputs.add_hook(self._recording.recorder.hook)
            self.get_logger().info(f'recording to {self._recording.path}')
        self.create_timer(float(values['diagnostics.period']), self._publish_diagnostics)
        # the twin computes in the executor's thread, where a signal's handler waits for the
        # callback's end; this thread sees the context shut down and stops the kernels
        self._done = threading.Event()
        self._watcher = threading.Thread(target=self._watch, name='twin-stop', daemon=True)
        self._watcher.start()
        self.get_logger().info(
            f'following with {settings.members} members, forecasts every '
            f"{values['forecast_period']:g} s over {', '.join(f'{h:g}' for h in horizons)} s")
        if note := parameter_note(settings):
            self.get_logger().info(note)

    def _watch(self) -> None:
        """Stop the twin's computation once the context is shut down (SIGINT, SIGTERM)."""
        while not self._done.wait(STOP_POLL):
            if not self.context.ok():
                self._follower.stop.request()
                return

    # ------------------------------------------------------------------ inputs

    def _latest(self, arrival: float | None = None) -> float | None:
        """
        Return the newest stamp an input arriving at ``arrival`` (wall s) may carry, or None.

        The stamps' lead over their arrival times (the largest of the inputs taken so far)
        plus the arrival: measured from the arrival, not from when the twin took the input,
        so that a twin busy for a second does not take the next frames for the future.
        """
        if self._lead is None:
            return None
        return (time.time() if arrival is None else arrival) + self._lead

    def _took(self, t: float, arrival: float) -> None:
        self._lead = t - arrival if self._lead is None else max(self._lead, t - arrival)

    def _received(self, name: str, data: bytes) -> tuple[dict[str, Any], float]:
        """Decode a message of table topic name, record it; return it and its stamp (s)."""
        msg = self._codec.decode(TWIN_TOPICS[name].type_name, data, strict=False)
        t = stamp_seconds(msg['header']['stamp'])
        self._outputs.received(name, data, round(t * 1e9))
        return msg, t

    def _refuse(self, text: str) -> None:
        self._refused += 1
        self.get_logger().warning(text, throttle_duration_sec=1.0)

    def _on_cone_state(self, data: bytes, info: Any) -> None:
        """Take the measured cone speed: frames that waited for it go on; open loop."""
        arrival = _arrival(info)
        before = self._follower.outlook
        try:
            msg, t = self._received('cone_state', data)  # one that does not decode: refused
            not_ahead('cone speed', t, self._latest(arrival))
            omega = cone_speed(t, list(msg['name']), [float(v) for v in msg['velocity']])
            taken = self._follower.cone_speed(t, omega)
        except Stopped:
            return
        except (TwinError, ValueError) as exc:
            self._refuse(str(exc))
            return
        self._took(t, arrival)
        if taken or self._follower.outlook is not before:
            self._publish(taken)

    def _on_detections(self, data: bytes, info: Any) -> None:
        """Take a frame of detections: check it, hand it to the twin, publish what it did."""
        arrival = _arrival(info)
        try:
            msg, t = self._received('detections', data)
            found = detection_frame(t, cloud_points(msg), msg['header']['frame_id'],
                                    self._frame_id, self._latest(arrival))
            self._arrivals[t] = round(arrival * 1e9)  # until the frame is taken
            try:
                taken = self._follower.frame(found)
            except ValueError:
                del self._arrivals[t]  # refused by the twin: it will not be taken
                raise
        except Stopped:
            return
        except (ConeFeederError, ValueError) as exc:
            self._refuse(str(exc))
            return
        self._took(t, arrival)
        if taken:
            self._publish(taken)

    def _on_exits(self, data: bytes, info: Any) -> None:
        """Take measured exits: a frame stamped EXIT_LAG s after each takes it."""
        arrival = _arrival(info)
        try:
            msg, t = self._received('exit_events', data)
            not_ahead('exits', t, self._latest(arrival))
            exits = measured_exits(t, cloud_points(msg), self._model.channels.count)
        except (ConeFeederError, ValueError) as exc:
            self._refuse(str(exc))  # the message is refused whole
            return
        taken: list[float] = []
        try:
            for when, channel, mass in exits:  # one older than the history is refused alone
                try:
                    taken += self._follower.measured_exit(when, channel, mass)
                except ValueError as exc:
                    self._refuse(str(exc))
        except Stopped:
            return
        if taken:
            self._publish(taken)

    # ------------------------------------------------------------------ outputs

    def _publish(self, taken: list[float]) -> None:
        """Publish the twin's pieces, parameters and a new forecast (the frames taken)."""
        twin = self._follower.current
        t = twin.t
        ns = round(t * 1e9)
        head = header(t, self._frame_id)
        ids, mean, covariance = twin.pieces()
        by_piece = twin.masses
        masses = np.array([by_piece[int(i)] for i in ids], dtype=float)
        outlook = self._follower.outlook
        self._outputs.publish(self._pub['twin/pieces'], pieces_message(
            head, self._model, ids, mean, covariance, masses, outlook, twin.tracks), ns)
        if outlook is not None and outlook is not self._published_outlook:
            self._published_outlook = outlook
            self._outputs.publish(self._pub['twin/channel_forecast'],
                                  channel_forecast_message(outlook), ns)
        self._outputs.publish(self._pub['twin/parameters'],
                              parameters_message(twin.parameters()), ns)
        now = time.time_ns()
        for stamp_s in taken:
            arrival = self._arrivals.pop(stamp_s, None)
            if arrival is not None:
                self._latencies.append((now - arrival) * 1e-9)

    def _publish_diagnostics(self) -> None:
        figures = self._follower.figures()
        t = self._follower.t
        state = self._follower.state(self._latest())  # the stream's time now, as estimated
        latencies = np.array(self._latencies or [np.nan])
        self._latencies = []
        values = {
            'state': state,
            'frames': str(figures['frames']),
            'forecasts': str(figures['forecasts']),
            'NIS': f"{figures['nis']:.4g}",
            'NIS degrees of freedom': str(figures['observed']),
            'association rate': f"{figures['association']:.3f}",
            'real-time factor (capacity)': f"{figures['rtf']:.3g}",
            'latency p95 (ms)': f'{1e3 * np.percentile(latencies, 95):.1f}',
            'latency max (ms)': f'{1e3 * np.max(latencies):.1f}',
            'inputs refused': str(self._refused),
            'exits measured': str(figures['measured']),
            'exits explained': f"{figures['explained']:.3f}",
        }
        if self._follower.twin is not None:
            ids, _, covariance = self._follower.current.pieces()
            spread = np.sqrt(np.trace(covariance, axis1=1, axis2=2)) if len(ids) else [np.nan]
            values['pieces'] = str(len(ids))
            values['ensemble spread median (mm)'] = f'{1e3 * float(np.median(spread)):.3g}'
            for key, (estimate, sd) in self._follower.current.parameters().items():
                values[key] = f'{estimate:.5g} +- {sd:.2g}'
            values['piece mass (kg)'] = f'{self._follower.current.piece_mass:.5g}'
        level = 0 if state == 'following' else 1
        status = diagnostic_status(level, f'{self.get_fully_qualified_name()}: twin', state,
                                   values)
        message = {'header': {'stamp': stamp(t or 0.0), 'frame_id': ''}, 'status': [status]}
        self._outputs.publish(self._pub['/diagnostics'], message, round((t or 0.0) * 1e9))

    def destroy_node(self) -> None:
        """Close the recording (with its totals), then destroy the node's handles."""
        done = getattr(self, '_done', None)
        if done is not None:
            done.set()
        follower = getattr(self, '_follower', None)
        if follower is not None:
            follower.stop.request()  # the forecast under way ends within a step
            follower.close()
        try:
            recording = getattr(self, '_recording', None)
            if recording is not None:
                closed = recording.close({'inputs_refused': str(self._refused)})
                if closed is not None:
                    self.log_at_exit(*closed)
        finally:
            super().destroy_node()


def _arrival(info: Any) -> float:
    """Return when a message arrived (wall s): rmw's received_timestamp, else now."""
    received = info.get('received_timestamp') if info is not None else None
    return received * 1e-9 if received else time.time()


def main(args: list[str] | None = None) -> int:
    """Run the twin until shut down; return the process exit status."""
    return run_node(TwinNode, 'twin_node', args)


if __name__ == '__main__':
    sys.exit(main())
