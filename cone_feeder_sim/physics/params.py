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
Validated, immutable parameters of the model (Table II of the paper) and of the solver.

Values are SI (m, s, kg, N, rad) apart from the cone tilt and the channel boundary, which
are given in degrees at the configuration edge. Every value is checked once, here, when a
parameter object is built from a mapping; the physics core trusts what it receives.

Product parameters (mass, damping, friction, contact) belong to each piece, so one run can
mix products: :class:`ProductParams` holds one product, and the simulator stores one row of
:func:`product_row` per particle.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
import math
from typing import Any

import numpy as np

from ..errors import ParameterError


@dataclass(frozen=True)
class Limit:
    """Allowed range of one numeric parameter; bounds are inclusive unless marked open."""

    lo: float
    hi: float
    unit: str
    lo_open: bool = False
    hi_open: bool = False

    def describe(self) -> str:
        """Return the range in interval notation with its unit, e.g. '(0, 10] kg'."""
        left = '(' if self.lo_open else '['
        right = ')' if self.hi_open else ']'
        unit = f' {self.unit}' if self.unit else ''
        return f'{left}{self.lo:g}, {self.hi:g}{right}{unit}'

    def contains(self, value: float) -> bool:
        """Tell whether a finite value lies in the range."""
        above = value > self.lo if self.lo_open else value >= self.lo
        below = value < self.hi if self.hi_open else value <= self.hi
        return above and below


def _in_range(key: str, number: float | int, limit: Limit) -> Any:
    """Return number if the limit contains it; otherwise raise naming key and the range."""
    if not limit.contains(number):
        shown = f'{number:g}' if isinstance(number, float) else str(number)
        raise ParameterError(
            f'parameter {key!r} = {shown} is out of range: allowed {limit.describe()}')
    return number


def check_number(key: str, value: Any, limit: Limit) -> float:
    """Return value as float after checking type, finiteness and range; name key on failure."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(
            f'parameter {key!r} must be a number in {limit.describe()}, '
            f'got {type(value).__name__} {value!r}')
    number = float(value)
    if not math.isfinite(number):
        raise ParameterError(
            f'parameter {key!r} must be finite, in {limit.describe()}, got {number!r}')
    return _in_range(key, number, limit)


def check_integer(key: str, value: Any, limit: Limit) -> int:
    """
    Return value as int after checking it is an integer in range; name key on failure.

    Integers are compared exactly (never through float), so a seed of 2**53 + 1 stays
    itself.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(
            f'parameter {key!r} must be an integer in {limit.describe()}, '
            f'got {type(value).__name__} {value!r}')
    return _in_range(key, int(value), limit)


def check_choice(key: str, value: Any, choices: tuple[str, ...]) -> str:
    """Return value after checking it is one of the allowed strings."""
    if not isinstance(value, str) or value not in choices:
        raise ParameterError(
            f'parameter {key!r} must be one of {", ".join(choices)}; got {value!r}')
    return value


#: Ranges of the per-piece product parameters (keys named after the paper's symbols).
PRODUCT_LIMITS: dict[str, Limit] = {
    'm': Limit(0.0, 100.0, 'kg', lo_open=True),
    'd': Limit(0.0, 1.0e5, 'N*s/m'),
    'mu_C': Limit(0.0, 10.0, ''),
    'mu_S': Limit(0.0, 10.0, ''),
    'v_C': Limit(0.0, 10.0, 'm/s', lo_open=True),
    'v_S': Limit(0.0, 10.0, 'm/s', lo_open=True),
    'T_F': Limit(0.0, 10.0, 's', lo_open=True),
    'qdot_F': Limit(0.0, 10.0, 'm/s', lo_open=True),
    's0': Limit(0.0, 0.5, 'm', lo_open=True),
    's_c_ratio': Limit(0.0, 1.0, '', lo_open=True, hi_open=True),
    'r_a': Limit(0.0, 1.0, '', lo_open=True, hi_open=True),
    'r_d': Limit(0.0, 1.0e6, 's/m', lo_open=True),
    'r_f': Limit(0.0, 1.0e6, 'N', lo_open=True),
    'young_modulus': Limit(0.0, 1.0e12, 'Pa', lo_open=True),
    'poisson_ratio': Limit(0.0, 0.5, ''),
}

#: Ranges of the machine and model parameters shared by all pieces.
MODEL_LIMITS: dict[str, Limit] = {
    'g': Limit(0.0, 100.0, 'm/s^2'),
    'cone_diameter': Limit(0.01, 20.0, 'm'),  # a cone of 1 cm or more: r = d / 2 never 0
    'cone_tilt': Limit(0.0, 60.0, 'deg'),
    'epsilon': Limit(0.0, 1.0, 'm/s', lo_open=True),
    'tip_epsilon': Limit(0.0, 0.1, 'm', lo_open=True),
    'channel_count': Limit(1, 360, ''),
    'channel_boundary': Limit(-360.0, 360.0, 'deg'),
}

