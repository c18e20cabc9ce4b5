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
The product feed: Poisson arrivals of pieces over an annulus, with product variation.

The one place where feed pieces are drawn: :class:`~.engine.FeederEngine` (``sim_node``, the
RL environment) calls :func:`draw_feed` once per tick, the headless runner once per output
interval. Pieces arrive as a Poisson process of ``rate`` pieces/s, at positions uniform per
area over the annulus ``rho_min <= rho <= rho_max``, ``drop_height`` above the cone surface
(centre of the piece, measured vertically), at rest in the world frame. Masses are
log-normal with the default product's mass as mean and relative standard deviation
``mass_rel_std``; the damping d is drawn uniformly from ``d_values`` (empty: the default
product's d). Every draw comes from the ``numpy.random.Generator`` the caller passes, so a
feed is reproduced from its seed.

A feed in a file (a scenario's ``feed:``, ``config/rl.yaml``) has the node's keys
(:data:`FEED_KEYS`, ``feed.<key>`` there); keys left out take :class:`FeedParams`' defaults.
"""

from dataclasses import dataclass, fields
import math
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..physics.params import (
    check_integer, check_number, check_section, Limit, ModelParams, PRODUCT_LIMITS,
    ProductParams)

__all__ = ['FEED_KEYS', 'FEED_LIMITS', 'FeedDrop', 'FeedParams', 'check_feed_fits',
           'draw_feed', 'feed_from_mapping']

#: Allowed ranges of the feed's settings (also the node's ``feed.*`` parameters).
FEED_LIMITS: dict[str, Limit] = {
    'feed_rate': Limit(0.0, 1.0e4, 'pieces/s'),
    'feed_rho': Limit(0.0, 20.0, 'm'),
    'feed_drop_height': Limit(0.0, 10.0, 'm'),
    'feed_mass_rel_std': Limit(0.0, 1.0, ''),
    'max_pieces': Limit(1, 10 ** 6, ''),
    'seed': Limit(0, 2 ** 63 - 1, ''),
}


@dataclass(frozen=True)
class FeedParams:
    """
    The product feed: Poisson arrivals over an annulus, with product variation.

    rate (pieces/s, 0 = off); rho_min, rho_max (m) the drop annulus; drop_height (m) of the
    piece's centre above the cone surface; mass_rel_std relative standard deviation of the
    (log-normal) mass; d_values (N*s/m) damping values drawn uniformly (empty: default);
    max_pieces: the feed pauses while this many pieces are on the cone.
    """

    rate: float = 0.0
    rho_min: float = 0.03
    rho_max: float = 0.15
    drop_height: float = 0.05
    mass_rel_std: float = 0.0
    d_values: tuple[float, ...] = ()
    max_pieces: int = 2000

    def __post_init__(self) -> None:
        """Validate every field; errors name the field."""
        object.__setattr__(self, 'rate', check_number('feed.rate', self.rate,
                                                      FEED_LIMITS['feed_rate']))
        for key in ('rho_min', 'rho_max'):
            object.__setattr__(self, key, check_number(f'feed.{key}', getattr(self, key),
                                                       FEED_LIMITS['feed_rho']))
        if not self.rho_min <= self.rho_max:
            raise ParameterError(f'feed.rho_min = {self.rho_min:g} m must not exceed '
                                 f'feed.rho_max = {self.rho_max:g} m')
        object.__setattr__(self, 'drop_height', check_number(
            'feed.drop_height', self.drop_height, FEED_LIMITS['feed_drop_height']))
        object.__setattr__(self, 'mass_rel_std', check_number(
            'feed.mass_rel_std', self.mass_rel_std, FEED_LIMITS['feed_mass_rel_std']))
        if isinstance(self.d_values, (str, bytes)):
            raise ParameterError(f'feed.d_values must be a list of numbers, got '
                                 f'{self.d_values!r}')
        object.__setattr__(self, 'd_values', tuple(
            check_number(f'feed.d_values[{i}]', v, PRODUCT_LIMITS['d'])
            for i, v in enumerate(self.d_values)))
        object.__setattr__(self, 'max_pieces', check_integer(
            'feed.max_pieces', self.max_pieces, FEED_LIMITS['max_pieces']))


def check_feed_fits(model: ModelParams, feed: FeedParams) -> None:
    """Refuse a feed annulus that reaches the cone edge."""
    if feed.rho_max >= model.r:
        raise ParameterError(
            f'feed.rho_max = {feed.rho_max:g} m must be inside the cone (radius r = '
            f'{model.r:g} m)')


#: The keys of a feed mapping (a scenario's ``feed:``), as the node's ``feed.<key>``.
FEED_KEYS = tuple(f.name for f in fields(FeedParams)) + ('seed',)


def feed_from_mapping(content: Any, where: str = 'feed') -> tuple[FeedParams, int]:
    """
    Return the feed and its seed from a mapping with the keys of :data:`FEED_KEYS`.

    Unknown keys and invalid values raise ParameterError naming the key (``where.key``).
    """
    check_section(where, content, FEED_KEYS)
    values = {k: v for k, v in content.items() if k != 'seed'}
    if 'd_values' in values:
        d_values = values['d_values']
        if not isinstance(d_values, (list, tuple)):
            raise ParameterError(f'{where}.d_values must be a list of numbers, got '
                                 f'{d_values!r}')
        values['d_values'] = tuple(d_values)
    try:
        feed = FeedParams(**values)
    except ParameterError as exc:
        raise ParameterError(str(exc).replace('feed.', f'{where}.', 1)) from None
    seed = check_integer(f'{where}.seed', content.get('seed', 0), FEED_LIMITS['seed'])
    return feed, seed


@dataclass(frozen=True, eq=False)
class FeedDrop:
    """Pieces the feed drops: world positions (M, 3) (m), masses (M,) (kg), products (M)."""

    positions: np.ndarray
    masses: np.ndarray
    products: tuple[ProductParams, ...]


def draw_feed(rng: np.random.Generator, feed: FeedParams, model: ModelParams, interval: float,
              room: int) -> FeedDrop | None:
    """
    Draw the pieces that arrive in ``interval`` seconds; None when none arrive.

    room: how many more pieces the cone may hold (feed.max_pieces less the pieces on it);
    the arrivals beyond it are dropped (the count is drawn whatever room is).
    """
    if feed.rate <= 0.0:
        return None
    count = int(rng.poisson(feed.rate * interval))
    count = min(count, max(0, room))
    if count == 0:
        return None
    rho = np.sqrt(rng.uniform(feed.rho_min ** 2, feed.rho_max ** 2, count))
    theta = rng.uniform(0.0, 2.0 * math.pi, count)
    positions = np.empty((count, 3))
    positions[:, 0] = rho * np.cos(theta)
    positions[:, 1] = rho * np.sin(theta)
    positions[:, 2] = model.h * (1.0 - rho / model.r) + feed.drop_height
    default = model.product
    sigma = math.sqrt(math.log1p(feed.mass_rel_std ** 2))
    masses = default.m * np.exp(sigma * rng.standard_normal(count) - 0.5 * sigma * sigma)
    masses = np.clip(masses, 1.0e-6, PRODUCT_LIMITS['m'].hi)
    if feed.d_values:
        d = np.asarray(feed.d_values)[rng.integers(0, len(feed.d_values), count)]
    else:
        d = np.full(count, default.d)
    products = tuple(default.with_overrides({'m': float(mi), 'd': float(di)})
                     for mi, di in zip(masses, d))
    return FeedDrop(positions, masses, products)
