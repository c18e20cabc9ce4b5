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
Parameter identification: fit a scenario's free parameters to tracked pieces.

``tracks`` (tracks of pieces: a CSV of particle, t, x, y[, z], or a recording), ``exits``
(observed exits and the simulated ones), ``spec`` (the fit file, validated), ``problem`` (the
residuals of a parameter vector: a simulation of the scenario compared with the data),
``jacobian`` (forward differences, columns side by side), ``shooting`` (multiple shooting)
and ``solve`` (global search, bounded least squares with standard errors, correlations and
identifiability warnings). No ROS; the headless simulator only.
"""
