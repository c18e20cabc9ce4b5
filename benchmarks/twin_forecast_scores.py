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
Study: the twin's forecasts against what the plant then does, and against five baselines.

The plant is the physics core with a feed (a piece every 0.2 s at rest on the annulus
0.05-0.15 m; the default product, or with --truth D MU_C its d and mu_C, the twin's prior
and the open loop's staying the default's) on a cone that speeds up to 8 rad/s and reverses
every 2 s; the camera sees it at 30 frames/s with 2 mm of noise and misses 5 % of the
pieces in each frame. The twin (16 members, the file's prior) follows it, and from 2 s on
forecasts every 0.25 s under the commanded rotation (a controller knows its command).
Scores:

- per piece, at a lead L of 0.25, 0.5, 1 and 2 s before its exit: how often the twin's most
  likely channel is the one it fell into, against an open-loop forecast (the model run from
  the piece's first detection, at rest there, under the same rotation) and a
  constant-velocity extrapolation of its last two detections to the rim;
- per forecast, the mass each channel gets over the next 1 and 2 s: the mean absolute error
  summed over the channels (kg), against the open-loop and constant-velocity forecasts and
  persistence (the last window's masses), climatology (each channel's mean rate over the
  run) and the empty forecast (none).

The twin's d and mu_C at the end (mean +- spread over its values) are printed too.
With --exits the twin also takes the plant's exits as a channel's sensors would report them
(each at the end of the frame's step in which it happened), and the count of them it
explained is printed; with --weighed too each comes with the piece's mass (a load cell's
step: the twin's mean piece mass, the mass of its pieces without a camera's, is
printed). --plant-mass gives the plant's pieces another mass than the prior's (0.125 kg)::

    .venv/bin/python benchmarks/twin_forecast_scores.py [--seconds 12] [--members 16] [--seed 1]
        [--truth 315 0.78] [--particles 32] [--smoother-pieces 6] [--exits [--weighed]]
        [--plant-mass 0.2] [--loosen 10]
"""

import argparse
from dataclasses import replace
import math
import time

from calibration import calibration_line
from cone_feeder_sim.physics.params import ModelParams
from cone_feeder_sim.physics.rotation import RotationProfile
from cone_feeder_sim.physics.simulation import (
    add_particles, advance, resting_height, SimParams, SimState, warm_up, world_from_cone)
from cone_feeder_sim.twin.estimator import Twin, TwinSettings
from cone_feeder_sim.twin.forecast import forecast
import numpy as np

LEADS = (0.25, 0.5, 1.0, 2.0)
WINDOWS = (1.0, 2.0)
EVERY = 0.25  # s between forecasts
FPS = 30


def reversing(seconds: float) -> RotationProfile:
    """Return the cone: up to 8 rad/s in 0.5 s, reversing every 2 s."""
    table = [[0.0, 0.0], [0.5, 8.0]]
    for k in range(int(seconds / 2.0) + 1):
        sign = 1.0 if k % 2 == 0 else -1.0
        table += [[2.0 * k + 1.5, sign * 8.0], [2.0 * k + 2.0, -sign * 8.0]]
    return RotationProfile.from_table(table)


def simulate_plant(params: SimParams, profile: RotationProfile, seconds: float) -> dict:
    """Run the plant with its feed; return its frames, exits and first detections."""
    model = params.model
    feed, noise = np.random.default_rng(3), np.random.default_rng(0)
    plant = SimState()
    frames, exits, first = [], [], {}
    for k in range(1, int(round(FPS * seconds)) + 1):
        t = k / FPS
        result = advance(plant, params, profile, t)
        plant = result.state
        exits += list(zip(result.exits.ids.tolist(), result.exits.t.tolist(),
                          result.exits.channel.tolist(), result.exits.mass.tolist()))
        if k % 6 == 0:
            r, a = math.sqrt(feed.uniform(0.05 ** 2, 0.15 ** 2)), feed.uniform(0, 2 * math.pi)
            x, y = r * math.cos(a), r * math.sin(a)
            plant, _ = add_particles(plant, params, np.array(
                [[x, y, resting_height(model, model.product, x, y)]]),
                omega=profile.omega(t))
        truth, _, _ = world_from_cone(plant.y, plant.angle, profile.omega(t))
        seen = noise.uniform(size=plant.count) > 0.05
        xy = truth[:, :2] + noise.normal(0.0, 0.002, (plant.count, 2))
        for i, point in zip(plant.ids[seen].tolist(), xy[seen]):
            first.setdefault(i, (t, point))
        frames.append((t, plant.ids.copy(), truth[:, :2].copy(), plant.ids[seen], xy[seen]))
    return {'frames': frames, 'exits': exits, 'first': first}


def open_loop(params: SimParams, profile: RotationProfile, first: dict,
              seconds: float) -> dict:
    """Return per piece (exit time, channel) of the model run from its first detection."""
    model = params.model
    out = {}
    for i, (t0, (x, y)) in first.items():
        state, _ = add_particles(SimState(t=t0), params, np.array(
            [[x, y, resting_height(model, model.product, x, y)]]), omega=profile.omega(t0))
        result = advance(state, params, profile, seconds + 2.0)
        out[i] = ((float(result.exits.t[0]), int(result.exits.channel[0]))
                  if len(result.exits) else (math.inf, 0))
    return out


def straight_line(model: ModelParams, now: float, track: list) -> tuple[float, int]:
    """Return (exit time, channel) of the line through the last two detections to the rim."""
    if len(track) < 2:
        return math.inf, 0
    (t0, p0), (t1, p1) = track[-2], track[-1]
    v = (p1 - p0) / (t1 - t0)
    a, b, c = v @ v, 2.0 * (p1 @ v), p1 @ p1 - model.r ** 2
    if a <= 0.0 or b * b - 4 * a * c < 0.0:
        return math.inf, 0
    s = (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)
    if s <= 0.0:
        return math.inf, 0
    crossing = p1 + v * s
    angle = math.degrees(math.atan2(crossing[1], crossing[0])) % 360.0
    return now + s, int(model.channels.channel_of(np.array([angle]))[0])


def main() -> None:
    """Print the calibration and the scores."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--seconds', type=float, default=12.0)
    parser.add_argument('--members', type=int, default=16)
    parser.add_argument('--seed', type=int, default=1, help="the twin's seed")
    parser.add_argument('--particles', type=int, default=TwinSettings.particles)
    parser.add_argument('--smoother-pieces', type=int, default=TwinSettings.smoother_pieces)
    parser.add_argument('--loosen', type=float, default=TwinSettings.loosen,
                        help="the members' solver tolerances times this")
    parser.add_argument('--exits', action='store_true',
                        help="the twin takes the plant's exits as a channel's sensors report "
                             'them (measured exits)')
    parser.add_argument('--dark', type=float, nargs=2, metavar=('START', 'END'),
                        help='the camera is off from START to END s: the twin moves on by the '
                             'model alone (open loop; with --exits, taking the measured '
                             'exits), and the scores are also given over these forecasts')
    parser.add_argument('--truth', type=float, nargs=2, metavar=('D', 'MU_C'),
                        help="the plant's d and mu_C (default: the prior's)")
    parser.add_argument('--plant-mass', type=float, metavar='KG',
                        help="the plant's pieces' mass (default: the prior's, 0.125 kg)")
    parser.add_argument('--weighed', action='store_true',
                        help="with --exits: each exit comes with the piece's mass, as a "
                             "load cell's step would")
    args = parser.parse_args()
    print(calibration_line(), flush=True)
    warm_up()
    model = ModelParams()
    params = SimParams(model=model)  # the prior: the twin's and the open loop's
    d, mu_c = (model.product.d, model.product.mu_C) if args.truth is None else args.truth
    truth = SimParams(model=replace(model, product=replace(
        model.product, d=d, mu_C=mu_c,
        m=model.product.m if args.plant_mass is None else args.plant_mass)))
    print(f'plant d = {d:g}, mu_C = {mu_c:g}, m = {truth.model.product.m:g} kg; '
          f'prior d = {model.product.d:g}, mu_C = {model.product.mu_C:g}, '
          f'm = {model.product.m:g} kg', flush=True)
    profile = reversing(args.seconds + 3.0)
    start = time.perf_counter()
    plant = simulate_plant(truth, profile, args.seconds)
    exits = plant['exits']
    exit_of = {i: (t, c) for i, t, c, _ in exits}
    closed = open_loop(params, profile, plant['first'], args.seconds)
    channels = model.channels.count
    twin = Twin(params, TwinSettings(members=args.members, sigma=0.002, seed=args.seed,
                                     particles=args.particles,
                                     smoother_pieces=args.smoother_pieces,
                                     loosen=args.loosen))
    tracks: dict[int, list] = {}
    picks: dict[float, dict] = {}  # forecast time: plant id -> (twin, line) channels
    masses: dict[float, dict] = {}  # forecast time: method -> (W, C) kg
    due = 2.0
    fed = 0  # the plant's exits given to the twin (with --exits)
    explained = taken_dark = 0
    for t, ids, truth, seen_ids, xy in plant['frames']:
        twin.cone_speed(t, profile.omega(t))
        if args.exits:  # those measured up to the frame (an exit of the frame's step: its end)
            new = [(te, c, m) for _, te, c, m in exits[fed:] if te <= t]
            fed += len(new)
            for te, c, m in new:
                twin.measured_exit(te, c, m if args.weighed else math.nan)
        if args.dark and args.dark[0] < t <= args.dark[1]:
            twin.predict(t)
            if args.exits:
                taken_dark += len(twin.open_loop_exits())
        else:
            explained += twin.update(t, xy).explained
        for i, point in zip(seen_ids.tolist(), xy):
            tracks.setdefault(i, []).append((t, point))
        if t + 1e-9 < due or t > args.seconds - max(WINDOWS):
            continue
        due += EVERY
        result = forecast(twin, LEADS, rotation=profile)
        best, _ = result.most_likely()
        twin_ids, mean, _ = twin.pieces()
        row = {int(i): k for k, i in enumerate(result.ids)}
        chosen: dict[int, tuple[int, int]] = {}
        line_mass = np.zeros((len(WINDOWS), channels))
        open_mass = np.zeros((len(WINDOWS), channels))
        for i, position in zip(ids.tolist(), truth):
            line = straight_line(model, t, [p for p in tracks.get(i, []) if p[0] <= t])
            distance = np.hypot(*(mean - position).T) if len(mean) else np.array([np.inf])
            k = int(np.argmin(distance))
            own = int(best[row[int(twin_ids[k])]]) if distance[k] < 0.01 else -1
            chosen[i] = (own, line[1])
            when, channel = closed.get(i, (math.inf, 0))
            for w, window in enumerate(WINDOWS):
                if channel and t < when <= t + window:
                    open_mass[w, channel - 1] += model.product.m
                if line[1] and line[0] <= t + window:
                    line_mass[w, line[1] - 1] += model.product.m
        picks[t] = chosen
        masses[t] = {'twin': result.mass[[LEADS.index(w) for w in WINDOWS]],
                     'open loop': open_mass, 'constant velocity': line_mass}
    wall = time.perf_counter() - start
    print(f'{len(exits)} exits, {len(picks)} forecasts, {wall:.1f} s wall', flush=True)
    print("the twin's parameters at the end: " + ', '.join(
        f'{key} {mean:.4g} +- {spread:.2g}' for key, (mean, spread) in twin.parameters().items()),
        flush=True)
    if args.exits:
        print(f'measured exits: {fed} given, {explained} explained in frames, twin piece '
              f'mass {twin.piece_mass:.4f} kg, '
              f'{taken_dark} took a piece in the dark', flush=True)
    for lead in LEADS:
        cases, right = 0, {'twin': 0, 'open loop': 0, 'constant velocity': 0}
        for i, (te, channel) in exit_of.items():
            times = [tf for tf in picks if abs(tf - (te - lead)) <= EVERY / 2 + 1e-9
                     and i in picks[tf]]
            if not times:
                continue
            tf = times[0]
            cases += 1
            own, line = picks[tf][i]
            right['twin'] += own == channel
            right['constant velocity'] += line == channel
            right['open loop'] += closed.get(i, (0, 0))[1] == channel
        print(f'lead {lead:g} s: {cases} exits; right channel: ' + ', '.join(
            f'{key} {count}' for key, count in right.items()), flush=True)
    total = np.zeros(channels)
    for _, _, c, m in exits:
        total[c - 1] += m
    duration = args.seconds
    for w, window in enumerate(WINDOWS):
        errors: dict[str, list[float]] = {}
        dark: dict[str, list[float]] = {}
        for tf, predicted in masses.items():
            actual = np.zeros(channels)
            last = np.zeros(channels)
            for _, te, c, m in exits:
                if tf < te <= tf + window:
                    actual[c - 1] += m
                if tf - window < te <= tf:
                    last[c - 1] += m
            candidates = {'twin': predicted['twin'][w], 'open loop': predicted['open loop'][w],
                          'constant velocity': predicted['constant velocity'][w],
                          'persistence': last, 'climatology': total / duration * window,
                          'empty': np.zeros(channels)}
            in_dark = bool(args.dark) and args.dark[0] < tf <= args.dark[1]
            for key, value in candidates.items():
                errors.setdefault(key, []).append(float(np.abs(value - actual).sum()))
                if in_dark:
                    dark.setdefault(key, []).append(errors[key][-1])
        print(f'channel mass over {window:g} s, mean absolute error summed over channels '
              f'(kg): ' + ', '.join(f'{key} {np.mean(v):.3f}' for key, v in errors.items()),
              flush=True)
        if dark:
            print(f'  the {len(dark["twin"])} forecasts in the dark: ' + ', '.join(
                f'{key} {np.mean(v):.3f}' for key, v in dark.items()), flush=True)
    print(calibration_line(), flush=True)


if __name__ == '__main__':
    main()