#: Ranges of the integrator settings (SolverParams).
SOLVER_LIMITS: dict[str, Limit] = {
    'rtol': Limit(0.0, 1.0, '', lo_open=True),
    'atol_position': Limit(0.0, 1.0, 'm', lo_open=True),
    'atol_velocity': Limit(0.0, 10.0, 'm/s', lo_open=True),
    'atol_force': Limit(0.0, 1.0e3, 'N', lo_open=True),
    'h_init': Limit(0.0, 1.0, 's', lo_open=True),
    'h_min': Limit(0.0, 1.0e-3, 's', lo_open=True),
    'h_max': Limit(0.0, 10.0, 's', lo_open=True),
    'max_steps': Limit(1, 10 ** 12, ''),
}

#: Ranges of the piece-piece contact settings (InteractionParams).
INTERACTION_LIMITS: dict[str, Limit] = {
    'restitution': Limit(0.0, 1.0, '', lo_open=True),
    'friction': Limit(0.0, 10.0, ''),
    'pull_off': Limit(0.0, 1.0e3, 'N'),
    'coupling_tolerance': Limit(0.0, 1.0e-2, 'm', lo_open=True),
}

#: How pieces that touch are integrated (InteractionParams.coupling).
COUPLING_CHOICES = ('island', 'multirate', 'exact')

NORMAL_FORCE_CHOICES = ('newton', 'literal')
FRICTION_DIRECTION_CHOICES = ('full', 'tangential')
CHANNEL_NUMBERING_CHOICES = ('clockwise', 'counter_clockwise')


@dataclass(frozen=True)
class ProductParams:
    """
    Parameters of one product (one kind of piece).

    Attributes (units): m (kg) mass; d (N*s/m) viscous damping; mu_C sliding and mu_S
    adhesive friction coefficients; v_C (m/s) Coulomb zero-crossing slope; v_S (m/s) velocity
    of maximum adhesion, the paper's v-hat_S; T_F (s) friction filter time constant; qdot_F
    (m/s) filter adaptation velocity of eq. 14; s0 (m) outer radius; s_c_ratio = s_c / s0;
    r_a activation at the compression radius; r_d (s/m) dissipation coefficient;
    r_f (N) maximum constraint force.
    """

    m: float = 0.125
    d: float = 225.0
    mu_C: float = 0.85
    mu_S: float = 0.99
    v_C: float = 5.0e-5
    v_S: float = 0.1
    T_F: float = 3.0e-4
    qdot_F: float = 1.0e-4
    s0: float = 0.025
    s_c_ratio: float = 0.5
    r_a: float = 0.99
    r_d: float = 120.0
    r_f: float = 120.0
    young_modulus: float = 4.0e4
    poisson_ratio: float = 0.45

    def __post_init__(self) -> None:
        """Validate every field against :data:`PRODUCT_LIMITS`."""
        for key, limit in PRODUCT_LIMITS.items():
            object.__setattr__(self, key, check_number(key, getattr(self, key), limit))

    @property
    def s_c(self) -> float:
        """Return the compression radius in m, the paper's s_c."""
        return self.s_c_ratio * self.s0

    @property
    def r_t(self) -> float:
        """Return the transition coefficient in 1/m, the paper's r_t of eq. 32."""
        return 2.0 * math.atanh(self.r_a) / (self.s0 - self.s_c)

    @property
    def r_c(self) -> float:
        """Return the constraint offset in m, the paper's r_c of eq. 33."""
        return 0.5 * (self.s0 + self.s_c)

    def with_overrides(self, overrides: Mapping[str, Any]) -> 'ProductParams':
        """Return a copy with some fields replaced; unknown keys are refused by name."""
        unknown = sorted(set(overrides) - set(PRODUCT_LIMITS))
        if unknown:
            raise ParameterError(
                f'unknown product parameter(s) {", ".join(map(repr, unknown))}; '
                f'known: {", ".join(PRODUCT_LIMITS)}')
        return replace(self, **dict(overrides))


# Column layout of one row of the per-particle product array used by the kernel.
P_M, P_D, P_MU_C, P_MU_S, P_V_C, P_V_S, P_T_F, P_QDOT_F = range(8)
P_S0, P_SC_RATIO, P_R_A, P_R_D, P_R_F, P_E, P_NU = range(8, 15)
P_R_T, P_R_C, P_C_S, P_Y_COMPLIANCE, P_G_COMPLIANCE = range(15, 20)
PRODUCT_WIDTH = 20


