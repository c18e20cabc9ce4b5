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
The ROS 2 nodes (sim_node, replay_node, camera_node, twin_node and the controllers).

Thin adapters: ROS parameters, topics and services become calls of the feeder engine and
the run recorder, and their outputs become messages. ``parameters``, ``qos`` and ``resim``
hold what the nodes share.

A node's process runs BLAS (numpy's and scipy's linear algebra) on one thread
(:data:`BLAS_THREADS`): set before numpy loads, which a node's module does after this
package. Its matrices are small (a twin's analysis solves systems of twice its detections),
and its cores are the simulation's: beside sim_node on two cores, OpenBLAS's threads waited
for cores the kernels held, and twin_node at 60 pieces took 1.25 and 1.15 s of stream per
second of computing, p95 latency 159 and 246 ms, against 1.85 and 1.82, 69 and 73 ms on one
thread (benchmarks/twin_node_rtf.py, doc/twin.md). A variable set in the environment wins.
A process that loaded numpy before importing this package keeps its BLAS threads; one that
imports it first (a notebook using ``ros.parameters``) gets one, and so do its children.
"""

import os

#: The environment variables that size BLAS's threads (OpenBLAS, MKL, BLIS): one.
BLAS_THREADS = {'OPENBLAS_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1', 'BLIS_NUM_THREADS': '1'}

for _name, _count in BLAS_THREADS.items():
    os.environ.setdefault(_name, _count)
