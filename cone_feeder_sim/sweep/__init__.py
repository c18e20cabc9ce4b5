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
Parameter sweeps: one scenario run many times with other parameters and seeds, on Dask.

``spec`` (the sweep file, expanded into jobs), ``job`` (one job, run as ``cone-feeder-sim
run`` runs a scenario), ``store`` (the output directory: job files, resume, summary),
``cluster`` (Dask: a LocalCluster or a scheduler, per-worker kernel loading), ``figure``
(the summary figure) and ``run`` (all of it). Dask is an optional dependency
(``pip install cone_feeder_sim[sweep]``); only ``cluster`` and ``run`` import it.
"""