def product_row(product: ProductParams) -> np.ndarray:
    """
    Return the kernel's row for one product, shape (PRODUCT_WIDTH,), float64.

    Columns 0..14 are the fields of :class:`ProductParams` in declaration order; then r_t
    (1/m, eq. 32), r_c (m, eq. 33), c_S = mu_S - mu_C*tanh(v_S/v_C), the coefficient of
    the normal force in F_S^Delta (eq. 10), and the piece's share of a pair's normal and
    shear compliance (1/Pa): (1 - nu^2)/E and 2 (2 - nu)(1 + nu)/E, which add up to a
    pair's 1/Y* and 1/G* (doc/model.md, "Contact between pieces").
    """
    base = [float(getattr(product, f.name)) for f in fields(product)]
    c_s = product.mu_S - product.mu_C * math.tanh(product.v_S / product.v_C)
    e, nu = product.young_modulus, product.poisson_ratio
    return np.array(base + [product.r_t, product.r_c, c_s, (1.0 - nu * nu) / e,
                            2.0 * (2.0 - nu) * (1.0 + nu) / e], dtype=np.float64)


@dataclass(frozen=True)
class ChannelLayout:
    """
    Dosing channels around the cone edge.

    `count` equal sectors; channel 1 starts at `boundary` (deg) and channels are numbered
    in the direction `numbering` seen from above. With the default (14, 108 deg, clockwise)
    channel 1 covers [82.29 deg, 108 deg), which reproduces Table I.
    """

    count: int = 14
    boundary: float = 108.0
    numbering: str = 'clockwise'

    def __post_init__(self) -> None:
        """Validate the layout."""
        count = self.count
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)):
            raise ParameterError(
                f"parameter 'channel_count' must be an integer in "
                f"{MODEL_LIMITS['channel_count'].describe()}, got {count!r}")
        check_number('channel_count', count, MODEL_LIMITS['channel_count'])
        object.__setattr__(self, 'count', int(count))
        object.__setattr__(self, 'boundary', check_number(
            'channel_boundary', self.boundary, MODEL_LIMITS['channel_boundary']))
        check_choice('channel_numbering', self.numbering, CHANNEL_NUMBERING_CHOICES)

    @property
    def width(self) -> float:
        """Angular width of one channel (deg)."""
        return 360.0 / self.count

    def channel_of(self, angle_deg: Any) -> np.ndarray:
        """
        Return the 1-based channel of exit angles.

        angle_deg: array-like (any shape) of angles atan2(y, x) in degrees (any branch).
        Returns an int64 array of the same shape, values in 1..count.
        """
        angle = np.asarray(angle_deg, dtype=np.float64)
        offset = np.mod(angle - self.boundary, 360.0)
        sector = np.floor(offset / self.width).astype(np.int64)
        sector = np.clip(sector, 0, self.count - 1)
        if self.numbering == 'clockwise':
            return self.count - sector
        return sector + 1

    def sector_edges(self, channel: int) -> tuple[float, float]:
        """Return (start, end) angles in degrees, counter-clockwise order, of a channel."""
        if not 1 <= channel <= self.count:
            raise ParameterError(f'channel {channel} is not in 1..{self.count}')
        if self.numbering == 'clockwise':
            start = self.boundary - channel * self.width
        else:
            start = self.boundary + (channel - 1) * self.width
        return start, start + self.width


