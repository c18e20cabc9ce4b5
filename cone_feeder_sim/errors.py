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

"""The package's exception hierarchy: one root, one class per concern."""


class ConeFeederError(Exception):
    """Root of every error raised on purpose by cone_feeder_sim."""


class ParameterError(ConeFeederError, ValueError):
    """A model, product or solver parameter is missing, of the wrong type or out of range."""


class ScenarioError(ConeFeederError, ValueError):
    """A scenario file or a particle specification is malformed."""


class InputError(ConeFeederError, ValueError):
    """An input to the running simulation (a command, a spawn) is refused."""


class Stopped(ConeFeederError):
    """A stop was requested (a signal, a node's shutdown) while a tick ran: it was dropped."""


class RecordingError(ConeFeederError):
    """A recording cannot be opened, written, read or recovered."""


class MessageError(ConeFeederError, ValueError):
    """A message's content does not fit its type (e.g. a PointCloud2 whose points do not fit)."""


class ReportError(ConeFeederError):
    """A recording cannot be read for a report, or the report cannot be written."""


class SweepError(ConeFeederError, ValueError):
    """A sweep file is malformed, or its output directory holds another sweep's results."""


class EnvConfigError(ConeFeederError, ValueError):
    """A reinforcement-learning environment's configuration is malformed (the key is named)."""


class ViewError(ConeFeederError):
    """The live view cannot start: no foxglove-sdk, its port is taken, or a bad setting."""


class TwinError(ConeFeederError, ValueError):
    """A twin file or its streams are malformed (the key, file or row is named)."""
