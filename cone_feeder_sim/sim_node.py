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
config/sim_node.yaml`` (or ``sim_node`` / ``python -m cone_feeder_sim.sim_node`` in a
virtual environment with the ``ros-jazzy-*`` wheels). All physics, the drive and the feed
live in :class:`~cone_feeder_sim.engine.FeederEngine`; this module turns ROS input into
engine input and engine output into messages. Messages are built from numpy arrays,
encoded by :mod:`cone_feeder_sim.cdr` and published as serialized bytes; every published
and received message passes through :meth:`SimNode.add_message_hook` callbacks with its
exact bytes (for MCAP recording).

Time: the engine's step is ``dt = 1 / update_rate`` of simulated time. The tick timer runs
on the steady clock with period ``dt / real_time_factor`` (``real_time_factor`` 0: as fast
as possible). One timer callback runs exactly one tick: when the CPU cannot keep up, the
timer skips the missed periods (no backlog, no catching up), simulated time runs slower
than ``real_time_factor`` asks, and ``/diagnostics`` says so (level WARN). Header stamps are
simulation time; ``/clock`` (when ``publish_clock``) carries the same time, never 0 (the
first tick ends at ``dt``). The node's own clock and ``use_sim_time`` do not drive it.

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
"""

from collections.abc import Callable
from dataclasses import dataclass, fields
import math
from pathlib import Path
import sys
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
import numpy as np
from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMessage
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from .cdr import CdrError, default_codec
from .config import config_dir, DEFAULT_PARAMETER_FILE, read_yaml
from .engine import (
    DriveParams, EngineConfig, FeederEngine, FeedParams, pattern_from_flat, PieceSpec,
    TickResult)
from .errors import ConeFeederError, ParameterError
from .params import (
    CHANNEL_KEYS, MODEL_KEYS, MODEL_LIMITS, model_params_from_mapping, ModelParams,
    PRODUCT_LIMITS, SolverParams)
from .recording import QosProfile
from .simulation import check_positions

__all__ = [
    'MessageRecord',
    'ParamSpec',
    'SimNode',
    'TopicInfo',
    'main',
    'parameter_specs',
]

NODE_NAME = 'sim_node'
DEFAULT_FRAME = 'feeder'

#: The five pieces of Table I of the paper: start position (m) and damping d (N*s/m).
TABLE_I = (((0.11, -0.01, 0.03), 225.0), ((-0.10, -0.01, 0.03), 135.0),
           ((0.08, -0.13, 0.03), 750.0), ((-0.07, 0.04, 0.03), 750.0),
           ((0.14, 0.06, 0.03), 30.0))
#: Default open-loop pattern: 2 s clockwise, 2 s counter-clockwise at 8 rad/s.
DEFAULT_PATTERN = (2.0, -8.0, 2.0, 8.0)
#: Default damping values of fed pieces: those of Table II.
DEFAULT_D_VALUES = (30.0, 135.0, 225.0, 750.0)

# --------------------------------------------------------------------------- QoS

STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
EVENTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)

# --------------------------------------------------------------------------- point layouts

# sensor_msgs/PointField datatypes
UINT32 = 6
FLOAT32 = 7
FLOAT64 = 8

STATE_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'vx', 'vy', 'vz', 'id', 'mass'],
    'formats': ['<f4'] * 6 + ['<u4', '<f4'],
    'offsets': [0, 4, 8, 12, 16, 20, 24, 28],
    'itemsize': 32})
STATE_DATATYPES = [FLOAT32] * 6 + [UINT32, FLOAT32]

EXIT_DTYPE = np.dtype({
    'names': ['x', 'y', 'z', 'vx', 'vy', 'vz', 'exit_time', 'angle', 'mass', 'id', 'channel'],
    'formats': ['<f8'] * 9 + ['<u4', '<u4'],
    'offsets': [0, 8, 16, 24, 32, 40, 48, 56, 64, 72, 76],
    'itemsize': 80})
EXIT_DATATYPES = [FLOAT64] * 9 + [UINT32, UINT32]


def point_fields(dtype: np.dtype, datatypes: list[int]) -> list[dict[str, Any]]:
    """Return the sensor_msgs/PointField list describing a structured dtype."""
    return [{'name': name, 'offset': dtype.fields[name][1], 'datatype': datatype, 'count': 1}
            for name, datatype in zip(dtype.names, datatypes)]


# --------------------------------------------------------------------------- hooks


@dataclass(frozen=True)
class MessageRecord:
    """
    One message as it went over the wire.

    direction: 'out' (published) or 'in' (received); topic: the fully resolved name;
    type_name: 'pkg/msg/Type'; data: the serialized CDR bytes (with encapsulation header);
    stamp_ns: simulation time (ns) of the message (received: the engine time on arrival);
    wall_ns: system time (ns) when it was published or received.
    """

    direction: str
    topic: str
    type_name: str
    data: bytes
    stamp_ns: int
    wall_ns: int


@dataclass(frozen=True)
class TopicInfo:
    """A topic of the node: resolved name, type, direction and QoS (for recorders)."""

    topic: str
    type_name: str
    direction: str
    qos: QosProfile


MessageHook = Callable[[MessageRecord], None]


def _recording_qos(qos: QoSProfile) -> QosProfile:
    return QosProfile(
        history='keep_last' if qos.history == HistoryPolicy.KEEP_LAST else 'keep_all',
        depth=int(qos.depth),
        reliability=('reliable' if qos.reliability == ReliabilityPolicy.RELIABLE
                     else 'best_effort'),
        durability=('transient_local' if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
                    else 'volatile'))


# --------------------------------------------------------------------------- parameters


@dataclass(frozen=True)
class ParamSpec:
    """
    One ROS parameter of the node.

    default: the default value (its type is the parameter's type) or, for an array that is
    empty by default, a Parameter.Type; limits: inclusive range for numbers (open bounds
    are checked when the value is used); dynamic: may change at run time.
    """

    name: str
    default: Any
    description: str
    dynamic: bool = False
    limits: tuple[float, float] | None = None
    constraints: str = ''

    def type_(self) -> Parameter.Type:
        """Return the parameter type."""
        if isinstance(self.default, Parameter.Type):
            return self.default
        return Parameter.Type.from_parameter_value(self.default)

    def descriptor(self) -> ParameterDescriptor:
        """Return the ROS descriptor: type, description, range, read-only flag."""
        desc = ParameterDescriptor(
            name=self.name, type=self.type_().value, description=self.description,
            additional_constraints=self.constraints, read_only=not self.dynamic)
        if self.limits is not None:
            lo, hi = self.limits
            if self.type_() == Parameter.Type.INTEGER:
                desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi),
                                                   step=0)]
            elif self.type_() == Parameter.Type.DOUBLE:
                desc.floating_point_range = [FloatingPointRange(
                    from_value=float(lo), to_value=float(hi), step=0.0)]
        return desc


_MODEL_DESCRIPTIONS = {
    'm': 'default product: mass of a piece (kg)',
    'd': 'default product: viscous damping d (N*s/m)',
    'mu_C': 'default product: sliding (Coulomb) friction coefficient',
    'mu_S': 'default product: adhesive (static) friction coefficient',
    'v_C': 'default product: slope of the Coulomb curve at zero crossing (m/s)',
    'v_S': 'default product: velocity of maximum adhesion v-hat_S (m/s)',
    'T_F': 'default product: time constant of the friction low-pass filter (s)',
    'qdot_F': 'default product: filter adaptation velocity of eq. 14 (m/s)',
    's0': 'default product: outer radius of a piece (m)',
    's_c_ratio': 'default product: compression radius as a fraction of s0',
    'r_a': 'default product: activation at the compression radius, eq. 32',
    'r_d': 'default product: dissipation coefficient of the constraint, eq. 34 (s/m)',
    'r_f': 'default product: maximum force of the constraint, eq. 34 (N)',
    'g': 'gravity (m/s^2)',
    'cone_diameter': 'cone diameter (m)',
    'cone_tilt': 'cone tilt (deg)',
    'epsilon': 'regularisation of e_v, eq. 4 (m/s)',
    'tip_epsilon': 'regularisation of rho near the cone tip (m)',
    'normal_force': 'normal force inside friction: newton | literal',
    'friction_direction': 'friction direction: full | tangential',
    'channel_count': 'number of dosing channels (equal sectors)',
    'channel_boundary': 'angle where channel 1 starts (deg, atan2(y, x))',
    'channel_numbering': 'channel numbering seen from above: clockwise | counter_clockwise',
}

_SOLVER_SPECS = (
    ('rtol', 'integrator relative tolerance', (0.0, 1.0)),
    ('atol_position', 'integrator absolute tolerance of positions (m)', (0.0, 1.0)),
    ('atol_velocity', 'integrator absolute tolerance of velocities (m/s)', (0.0, 10.0)),
    ('atol_force', 'integrator absolute tolerance of the filter force (N)', (0.0, 1.0e3)),
    ('h_init', 'first trial step of the integrator (s)', (0.0, 1.0)),
    ('h_min', 'smallest step before a piece is declared failed (s)', (0.0, 1.0e-3)),
    ('h_max', 'longest integrator step (s)', (0.0, 10.0)),
    ('max_steps', 'steps allowed per piece and tick', (1, 1_000_000_000)),
)


def _model_value(model: ModelParams, key: str) -> Any:
    if key in PRODUCT_LIMITS:
        return float(getattr(model.product, key))
    if key in CHANNEL_KEYS:
        value = getattr(model.channels, CHANNEL_KEYS[key])
        return int(value) if key == 'channel_count' else (
            float(value) if key == 'channel_boundary' else value)
    value = getattr(model, key)
    return value if isinstance(value, str) else float(value)


def model_param_specs(base: ModelParams) -> list[ParamSpec]:
    """Return the read-only ``model.<key>`` parameters with defaults from ``base``."""
    specs = []
    for key in list(PRODUCT_LIMITS) + list(MODEL_KEYS) + list(CHANNEL_KEYS):
        limit = PRODUCT_LIMITS.get(key) or MODEL_LIMITS.get(key)
        specs.append(ParamSpec(
            f'model.{key}', _model_value(base, key), _MODEL_DESCRIPTIONS[key],
            limits=None if limit is None else (limit.lo, limit.hi),
            constraints='' if limit is None else f'allowed {limit.describe()}'))
    return specs


def parameter_specs(base: ModelParams | None = None) -> list[ParamSpec]:
    """Return every parameter of the node (model defaults from ``base``)."""
    solver = SolverParams()
    specs = [
        ParamSpec('parameter_file', '', 'model parameter file (YAML, keys of '
                  'config/table2.yaml); empty: the table2.yaml of the package. model.<key> '
                  'parameters override single values of it'),
        ParamSpec('update_rate', 50.0, 'ticks per second of simulated time: the simulation '
                  'step is dt = 1 / update_rate (Hz)', limits=(1.0, 1000.0)),
        ParamSpec('real_time_factor', 1.0, 'simulated seconds per wall-clock second; 0 runs '
                  'as fast as possible', dynamic=True, limits=(0.0, 100.0)),
        ParamSpec('publish_clock', False, 'publish the simulation time on /clock'),
        ParamSpec('start_paused', False, 'start paused (resume with ~/pause false, or '
                  '~/step): lets subscribers connect before anything happens'),
        ParamSpec('frame_id', DEFAULT_FRAME, 'frame of all published data and of spawn '
                  'poses (fixed, z up, origin at the centre of the cone base)'),
        ParamSpec('max_angular_velocity', 10.47, 'limit of the cone angular velocity; '
                  'commands beyond it are clamped (rad/s)', dynamic=True,
                  limits=(0.0, 100.0), constraints='> 0'),
        ParamSpec('max_angular_acceleration', 20.0, 'limit of the cone angular acceleration '
                  '(rad/s^2)', dynamic=True, limits=(0.0, 1.0e4), constraints='> 0'),
        ParamSpec('cmd_timeout', 0.5, 'seconds of simulated time without a rotation_cmd after '
                  'which the cone ramps to rest; 0 holds the last command', dynamic=True,
                  limits=(0.0, 1.0e6)),
        ParamSpec('open_loop_pattern', list(DEFAULT_PATTERN),
                  'target until the first rotation_cmd: flat pairs [duration s, omega rad/s, '
                  '...], looped; empty: rest', dynamic=True,
                  constraints='even length, durations > 0, |omega| <= 100'),
        ParamSpec('initial_pieces.positions', [v for p, _ in TABLE_I for v in p],
                  'pieces placed at the start and after each reset: flat [x, y, z, ...] (m, '
                  'world frame)', constraints='length a multiple of 3, inside the cone'),
        ParamSpec('initial_pieces.d', [d for _, d in TABLE_I],
                  'damping d of each initial piece (N*s/m); empty: the default product',
                  constraints='empty or one value per piece'),
        ParamSpec('feed.rate', 2.0, 'product feed: mean pieces per second (Poisson '
                  'arrivals); 0 = off', dynamic=True, limits=(0.0, 1.0e4)),
        ParamSpec('feed.rho_min', 0.03, 'product feed: inner radius of the drop annulus (m)',
                  dynamic=True, limits=(0.0, 20.0)),
        ParamSpec('feed.rho_max', 0.15, 'product feed: outer radius of the drop annulus (m)',
                  dynamic=True, limits=(0.0, 20.0), constraints='>= feed.rho_min, < r'),
        ParamSpec('feed.drop_height', 0.05, 'product feed: height of the centre of a new '
                  'piece above the cone surface (m)', dynamic=True, limits=(0.0, 10.0)),
        ParamSpec('feed.mass_rel_std', 0.2, 'product feed: relative standard deviation of the '
                  'log-normal mass (mean: model.m)', dynamic=True, limits=(0.0, 1.0)),
        ParamSpec('feed.d_values', list(DEFAULT_D_VALUES), 'product feed: damping values '
                  'drawn uniformly (N*s/m); empty: model.d', dynamic=True),
        ParamSpec('feed.max_pieces', 2000, 'product feed pauses while this many pieces are on '
                  'the cone', dynamic=True, limits=(1, 1_000_000)),
        ParamSpec('feed.seed', 0, 'seed of the random generator of the feed', limits=(0, 2 ** 62)),
        ParamSpec('markers.rate', 10.0, 'marker messages per second of simulated time (at most '
                  'one per tick); 0 = none', dynamic=True, limits=(0.0, 1000.0)),
        ParamSpec('diagnostics.period', 1.0, 'wall-clock seconds between /diagnostics messages',
                  dynamic=True, limits=(0.05, 3600.0)),
    ]
    specs += [ParamSpec(f'solver.{key}', getattr(solver, key), text, limits=limits)
              for key, text, limits in _SOLVER_SPECS]
    # settings added to SolverParams later are declared too (without a range of their own)
    known = {key for key, _, _ in _SOLVER_SPECS}
    specs += [ParamSpec(f'solver.{f.name}', getattr(solver, f.name),
                        f'integrator setting {f.name}, see cone_feeder_sim.params.SolverParams')
              for f in fields(SolverParams) if f.name not in known]
    specs += model_param_specs(base if base is not None else ModelParams())
    return specs


def _array(value: Any) -> list[float]:
    """Return a parameter's array value; NOT_SET (an empty YAML list) is empty."""
    return [] if value is None else list(value)


def drive_from_values(values: dict[str, Any]) -> DriveParams:
    """Build the drive from parameter values (raise ParameterError naming the problem)."""
    return DriveParams(
        max_angular_velocity=values['max_angular_velocity'],
        max_angular_acceleration=values['max_angular_acceleration'],
        cmd_timeout=values['cmd_timeout'],
        pattern=pattern_from_flat(_array(values['open_loop_pattern'])))


def feed_from_values(values: dict[str, Any]) -> FeedParams:
    """Build the feed from parameter values (raise ParameterError naming the problem)."""
    return FeedParams(
        rate=values['feed.rate'], rho_min=values['feed.rho_min'],
        rho_max=values['feed.rho_max'], drop_height=values['feed.drop_height'],
        mass_rel_std=values['feed.mass_rel_std'], d_values=tuple(_array(values['feed.d_values'])),
        max_pieces=values['feed.max_pieces'])


def model_from_values(values: dict[str, Any], base: ModelParams) -> ModelParams:
    """Build the model from the ``model.<key>`` values over ``base``."""
    mapping = {name[len('model.'):]: value for name, value in values.items()
               if name.startswith('model.')}
    return model_params_from_mapping(mapping, base)


def engine_config_from_values(values: dict[str, Any], base: ModelParams) -> EngineConfig:
    """Build and validate the whole engine configuration from parameter values."""
    model = model_from_values(values, base)
    solver = SolverParams(**{name[len('solver.'):]: value for name, value in values.items()
                             if name.startswith('solver.')})
    flat = _array(values['initial_pieces.positions'])
    if len(flat) % 3:
        raise ParameterError(f'initial_pieces.positions must be triples [x, y, z, ...]; got '
                             f'{len(flat)} numbers')
    positions = [tuple(flat[i:i + 3]) for i in range(0, len(flat), 3)]
    damping = _array(values['initial_pieces.d'])
    if damping and len(damping) != len(positions):
        raise ParameterError(f'initial_pieces.d has {len(damping)} values for '
                             f'{len(positions)} pieces (give one per piece or none)')
    pieces = tuple(
        PieceSpec(p, product=model.product.with_overrides({'d': damping[i]})
                  if damping else None)
        for i, p in enumerate(positions))
    return EngineConfig(model=model, solver=solver, dt=1.0 / values['update_rate'],
                        drive=drive_from_values(values), feed=feed_from_values(values),
                        initial_pieces=pieces, seed=values['feed.seed'])


def load_base_model(parameter_file: str) -> ModelParams:
    """Return the model of a parameter file ('' = the package's table2.yaml)."""
    path = Path(parameter_file) if parameter_file else config_dir() / DEFAULT_PARAMETER_FILE
    content = read_yaml(path)
    if not isinstance(content, dict):
        raise ParameterError(f'{path} must hold a mapping of parameter: value')
    try:
        return model_params_from_mapping(content)
    except ParameterError as exc:
        raise ParameterError(f'{path}: {exc}') from exc


def _stamp(t: float) -> dict[str, int]:
    ns = int(round(t * 1e9))
    sec, nanosec = divmod(ns, 1_000_000_000)
    return {'sec': sec, 'nanosec': nanosec}


def _color(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {'r': r, 'g': g, 'b': b, 'a': a}


@dataclass(frozen=True)
class _Output:
    """A publisher with its resolved topic, type name and CDR encoder."""

    publisher: Any
    topic: str
    type_name: str
    encode: Callable[[Any], bytes]


class _Window:
    """Counters of the current diagnostics window."""

    def __init__(self, wall: float, sim: float) -> None:
        self.wall0 = wall
        self.sim0 = sim
        self.ticks = 0
        self.step_s = 0.0
        self.step_max = 0.0
        self.publish_s = 0.0
        self.overruns = 0
        self.skipped = 0
        self.accepted = 0
        self.rejected = 0


class SimNode(Node):
    """The cone feeder simulator as a ROS 2 node; see the module documentation."""

    def __init__(self, **kwargs: Any) -> None:
        """Declare the parameters, build the engine and create every ROS handle."""
        super().__init__(kwargs.pop('node_name', NODE_NAME), **kwargs)
        try:
            self._setup()
        except BaseException:
            self.destroy_node()
            raise

    def _setup(self) -> None:
        self._codec = default_codec()
        self._hooks: list[MessageHook] = []
        self._topics: dict[str, TopicInfo] = {}
        file_param = self.declare_parameter(
            'parameter_file', '', parameter_specs()[0].descriptor()).value
        self._base_model = load_base_model(file_param)
        self._specs = {s.name: s for s in parameter_specs(self._base_model)}
        for spec in self._specs.values():
            if spec.name != 'parameter_file':
                self.declare_parameter(spec.name, spec.default, spec.descriptor())
        values = self._values()
        self._engine = FeederEngine(engine_config_from_values(values, self._base_model))
        self._frame = str(values['frame_id'])
        self._rtf = float(values['real_time_factor'])
        self._marker_rate = float(values['markers.rate'])
        self._paused = False
        self._last_markers_t = -math.inf
        self._total_exits = 0
        self._total_failures = 0
        self._refused = 0
        self._last_tick: TickResult | None = None
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._last_tick_wall: float | None = None
        self._window = _Window(time.perf_counter(), self._engine.t)
        self._timing = [0, 0.0, 0.0]  # ticks, step s, publish s since the start

        self._pub_particles = self._publisher(PoseArray, 'particles', STATE_QOS)
        self._pub_states = self._publisher(PointCloud2, 'particle_states', STATE_QOS)
        self._pub_exits = self._publisher(PointCloud2, 'exit_events', EVENTS_QOS)
        self._pub_channel = self._publisher(Float64MultiArray, 'channel_mass', LATCHED_QOS)
        self._pub_cone = self._publisher(JointState, 'cone_state', STATE_QOS)
        self._pub_markers = self._publisher(MarkerArray, 'markers', LATCHED_QOS)
        self._pub_diag = self._publisher(DiagnosticArray, '/diagnostics', STATE_QOS)
        self._pub_clock = (self._publisher(ClockMessage, '/clock', CLOCK_QOS)
                           if values['publish_clock'] else None)
        self._sub_cmd = self.create_subscription(
            Float64, 'rotation_cmd', self._on_rotation_cmd, COMMAND_QOS, raw=True)
        self._sub_spawn = self.create_subscription(
            PoseArray, 'spawn', self._on_spawn, COMMAND_QOS, raw=True)
        for sub, type_name in ((self._sub_cmd, 'std_msgs/msg/Float64'),
                               (self._sub_spawn, 'geometry_msgs/msg/PoseArray')):
            self._topics[sub.topic_name] = TopicInfo(sub.topic_name, type_name, 'in',
                                                     _recording_qos(COMMAND_QOS))
        self._srv_reset = self.create_service(Trigger, '~/reset', self._on_reset)
        self._srv_pause = self.create_service(SetBool, '~/pause', self._on_pause)
        self._srv_step = self.create_service(Trigger, '~/step', self._on_step)

        self._static_markers = self._build_static_markers()
        self._tick_timer = self.create_timer(self._tick_period(), self._on_timer,
                                             clock=self._steady,
                                             autostart=not values['start_paused'])
        self._paused = bool(values['start_paused'])
        self._diag_timer = self.create_timer(float(values['diagnostics.period']),
                                             self._publish_diagnostics, clock=self._steady)
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(
            f'simulating {self._engine.piece_count} pieces, dt = {self._engine.dt:g} s, '
            f'real_time_factor = {self._rtf:g}, feed {self._engine.feed.rate:g} pieces/s')

    # ------------------------------------------------------------------ plumbing

    def _publisher(self, msg_type: Any, topic: str, qos: QoSProfile) -> '_Output':
        pub = self.create_publisher(msg_type, topic, qos)
        type_name = msg_type.__module__.split('.')[0] + '/msg/' + msg_type.__name__
        self._topics[pub.topic_name] = TopicInfo(pub.topic_name, type_name, 'out',
                                                 _recording_qos(qos))
        return _Output(pub, pub.topic_name, type_name, self._codec.encoder(type_name))

    def _values(self) -> dict[str, Any]:
        # get_parameter_or: an empty list in a parameter file leaves an array NOT_SET
        return {name: self.get_parameter_or(name).value for name in self._specs}

    def _tick_period(self) -> float:
        return 0.0 if self._rtf == 0.0 else self._engine.dt / self._rtf

    def _publish(self, out: '_Output', message: dict[str, Any], stamp_ns: int) -> None:
        data = out.encode(message)
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
        return self._timing[0], self._timing[1], self._timing[2]

    @property
    def last_tick(self) -> TickResult | None:
        """Return the result of the last tick, if any."""
        return self._last_tick

    def _now_ns(self) -> int:
        return int(round(self._engine.t * 1e9))

    # ------------------------------------------------------------------ inputs

    def _on_rotation_cmd(self, data: bytes) -> None:
        if self._hooks:
            self._emit(MessageRecord('in', self._sub_cmd.topic_name, 'std_msgs/msg/Float64',
                                     bytes(data), self._now_ns(), time.time_ns()))
        try:
            value = self._codec.decode('std_msgs/msg/Float64', data, strict=False)['data']
            self._engine.command(value)
        except (CdrError, ConeFeederError) as exc:
            self._refused += 1
            self.get_logger().warning(f'rotation_cmd refused: {exc}', throttle_duration_sec=1.0)
            return
        limit = self._engine.drive.max_angular_velocity
        if abs(value) > limit:
            self.get_logger().warning(
                f'rotation_cmd {value:g} rad/s clamped to the limit {limit:g} rad/s',
                throttle_duration_sec=5.0)

    def _on_spawn(self, data: bytes) -> None:
        if self._hooks:
            self._emit(MessageRecord('in', self._sub_spawn.topic_name,
                                     'geometry_msgs/msg/PoseArray', bytes(data),
                                     self._now_ns(), time.time_ns()))
        try:
            msg = self._codec.decode('geometry_msgs/msg/PoseArray', data, strict=False)
        except CdrError as exc:
            self._refused += 1
            self.get_logger().warning(f'spawn refused: cannot decode the message: {exc}')
            return
        frame = msg['header']['frame_id']
        if frame not in ('', self._frame):
            self._refused += 1
            self.get_logger().warning(
                f'spawn refused: poses are in frame {frame!r}, expected {self._frame!r} '
                '(or an empty frame_id)')
            return
        model = self._engine.model
        valid = []
        problems = []
        for i, pose in enumerate(msg['poses']):
            p = pose['position']
            point = np.array([[p['x'], p['y'], p['z']]])
            try:
                if not np.all(np.isfinite(point)):
                    raise ConeFeederError(f'position {point[0].tolist()} is not finite')
                check_positions(model, point)
            except ConeFeederError as exc:
                problems.append(f'pose {i}: {str(exc).replace("position[0] ", "")}')
                continue
            valid.append(point[0])
        if problems:
            self._refused += len(problems)
            self.get_logger().warning(
                f'spawn: refused {len(problems)} of {len(msg["poses"])} poses: '
                + '; '.join(problems[:5]) + (' ...' if len(problems) > 5 else ''))
        if valid:
            positions = np.array(valid)
            try:
                self._engine.spawn(positions, velocities=np.zeros_like(positions))
            except ConeFeederError as exc:
                self._refused += len(valid)
                self.get_logger().warning(f'spawn refused: {exc}')

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        self._engine.reset()
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
            return f'paused at t = {self._engine.t:.6f} s'
        if not self._paused:
            return 'already running'
        self._paused = False
        self._last_tick_wall = None
        self._window = _Window(time.perf_counter(), self._engine.t)
        self._tick_timer.reset()
        return f'resumed at t = {self._engine.t:.6f} s'

    def step(self) -> TickResult:
        """Run one tick now and publish it (what ~/step does while paused)."""
        return self._run_tick()

    # ------------------------------------------------------------------ parameters

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        values = self._values()
        for param in parameters:
            if param.name in self._specs:
                values[param.name] = param.value
        try:
            drive_from_values(values)
            feed = feed_from_values(values)
            if feed.rho_max >= self._engine.model.r:
                raise ParameterError(
                    f'feed.rho_max = {feed.rho_max:g} m must be inside the cone (radius '
                    f'{self._engine.model.r:g} m)')
        except ConeFeederError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        names = {p.name for p in parameters}
        values = self._values()
        drive_keys = {'max_angular_velocity', 'max_angular_acceleration', 'cmd_timeout',
                      'open_loop_pattern'}
        drive = drive_from_values(values) if names & drive_keys else None
        feed = feed_from_values(values) if any(n.startswith('feed.') for n in names) else None
        if drive is not None or feed is not None:
            self._engine.reconfigure(drive=drive, feed=feed)
        if 'real_time_factor' in names:
            self._rtf = float(values['real_time_factor'])
            self._tick_timer.timer_period_ns = int(round(self._tick_period() * 1e9))
            self._last_tick_wall = None
            self._window = _Window(time.perf_counter(), self._engine.t)
        if 'markers.rate' in names:
            self._marker_rate = float(values['markers.rate'])
        if 'diagnostics.period' in names:
            self._diag_timer.timer_period_ns = int(round(values['diagnostics.period'] * 1e9))

    # ------------------------------------------------------------------ the tick

    def _on_timer(self) -> None:
        now = time.perf_counter()
        period = self._tick_period()
        if self._last_tick_wall is not None and period > 0.0:
            missed = int((now - self._last_tick_wall) / period + 0.5) - 1
            if missed > 0:
                self._window.skipped += missed
        self._last_tick_wall = now
        self._run_tick()
        if period > 0.0 and time.perf_counter() - now > period:
            self._window.overruns += 1

    def _run_tick(self) -> TickResult:
        start = time.perf_counter()
        result = self._engine.tick()
        stepped = time.perf_counter()
        self._publish_tick(result)
        done = time.perf_counter()
        window = self._window
        window.ticks += 1
        window.step_s += stepped - start
        window.step_max = max(window.step_max, stepped - start)
        window.publish_s += done - stepped
        self._timing[0] += 1
        self._timing[1] += stepped - start
        self._timing[2] += done - stepped
        window.accepted += result.stats.accepted
        window.rejected += result.stats.rejected
        self._last_tick = result
        self._total_exits += len(result.exits)
        self._total_failures += len(result.failures)
        for failure in result.failures:
            self.get_logger().warning(
                f'piece {failure.particle_id} removed at t = {failure.t:.6f} s: '
                f'{failure.reason} (at {failure.position})')
        if result.reset:
            self._last_markers_t = -math.inf
        return result

    def _publish_tick(self, res: TickResult) -> None:
        stamp = _stamp(res.t)
        stamp_ns = stamp['sec'] * 1_000_000_000 + stamp['nanosec']
        header = {'stamp': stamp, 'frame_id': self._frame}
        n = res.count
        if self._pub_clock is not None:
            self._publish(self._pub_clock, {'clock': stamp}, stamp_ns)
        poses = np.zeros((n, 7))
        poses[:, 0:3] = res.positions
        poses[:, 6] = 1.0
        self._publish(self._pub_particles, {'header': header, 'poses': poses}, stamp_ns)
        points = np.zeros(n, dtype=STATE_DTYPE)
        for i, name in enumerate(('x', 'y', 'z')):
            points[name] = res.positions[:, i]
            points['v' + name] = res.velocities[:, i]
        points['id'] = res.ids & 0xFFFFFFFF
        points['mass'] = res.masses
        self._publish(self._pub_states, self._cloud(header, points, STATE_DATATYPES), stamp_ns)
        if len(res.exits):
            ex = res.exits
            rows = np.zeros(len(ex), dtype=EXIT_DTYPE)
            for i, name in enumerate(('x', 'y', 'z')):
                rows[name] = ex.position[:, i]
                rows['v' + name] = ex.velocity[:, i]
            rows['exit_time'] = ex.t
            rows['angle'] = np.arctan2(ex.position[:, 1], ex.position[:, 0])
            rows['mass'] = ex.mass
            rows['id'] = ex.ids & 0xFFFFFFFF
            rows['channel'] = ex.channel
            self._publish(self._pub_exits, self._cloud(header, rows, EXIT_DATATYPES), stamp_ns)
        count = res.channel_mass.shape[0]
        self._publish(self._pub_channel, {
            'layout': {'dim': [{'label': 'channel', 'size': count, 'stride': count}],
                       'data_offset': 0},
            'data': res.channel_mass}, stamp_ns)
        self._publish(self._pub_cone, {
            'header': header, 'name': ['cone'], 'position': np.array([res.angle]),
            'velocity': np.array([res.omega]), 'effort': np.zeros(0)}, stamp_ns)
        if self._marker_rate > 0.0 and (
                res.t - self._last_markers_t >= 1.0 / self._marker_rate - 1e-9 * res.t
                or res.reset):
            self._last_markers_t = res.t
            self._publish(self._pub_markers, {'markers': self._static_markers
                                              + self._dynamic_markers(res, header)}, stamp_ns)

    @staticmethod
    def _cloud(header: dict[str, Any], points: np.ndarray, datatypes: list[int]
               ) -> dict[str, Any]:
        step = points.dtype.itemsize
        return {'header': header, 'height': 1, 'width': points.shape[0],
                'fields': point_fields(points.dtype, datatypes), 'is_bigendian': False,
                'point_step': step, 'row_step': step * points.shape[0], 'data': points,
                'is_dense': True}

    # ------------------------------------------------------------------ markers

    def _marker(self, ns: str, marker_id: int, marker_type: int, **fields: Any
                ) -> dict[str, Any]:
        marker = self._codec.default_message('visualization_msgs/msg/Marker')
        marker['header'] = {'stamp': {'sec': 0, 'nanosec': 0}, 'frame_id': self._frame}
        marker['ns'] = ns
        marker['id'] = marker_id
        marker['type'] = marker_type
        marker['pose']['orientation']['w'] = 1.0
        marker['scale'] = {'x': 1.0, 'y': 1.0, 'z': 1.0}
        marker['color'] = _color(1.0, 1.0, 1.0)
        marker.update(fields)
        return marker

    def _build_static_markers(self) -> list[dict[str, Any]]:
        """Return the cone surface, the channel sectors and their labels."""
        model = self._engine.model
        r, h = model.r, model.h
        segments = 96
        angles = np.linspace(0.0, 2.0 * math.pi, segments + 1)
        tri = np.zeros((segments * 3, 3))
        tri[0::3] = (0.0, 0.0, h)
        tri[1::3, 0] = r * np.cos(angles[:-1])
        tri[1::3, 1] = r * np.sin(angles[:-1])
        tri[2::3, 0] = r * np.cos(angles[1:])
        tri[2::3, 1] = r * np.sin(angles[1:])
        markers = [self._marker('cone', 0, 11, points=tri,  # TRIANGLE_LIST
                                color=_color(0.7, 0.72, 0.75, 0.8))]
        channels = model.channels
        ring = []
        colors = []
        labels = []
        sub = 8
        for channel in range(1, channels.count + 1):
            start, end = (math.radians(a) for a in channels.sector_edges(channel))
            edge = np.linspace(start, end, sub + 1)
            shade = (0.25, 0.55, 0.85, 0.9) if channel % 2 else (0.95, 0.75, 0.2, 0.9)
            for a0, a1 in zip(edge[:-1], edge[1:]):
                inner0 = (r * math.cos(a0), r * math.sin(a0), 0.0)
                inner1 = (r * math.cos(a1), r * math.sin(a1), 0.0)
                outer0 = (1.15 * r * math.cos(a0), 1.15 * r * math.sin(a0), 0.0)
                outer1 = (1.15 * r * math.cos(a1), 1.15 * r * math.sin(a1), 0.0)
                ring += [inner0, outer0, outer1, inner0, outer1, inner1]
                colors += [shade] * 6
            mid = 0.5 * (start + end)
            labels.append(self._marker(
                'channel_labels', channel, 9,  # TEXT_VIEW_FACING
                pose={'position': {'x': 1.25 * r * math.cos(mid), 'y': 1.25 * r * math.sin(mid),
                                   'z': 0.01},
                      'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}},
                scale={'x': 0.0, 'y': 0.0, 'z': 0.03}, text=str(channel)))
        markers.append(self._marker('channels', 0, 11, points=np.array(ring),
                                    colors=np.array(colors, dtype=np.float32)))
        return markers + labels

    def _dynamic_markers(self, res: TickResult, header: dict[str, Any]
                         ) -> list[dict[str, Any]]:
        """Return the pieces and a line that turns with the cone."""
        model = self._engine.model
        c, s = math.cos(res.angle), math.sin(res.angle)
        line = np.array([[0.0, 0.0, model.h + 0.002], [model.r * c, model.r * s, 0.002]])
        marker_line = self._marker('cone_angle', 0, 5, header=header,  # LINE_LIST
                                   points=line, scale={'x': 0.004, 'y': 0.0, 'z': 0.0},
                                   color=_color(0.1, 0.1, 0.1))
        size = 2.0 * model.product.s0
        if res.count:
            pieces = self._marker('pieces', 0, 7, header=header,  # SPHERE_LIST
                                  points=res.positions,
                                  scale={'x': size, 'y': size, 'z': size},
                                  color=_color(0.85, 0.25, 0.25))
        else:
            pieces = self._marker('pieces', 0, 7, header=header, action=2)  # DELETE
        return [marker_line, pieces]

    # ------------------------------------------------------------------ diagnostics

    def _publish_diagnostics(self) -> None:
        now = time.perf_counter()
        window = self._window
        wall = now - window.wall0
        sim = self._engine.t - window.sim0
        achieved = sim / wall if wall > 0 else 0.0
        ticks = max(window.ticks, 1)
        level = 0
        if self._paused:
            message = f'paused at t = {self._engine.t:.3f} s'
        elif self._rtf == 0.0:
            message = f'running as fast as possible: real-time factor {achieved:.2f}'
        elif window.ticks and achieved < 0.9 * self._rtf:
            level = 1
            message = (f'cannot keep up: real-time factor {achieved:.2f} < {self._rtf:g} '
                       f'(tick {1e3 * (window.step_s + window.publish_s) / ticks:.3g} ms, '
                       f'period {1e3 * self._tick_period():.3g} ms); simulation time runs '
                       'slower, ticks are not caught up')
        else:
            message = f'real-time factor {achieved:.2f} (target {self._rtf:g})'
        res = self._last_tick
        values = {
            'simulation time (s)': f'{self._engine.t:.6f}',
            'paused': str(self._paused),
            'real-time factor (achieved)': f'{achieved:.4f}',
            'real-time factor (target)': f'{self._rtf:g}',
            'update rate (Hz)': f'{1.0 / self._engine.dt:g}',
            'ticks in window': str(window.ticks),
            'step time mean (ms)': f'{1e3 * window.step_s / ticks:.3f}',
            'step time max (ms)': f'{1e3 * window.step_max:.3f}',
            'publish time mean (ms)': f'{1e3 * window.publish_s / ticks:.3f}',
            'overruns (ticks longer than the period)': str(window.overruns),
            'skipped periods': str(window.skipped),
            'pieces': str(self._engine.piece_count),
            'accepted steps': str(window.accepted),
            'rejected steps': str(window.rejected),
            'exits (total)': str(self._total_exits),
            'failures (total)': str(self._total_failures),
            'refused inputs (total)': str(self._refused),
            'cone omega (rad/s)': f'{self._engine.omega:.4f}',
            'drive mode': res.mode if res is not None else 'not started',
        }
        stamp = _stamp(self._engine.t)
        message_dict = {
            'header': {'stamp': stamp, 'frame_id': ''},
            'status': [{'level': level,
                        'name': f'{self.get_fully_qualified_name()}: simulation',
                        'message': message, 'hardware_id': 'cone_feeder',
                        'values': [{'key': k, 'value': v} for k, v in values.items()]}]}
        self._publish(self._pub_diag, message_dict, stamp['sec'] * 1_000_000_000
                      + stamp['nanosec'])
        if not self._paused:
            self._window = _Window(now, self._engine.t)


def main(args: list[str] | None = None) -> int:
    """Run the node until shut down; return the process exit status."""
    rclpy.init(args=args)
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
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == '__main__':
    sys.exit(main())