@dataclass(frozen=True)
class InteractionParams:
    """
    Contact between pieces: the soft-sphere law of DEM (doc/model.md, "Contact between pieces").

    enabled: pieces push, rub and stick to each other (off: each piece moves alone, the
    paper's model). The pair law (its parameters apart from each product's young_modulus
    and poisson_ratio): restitution e, the separation speed over the closing speed of a
    collision (sets the normal and tangential damping); friction, the Coulomb coefficient
    between two pieces; pull_off (N), the largest pull between two default pieces (sizes
    the cohesion). The defaults e = 0.3, friction 0.5 and pull-off 0.05 N are assumptions:
    no measurement of raw meat on raw meat is known to us (config/table2.yaml says so).
    coupling: 'island' (default: one linearly implicit step per contact island, its fast
    pieces and colliding pairs refined alone, :mod:`island`), 'exact' (the pieces that
    touch and their contact histories integrated as one system, :mod:`exact`: the
    reference, whatever the cost) or 'multirate' (each piece keeps its own steps, the pair
    forces couple the pieces over intervals chosen by the contact time and error control,
    :mod:`coupling`). coupling_tolerance (m): multirate only, the largest position error
    one coupling interval may give a piece.
    """

    enabled: bool = False
    restitution: float = 0.3
    friction: float = 0.5
    pull_off: float = 0.05
    coupling: str = 'island'
    coupling_tolerance: float = 1.0e-8

    def __post_init__(self) -> None:
        """Validate the fields."""
        if not isinstance(self.enabled, (bool, np.bool_)):
            raise ParameterError(f"parameter 'interactions.enabled' must be true or false, "
                                 f'got {self.enabled!r}')
        object.__setattr__(self, 'enabled', bool(self.enabled))
        for key in ('restitution', 'friction', 'pull_off', 'coupling_tolerance'):
            object.__setattr__(self, key, check_number(
                f'interactions.{key}', getattr(self, key), INTERACTION_LIMITS[key]))
        check_choice('interactions.coupling', self.coupling, COUPLING_CHOICES)

    @property
    def beta(self) -> float:
        """Return the damping ratio of the law, ln e / sqrt(ln^2 e + pi^2) (0 for e = 1)."""
        log_e = math.log(self.restitution)
        return log_e / math.sqrt(log_e * log_e + math.pi * math.pi)


# Layout of the global (machine and model) array used by the kernel.
G_R, G_H, G_K, G_G, G_EPS, G_TIP_EPS, G_LITERAL, G_TANGENTIAL = range(8)
GLOBAL_WIDTH = 8


@dataclass(frozen=True)
class ModelParams:
    """
    Machine geometry, model constants and model options, plus the default product.

    g (m/s^2); cone_diameter (m); cone_tilt (deg); epsilon (m/s) of eq. 4; tip_epsilon (m)
    regularises rho near the cone tip, rho = sqrt(x^2 + y^2 + tip_epsilon^2);
    normal_force: 'newton' (N = R_a*F_c in friction, default) or 'literal' (N/r_f);
    friction_direction: 'full' (3-D v_dif, default) or 'tangential' (normal part removed);
    interactions: contact between pieces (off by default: the paper's model).
    """

    product: ProductParams = ProductParams()
    g: float = 9.81
    cone_diameter: float = 0.45
    cone_tilt: float = 7.5
    epsilon: float = 1.0e-7
    tip_epsilon: float = 1.0e-4
    normal_force: str = 'newton'
    friction_direction: str = 'full'
    channels: ChannelLayout = ChannelLayout()
    interactions: InteractionParams = InteractionParams()

    def __post_init__(self) -> None:
        """Validate every field."""
        for key in ('g', 'cone_diameter', 'cone_tilt', 'epsilon', 'tip_epsilon'):
            object.__setattr__(self, key, check_number(key, getattr(self, key),
                                                       MODEL_LIMITS[key]))
        check_choice('normal_force', self.normal_force, NORMAL_FORCE_CHOICES)
        check_choice('friction_direction', self.friction_direction,
                     FRICTION_DIRECTION_CHOICES)

    @property
    def r(self) -> float:
        """Return the cone radius in m."""
        return 0.5 * self.cone_diameter

    @property
    def h(self) -> float:
        """Cone height h = r*tan(tilt) (m)."""
        return self.r * math.tan(math.radians(self.cone_tilt))

    def global_row(self) -> np.ndarray:
        """
        Return the kernel's global array, shape (GLOBAL_WIDTH,), float64, read-only.

        Read-only wherever it is made: numba compiles (and caches) a kernel per kind of
        array, so a writable row passed anywhere would compile the kernels a second time.
        """
        row = np.zeros(GLOBAL_WIDTH, dtype=np.float64)
        row[G_R] = self.r
        row[G_H] = self.h
        row[G_K] = self.h / self.r
        row[G_G] = self.g
        row[G_EPS] = self.epsilon
        row[G_TIP_EPS] = self.tip_epsilon
        row[G_LITERAL] = 1.0 if self.normal_force == 'literal' else 0.0
        row[G_TANGENTIAL] = 1.0 if self.friction_direction == 'tangential' else 0.0
        row.setflags(write=False)
        return row


#: Keys of the ``interactions`` mapping of parameter files and scenarios.
INTERACTION_KEYS = ('enabled', 'restitution', 'friction', 'pull_off', 'coupling',
                    'coupling_tolerance')


