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

"""The fit's Dask test needs the optional extra (cone_feeder_sim[sweep]); the rest not."""

import importlib.util

#: Not collected where Dask is not installed; the README's set-up installs it.
collect_ignore = [] if importlib.util.find_spec('distributed') else ['test_fit_dask.py']
