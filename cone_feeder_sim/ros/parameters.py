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
The parameters of ``sim_node``: one table of names, defaults, descriptions and ranges.

Ranges come from the tables that validate the values (:data:`~cone_feeder_sim.physics.params.
PRODUCT_LIMITS`, ``MODEL_LIMITS``, ``SOLVER_LIMITS``, :data:`~cone_feeder_sim.feeder.engine.
ENGINE_LIMITS`; the node's own settings in :data:`NODE_LIMITS`), so a parameter file and a
ROS parameter accept the same values. The builders turn parameter values into the engine's
configuration; they need no ROS.
"""

from dataclasses import dataclass, fields, replace
import difflib
from functools import cache
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..errors import ConeFeederError, ParameterError
from ..feeder.engine import (
    DriveParams, ENGINE_LIMITS, EngineConfig, FeederEngine, FeedParams, pattern_from_flat,
    PieceSpec)
from ..formats.mcap_writer import COMPRESSIONS
from ..formats.parameter_file import config_dir, load_weigher_params
from ..formats.runlog import DEFAULT_RECORD_PATH, model_parameter_values
from ..formats.scenario_file import load_scenario
from ..physics.params import (
    CHANNEL_KEYS, COUPLING_CHOICES, INTERACTION_KEYS, INTERACTION_LIMITS, InteractionParams,
    Limit, MODEL_KEYS, MODEL_LIMITS, model_params_from_mapping, ModelParams, PRODUCT_LIMITS,
    SOLVER_LIMITS, SolverParams)
from ..weigher.machine import WEIGHER_LIMITS, WeigherParams

__all__ = [
    'DRIVE_PARAMETERS',
    'LIVE_PARAMETERS',
    'NODE_LIMITS',
    'ParamSpec',
    'parameter_problem',
    'RUN_PARAMETERS',
    'declare',
    'declare_recorded',
    'warn_unknown_parameters',
    'drive_from_values',
    'engine_config_from_values',
    'feed_from_values',
    'parameter_specs',
    'table_i_pieces',
]

DEFAULT_FRAME = 'feeder'
#: The scenario whose pieces are the node's default initial pieces (Table I of the paper).
TABLE_I_SCENARIO = 'paper_table1.yaml'

#: Ranges of the node's own settings (the engine's and the model's are in their tables).
NODE_LIMITS: dict[str, Limit] = {
    'update_rate': Limit(1.0, 1000.0, 'Hz'),
    'real_time_factor': Limit(0.0, 100.0, ''),
    'catch_up': Limit(0.0, 60.0, 's'),
    'markers.rate': Limit(0.0, 1000.0, '1/s'),
    'diagnostics.period': Limit(0.05, 3600.0, 's'),
    'threads': Limit(0, 1024, ''),
    'record_max_file_size': Limit(0, 2 ** 62, 'bytes'),
    'record_max_file_duration': Limit(0.0, 1.0e9, 's'),
    'record_min_free_space': Limit(0, 2 ** 62, 'bytes'),
}


@cache
def table_i_pieces() -> tuple[tuple[tuple[float, float, float], float], ...]:
    """
    Return the five pieces of Table I: start position (m) and damping d (N*s/m) each.

    Read from the package's ``paper_table1.yaml`` scenario, the one place they are written.
    """
    scenario = load_scenario(config_dir() / TABLE_I_SCENARIO)
    return tuple((spec.position, spec.product.d) for spec in scenario.particles)


#: Default open-loop pattern: 2 s clockwise, 2 s counter-clockwise at 8 rad/s.
DEFAULT_PATTERN = (2.0, -8.0, 2.0, 8.0)
#: Default damping values of fed pieces: those of Table II.
DEFAULT_D_VALUES = (30.0, 135.0, 225.0, 750.0)


#: Parameters that re-simulation does not take from the recording (wall-clock pacing,
#: start state of the timer, the outputs of this run).
LIVE_PARAMETERS = ('real_time_factor', 'catch_up', 'start_paused', 'diagnostics.period',
                   'record_path', 'record_compression', 'record_max_file_size',
                   'record_max_file_duration', 'record_min_free_space', 'replay_commands',
                   'threads')
#: Run-time parameters that change what the simulation does (refused while re-simulating).
#: The parameters of the cone drive (an engine input when they change).
DRIVE_PARAMETERS = ('max_angular_velocity', 'max_angular_acceleration', 'cmd_timeout',
                    'open_loop_pattern')
RUN_PARAMETERS = DRIVE_PARAMETERS + ('markers.rate',)


def changes_the_run(name: str) -> bool:
    """Tell whether a parameter changes what the simulation does (drive, feed, markers)."""
    return name in RUN_PARAMETERS or name.startswith('feed.')


def parameter_problem(values: dict[str, Any], parameters: list[Parameter],
                      engine: FeederEngine, resimulating: bool) -> str | None:
    """
    Return why a run-time change of ``parameters`` is refused, or None to accept it.

    values: the node's parameter values before the change. While re-simulating, what
    changes the run comes from the recording. A change of the drive or the feed must make a
    valid drive, and the engine must take it (:meth:`FeederEngine.check_reconfigure`: a
    feed that fits the cone, room in its input queue).
    """
    run = [p.name for p in parameters if changes_the_run(p.name)]
    if not run:
        return None
    if resimulating:
        return (f're-simulating a recording: {", ".join(run)} come from the recording until '
                'its end')
    values = dict(values)
    for param in parameters:
        if param.name in values:
            values[param.name] = param.value
    try:
        drive_from_values(values)
        engine.check_reconfigure(feed=feed_from_values(values))
    except ConeFeederError as exc:
        return str(exc)
    return None


@dataclass(frozen=True)
class ParamSpec:
    """
    One ROS parameter of a node.

    default: the default value (its type is the parameter's type) or, for an array that is
    empty by default, a Parameter.Type; limit: the allowed range of a number, taken from the
    table that validates the value (so files and ROS parameters accept the same values);
    dynamic: may change at run time; constraints: what the range cannot say.
    """

    name: str
    default: Any
    description: str
    dynamic: bool = False
    limit: Limit | None = None
    constraints: str = ''

    def type_(self) -> Parameter.Type:
        """Return the parameter type."""
        if isinstance(self.default, Parameter.Type):
            return self.default
        return Parameter.Type.from_parameter_value(self.default)

    def descriptor(self) -> ParameterDescriptor:
        """
        Return the ROS descriptor: type, description, range, read-only flag.

        A ROS range is closed; an open bound of the limit (e.g. ``> 0``) is given in
        ``additional_constraints`` and refused by the validation the value goes through.
        """
        constraints = [self.constraints] if self.constraints else []
        if self.limit is not None:
            constraints.insert(0, f'allowed {self.limit.describe()}')
        desc = ParameterDescriptor(
            name=self.name, type=self.type_().value, description=self.description,
            additional_constraints='; '.join(constraints), read_only=not self.dynamic)
        if self.limit is not None:
            if self.type_() == Parameter.Type.INTEGER:
                desc.integer_range = [IntegerRange(
                    from_value=int(self.limit.lo), to_value=int(self.limit.hi), step=0)]
            elif self.type_() == Parameter.Type.DOUBLE:
                desc.floating_point_range = [FloatingPointRange(
                    from_value=float(self.limit.lo), to_value=float(self.limit.hi), step=0.0)]
        return desc


def warn_unknown_parameters(node: Node) -> list[str]:
    """
    Warn about overrides (parameter files, ``-p``) that name no parameter of the node.

    A misspelt name would otherwise be silently ignored; like Nav2 and Gazebo users expect,
    the node starts and each unknown name is logged with the closest valid name. Returns the
    warnings.
    """
    declared = sorted(node._parameters)  # rclpy has no public list of either
    warnings = []
    for name in sorted(set(node._parameter_overrides) - set(declared)):
        close = difflib.get_close_matches(name, declared, n=1, cutoff=0.6)
        hint = f'; did you mean {close[0]!r}?' if close else ''
        warnings.append(f'parameter {name!r} is not a parameter of {node.get_name()} and is '
                        f'ignored{hint}')
    for text in warnings:
        node.get_logger().warning(text)
    return warnings


def declare(node: Node, spec: ParamSpec, value: Any = None, **kwargs: Any) -> Parameter:
    """Declare ``spec`` on ``node`` (with ``value`` instead of the default, if given)."""
    return node.declare_parameter(spec.name, spec.default if value is None else value,
                                  spec.descriptor(), **kwargs)


def declare_recorded(node: Node, spec: ParamSpec, recorded: tuple[bool, Any]) -> Parameter:
    """
    Declare ``spec`` while re-simulating: the recorded value over a given one.

    recorded: (found, value) of the parameter in the recording. Parameters that do not
    change the simulation (LIVE_PARAMETERS) and those not recorded are declared as usual.
    """
    found, value = recorded
    if not found or spec.name in LIVE_PARAMETERS:
        return declare(node, spec)
    if value is None or value == []:
        value = spec.type_()  # an empty array: declared without a value, as '[]' does
    return declare(node, spec, value, ignore_override=True)


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
    'young_modulus': "default product: Young's modulus (Pa), contact between pieces only",
    'poisson_ratio': "default product: Poisson's ratio, contact between pieces only",
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

#: The ``interactions.*`` parameters after ``enabled`` (doc/model.md, "Pieces that touch").
_INTERACTION_DESCRIPTIONS = {
    'restitution': 'pair law: restitution coefficient e, separation over closing speed of '
                   'a collision (0 < e <= 1; sets the normal and tangential damping)',
    'friction': 'pair law: Coulomb friction coefficient between two pieces',
    'pull_off': 'pair law: force (N) that parts two just-touching default pieces (sizes the '
                'cohesion)',
    'coupling': "how pieces that touch are integrated: 'island' (one linearly implicit "
                'step per contact island, its fast pieces and colliding pairs refined '
                "alone), 'exact' (the pieces and their contact histories as one system: "
                "the reference, whatever the cost) or 'multirate' (each piece on its own "
                'steps, pair forces extrapolated over error-controlled intervals)',
    'coupling_tolerance': 'multirate coupling only: largest position error (m) one coupling '
                          'interval may give a piece',
}

_SOLVER_DESCRIPTIONS = {
    'rtol': 'integrator relative tolerance',
    'atol_position': 'integrator absolute tolerance of positions (m)',
    'atol_velocity': 'integrator absolute tolerance of velocities (m/s)',
    'atol_force': 'integrator absolute tolerance of the filter force (N)',
    'h_init': 'first trial step of the integrator (s)',
    'h_min': 'smallest step before a piece is declared failed (s)',
    'h_max': 'longest integrator step (s)',
    'max_steps': 'steps allowed per piece and tick',
}


def model_param_specs(base: ModelParams) -> list[ParamSpec]:
    """Return the read-only ``model.<key>`` parameters with defaults from ``base``."""
    specs = []
    defaults = model_parameter_values(base)
    for key in list(PRODUCT_LIMITS) + list(MODEL_KEYS) + list(CHANNEL_KEYS):
        specs.append(ParamSpec(f'model.{key}', defaults[f'model.{key}'],
                               _MODEL_DESCRIPTIONS[key],
                               limit=PRODUCT_LIMITS.get(key) or MODEL_LIMITS.get(key)))
    return specs


def parameter_specs(base: ModelParams | None = None) -> list[ParamSpec]:
    """Return every parameter of the node (model defaults from ``base``)."""
    solver = SolverParams()
    table_i = table_i_pieces()
    specs = [
        ParamSpec('parameter_file', '', 'model parameter file (YAML, keys of '
                  'config/table2.yaml); empty: the table2.yaml of the package. model.<key> '
                  'parameters override single values of it'),
        ParamSpec('update_rate', 50.0, 'ticks per second of simulated time: the simulation '
                  'step is dt = 1 / update_rate (Hz)', limit=NODE_LIMITS['update_rate']),
        ParamSpec('real_time_factor', 1.0, 'simulated seconds per wall-clock second; 0 runs '
                  'as fast as possible', dynamic=True, limit=NODE_LIMITS['real_time_factor']),
        ParamSpec('catch_up', 0.5, 'wall-clock seconds the simulation may fall behind (a '
                  'long tick) and catch up by running the next ticks sooner; beyond it the lag '
                  'is given up and simulated time runs slower (s, 0 = never catch up)',
                  dynamic=True, limit=NODE_LIMITS['catch_up']),
        ParamSpec('publish_clock', False, 'publish the simulation time on /clock'),
        ParamSpec('start_paused', False, 'start paused (resume with ~/pause false, or '
                  '~/step): lets subscribers connect before anything happens'),
        ParamSpec('frame_id', DEFAULT_FRAME, 'frame of all published data and of spawn '
                  'poses (fixed, z up, origin at the centre of the cone base)'),
        ParamSpec('max_angular_velocity', 10.47, 'limit of the cone angular velocity; '
                  'commands beyond it are clamped (rad/s)', dynamic=True,
                  limit=ENGINE_LIMITS['max_angular_velocity']),
        ParamSpec('max_angular_acceleration', 20.0, 'limit of the cone angular acceleration '
                  '(rad/s^2)', dynamic=True, limit=ENGINE_LIMITS['max_angular_acceleration']),
        ParamSpec('cmd_timeout', 0.5, 'seconds of simulated time without a rotation_cmd after '
                  'which the cone ramps to rest; 0 holds the last command', dynamic=True,
                  limit=ENGINE_LIMITS['cmd_timeout']),
        ParamSpec('open_loop_pattern', list(DEFAULT_PATTERN),
                  'target until the first rotation_cmd: flat pairs [duration s, omega rad/s, '
                  '...], looped; empty: rest', dynamic=True,
                  constraints='even length, durations > 0, |omega| <= 100'),
        ParamSpec('initial_pieces.positions', [v for p, _ in table_i for v in p],
                  'pieces placed at the start and after each reset: flat [x, y, z, ...] (m, '
                  'world frame)', constraints='length a multiple of 3, inside the cone'),
        ParamSpec('initial_pieces.d', [d for _, d in table_i],
                  'damping d of each initial piece (N*s/m); empty: the default product',
                  constraints='empty or one value per piece'),
        ParamSpec('feed.rate', 2.0, 'product feed: mean pieces per second (Poisson '
                  'arrivals); 0 = off', dynamic=True, limit=ENGINE_LIMITS['feed_rate']),
        ParamSpec('feed.rho_min', 0.03, 'product feed: inner radius of the drop annulus (m)',
                  dynamic=True, limit=ENGINE_LIMITS['feed_rho']),
        ParamSpec('feed.rho_max', 0.15, 'product feed: outer radius of the drop annulus (m)',
                  dynamic=True, limit=ENGINE_LIMITS['feed_rho'],
                  constraints='>= feed.rho_min, < r'),
        ParamSpec('feed.drop_height', 0.05, 'product feed: height of the centre of a new '
                  'piece above the cone surface (m)', dynamic=True,
                  limit=ENGINE_LIMITS['feed_drop_height']),
        ParamSpec('feed.mass_rel_std', 0.2, 'product feed: relative standard deviation of the '
                  'log-normal mass (mean: model.m)', dynamic=True,
                  limit=ENGINE_LIMITS['feed_mass_rel_std']),
        ParamSpec('feed.d_values', list(DEFAULT_D_VALUES), 'product feed: damping values '
                  'drawn uniformly (N*s/m); empty: model.d', dynamic=True),
        ParamSpec('feed.max_pieces', 2000, 'product feed pauses while this many pieces are on '
                  'the cone', dynamic=True, limit=ENGINE_LIMITS['max_pieces']),
        ParamSpec('feed.seed', 0, 'seed of the random generator of the feed',
                  limit=ENGINE_LIMITS['seed']),
        ParamSpec('threads', 0, 'threads that integrate the pieces (0 = every core); the '
                  'results are the same for any count', limit=NODE_LIMITS['threads']),
        ParamSpec('spawn.max_height', 1.0, 'highest start of a spawned piece (m, z of its centre '
                  'above the cone base); spawn poses above it are refused',
                  limit=ENGINE_LIMITS['spawn_max_height']),
        ParamSpec('markers.rate', 10.0, 'marker messages per second of simulated time (at most '
                  'one per tick); 0 = none', dynamic=True, limit=NODE_LIMITS['markers.rate']),
        ParamSpec('diagnostics.period', 1.0, 'wall-clock seconds between /diagnostics messages',
                  dynamic=True, limit=NODE_LIMITS['diagnostics.period']),
        ParamSpec('record_path', DEFAULT_RECORD_PATH, 'MCAP file of this run (every published '
                  'topic, every received command, the applied inputs, the parameters); '
                  'strftime fields are filled in (an existing file gets _2, _3, ...); '
                  'missing directories are created; empty: no recording'),
        ParamSpec('record_compression', 'zstd', 'chunk compression of the recording: zstd '
                  '(smallest files), lz4 (least CPU) or none',
                  constraints=' | '.join(COMPRESSIONS)),
        ParamSpec('record_max_file_size', 100_000_000, 'the recording goes on in a new file '
                  '(<stem>_2.mcap, ...) before one passes this many bytes; 0 = no limit',
                  limit=NODE_LIMITS['record_max_file_size']),
        ParamSpec('record_max_file_duration', 360.0, 'the recording goes on in a new file '
                  'when one holds this many seconds of simulated time (the first 360 s of the '
                  'default scene are about 100 MB); 0 = no limit',
                  limit=NODE_LIMITS['record_max_file_duration']),
        ParamSpec('record_min_free_space', 500_000_000, 'the recording stops, its file '
                  'closed, when less than this many bytes are free on its device; the '
                  'simulation goes on; 0 = no guard',
                  limit=NODE_LIMITS['record_min_free_space']),
        ParamSpec('replay_commands', '', 'MCAP file of an earlier sim_node run to re-simulate: '
                  'its parameters, initial state and applied inputs (at the same ticks) drive '
                  'this run, live inputs are refused until its last tick, then the node '
                  'pauses; empty: a live run'),
    ]
    specs += [ParamSpec(f'solver.{f.name}', getattr(solver, f.name),
                        _SOLVER_DESCRIPTIONS[f.name], limit=SOLVER_LIMITS[f.name])
              for f in fields(SolverParams)]
    model = base if base is not None else ModelParams()
    specs += [
        ParamSpec('interactions.enabled', True, 'contact between pieces: they push, rub and '
                  "stick to each other (on in the node; off is the paper's model, where "
                  "pieces pass through each other); overrides the parameter file's value"),
    ]
    specs += [ParamSpec(f'interactions.{key}', getattr(model.interactions, key),
                        f'{description}; default from the parameter file',
                        limit=INTERACTION_LIMITS.get(key),
                        constraints=(f'one of {", ".join(COUPLING_CHOICES)}'
                                     if key == 'coupling' else ''))
              for key, description in _INTERACTION_DESCRIPTIONS.items()]
    specs += model_param_specs(model)
    specs += weigher_param_specs()
    return specs


def weigher_param_specs() -> list[ParamSpec]:
    """Return the ``weigher.*`` parameters: on/off and one per key of config/weigher.yaml."""
    machine = load_weigher_params()
    specs = [ParamSpec('weigher.enabled', True, 'run the multihead weigher below the cone: '
                       'dosing channels, pool and weigh hoppers, packs (hopper_weights, '
                       'pack_events, /diagnostics)')]
    for key, limit in WEIGHER_LIMITS.items():
        specs.append(ParamSpec(f'weigher.{key}', getattr(machine, key),
                               f'{WEIGHER_DESCRIPTIONS[key]}; default from config/weigher.yaml',
                               limit=limit))
    return specs


#: What each weigher key means (units in the range), for the parameter descriptions.
WEIGHER_DESCRIPTIONS = {
    'target': 'pack target weight (kg)',
    'max_over': 'most a pack may exceed the target (kg); 0 = no limit',
    'tolerable_negative_error': 'tolerable negative error below the target (kg)',
    'min_heads': 'fewest hoppers in a pack',
    'max_heads': 'most hoppers in a pack',
    'cycles_per_minute': 'machine cycles per minute',
    'transport_time': 'dosing channel transport time, rim to pool hopper (s)',
    'gate_time': 'pool hopper to weigh hopper (s)',
    'settle_time': 'weigh hopper settling before weighing (s)',
    'load_cell_noise': 'standard deviation of one weighing (kg)',
    'seed': 'seed of the load-cell noise',
}


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


def model_and_solver_from_values(values: dict[str, Any],
                                 base: ModelParams) -> tuple[ModelParams, SolverParams]:
    """Build the model (``model.*`` over base, ``interactions.*``) and ``solver.*``."""
    model = replace(model_from_values(values, base), interactions=InteractionParams(
        **{key: values[f'interactions.{key}'] for key in INTERACTION_KEYS}))
    solver = SolverParams(**{name[len('solver.'):]: value for name, value in values.items()
                             if name.startswith('solver.')})
    return model, solver


def engine_config_from_values(values: dict[str, Any], base: ModelParams) -> EngineConfig:
    """Build and validate the whole engine configuration from parameter values."""
    model, solver = model_and_solver_from_values(values, base)
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
    weigher = None
    if values['weigher.enabled']:
        weigher = WeigherParams(**{key: values[f'weigher.{key}'] for key in WEIGHER_LIMITS})
    return EngineConfig(model=model, solver=solver, dt=1.0 / values['update_rate'],
                        drive=drive_from_values(values), feed=feed_from_values(values),
                        initial_pieces=pieces, seed=values['feed.seed'],
                        spawn_max_height=values['spawn.max_height'], weigher=weigher)
