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
The digital twin of a running feeder (issue 39, in progress): detections in, forecasts out.

Built so far, each with its checks (doc/twin.md): ``enkf`` (the ensemble Kalman filter's
analysis of an ensemble of states against observed positions, with the normalised innovation
squared), ``association`` (detections to the twin's pieces: a chi-square gate, then an
optimal assignment) and ``estimator`` (``Twin``: an ensemble of the physics core's states
following detections, births, deaths and exits, d and mu_C weighed per window) and
``forecast`` (each piece's channel probabilities and exit time, each channel's mass over
the horizons, from the members), ``spec``, ``streams`` and ``run`` (the headless
``cone-feeder-sim twin`` over recorded CSV or MCAP streams), ``frames`` (the inputs'
checks), ``live`` (``Follower``: the twin frame by frame, as ``twin_node`` runs it; late
frames analysed again from a snapshot), ``messages`` (its estimates as standard
messages), ``particles`` (the parameters' particle step once per window) and ``camera`` (a
camera standing in for the real one: noise, misses, false detections, swapped track ids;
for ``camera_node``). No ROS here.
"""