def check_section(section: str, mapping: Any, keys: Sequence[str]) -> Mapping[str, Any]:
    """
    Return ``mapping`` after checking it is a mapping of some of ``keys``.

    Raises ParameterError naming the section and the unknown keys (the one check of every
    section of a file: interactions, a scenario's feed, the RL environment's sections).
    """
    if not isinstance(mapping, Mapping):
        raise ParameterError(f'{section} must be a mapping with keys {", ".join(keys)}, got '
                             f'{mapping!r}')
    unknown = sorted(str(k) for k in set(mapping) - set(keys))
    if unknown:
        raise ParameterError(f'unknown {section} key(s) {", ".join(map(repr, unknown))}; '
                             f'known: {", ".join(keys)}')
    return mapping


def interaction_params_from_mapping(mapping: Any,
                                    base: InteractionParams | None = None) -> InteractionParams:
    """Build validated contact settings from an ``interactions`` mapping over ``base``."""
    base = base if base is not None else InteractionParams()
    return replace(base, **dict(check_section('interactions', mapping, INTERACTION_KEYS)))


MODEL_KEYS = ('g', 'cone_diameter', 'cone_tilt', 'epsilon', 'tip_epsilon', 'normal_force',
              'friction_direction')
CHANNEL_KEYS = {'channel_count': 'count', 'channel_boundary': 'boundary',
                'channel_numbering': 'numbering'}


def model_params_from_mapping(mapping: Mapping[str, Any],
                              base: ModelParams | None = None) -> ModelParams:
    """
    Build validated :class:`ModelParams` from a flat mapping of parameter-file keys.

    Keys are those of the parameter file (product keys, model keys, channel keys and the
    ``interactions`` mapping); keys
    missing from the mapping keep their value in `base` (Table II by default). Unknown keys
    and invalid values raise :class:`ParameterError` naming the key.
    """
    base = base if base is not None else ModelParams()
    if not isinstance(mapping, Mapping):
        raise ParameterError(f'parameters must be a mapping of key: value, got {mapping!r}')
    known = set(PRODUCT_LIMITS) | set(MODEL_KEYS) | set(CHANNEL_KEYS) | {'interactions'}
    unknown = sorted(str(k) for k in set(mapping) - known)
    if unknown:
        raise ParameterError(
            f'unknown parameter(s) {", ".join(map(repr, unknown))}; known: '
            f'{", ".join(sorted(known))}')
    product = base.product.with_overrides(
        {k: v for k, v in mapping.items() if k in PRODUCT_LIMITS})
    channels = replace(base.channels, **{CHANNEL_KEYS[k]: v for k, v in mapping.items()
                                         if k in CHANNEL_KEYS})
    model = {k: v for k, v in mapping.items() if k in MODEL_KEYS}
    interactions = (interaction_params_from_mapping(mapping['interactions'], base.interactions)
                    if 'interactions' in mapping else base.interactions)
    return replace(base, product=product, channels=channels, interactions=interactions,
                   **model)


@dataclass(frozen=True)
class SolverParams:
    """
    Tolerances and limits of the adaptive Rosenbrock integrator.

    rtol: relative tolerance; atol_position (m), atol_velocity (m/s), atol_force (N):
    absolute tolerances of the three blocks of the state; h_init (s) first trial step, and
    the largest step tried right after a jump of the cone's angular acceleration;
    h_min (s) smallest step before a particle is declared failed; h_max (s) longest step
    (a stick-slip transition starting inside a longer step can escape the error estimate);
    max_steps: accepted plus rejected steps allowed per particle and call.
    """

    rtol: float = 1.0e-5
    atol_position: float = 1.0e-6
    atol_velocity: float = 1.0e-5
    atol_force: float = 1.0e-4
    h_init: float = 1.0e-5
    h_min: float = 1.0e-12
    h_max: float = 0.01
    max_steps: int = 1_000_000

    def __post_init__(self) -> None:
        """Validate every field."""
        for key, limit in SOLVER_LIMITS.items():
            if key == 'max_steps':
                object.__setattr__(self, key, check_integer(key, self.max_steps, limit))
            else:
                object.__setattr__(self, key, check_number(key, getattr(self, key), limit))

    def atol_row(self) -> np.ndarray:
        """Return the absolute tolerance per state component, shape (9,)."""
        return np.repeat([self.atol_position, self.atol_velocity, self.atol_force], 3)


def solver_params_from_mapping(mapping: Mapping[str, Any] | None) -> SolverParams:
    """Build validated solver settings; unknown keys are refused by name."""
    mapping = dict(mapping or {})
    known = set(SolverParams.__dataclass_fields__)
    unknown = sorted(set(mapping) - known)
    if unknown:
        raise ParameterError(f'unknown solver setting(s) {", ".join(map(repr, unknown))}; '
                             f'known: {", ".join(sorted(known))}')
    return SolverParams(**mapping)
