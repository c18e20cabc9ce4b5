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
The live node's recording: open it from the parameters, watch it, close it with the totals.

:class:`NodeRecording` wraps the :class:`~cone_feeder_sim.formats.run_recorder.RunRecorder`
of one run (or none, when ``record_path`` is empty). The run metadata is
:func:`~cone_feeder_sim.formats.runlog.run_metadata`, the layout the headless runner writes
too, with the keys re-simulation needs (:func:`node_metadata`). A recording that stops (a
full disk, a vanished folder) is closed and its error kept, while the simulation goes on.
"""

from collections.abc import Callable, Mapping, Sequence
import json
import os
from pathlib import Path
from typing import Any

from .outputs import TopicInfo
from ..errors import ParameterError
from ..feeder.engine import FeederEngine
from ..formats.mcap_writer import COMPRESSIONS
from ..formats.run_recorder import RecordingLimits, RunRecorder
from ..formats.runlog import (
    engine_config_json, expand_record_path, METADATA_NAME, run_metadata)

__all__ = ['NodeRecording', 'node_metadata']


def node_metadata(values: Mapping[str, Any], engine: FeederEngine, node: str, namespace: str,
                  topics: Mapping[str, str], input_topics: Sequence[str]) -> dict[str, str]:
    """
    Return the metadata of a sim_node run: its parameters and what re-simulation needs.

    values: the node's parameters; node and namespace: its fully qualified name and
    namespace; topics: table name -> resolved topic; input_topics: the received ones.
    """
    return run_metadata(
        values, 'sim_node', topics, input_topics, node=node, namespace=namespace,
        dt=repr(engine.dt), seed=str(engine.config.seed),
        model_options=json.dumps({'normal_force': engine.model.normal_force,
                                  'friction_direction': engine.model.friction_direction}),
        engine_config=engine_config_json(engine.config),
        ros_distro=os.environ.get('ROS_DISTRO', ''))


class NodeRecording:
    """The MCAP recording of a node's run, or none (see the module documentation)."""

    def __init__(self, values: Mapping[str, Any], topics: Sequence[TopicInfo],
                 metadata: Callable[[], dict[str, str]]) -> None:
        """
        Open the file named by ``values['record_path']`` ('' : no recording).

        values: the node's parameters (record_path, record_compression, the record_max_*
        limits); topics: what the node publishes and receives; metadata: gives the run
        metadata (called only when recording). Raises ParameterError for a compression
        the writer lacks, RecordingError when the file cannot be made.
        """
        self.recorder: RunRecorder | None = None
        #: why the recording stopped (None while it runs, or never started)
        self.error: str | None = None
        template = str(values['record_path'])
        if not template:
            return
        compression = str(values['record_compression'])
        if compression not in COMPRESSIONS:
            raise ParameterError(f'record_compression must be one of {", ".join(COMPRESSIONS)}, '
                                 f'got {compression!r}')
        limits = RecordingLimits(
            max_file_size=int(values['record_max_file_size']),
            max_file_duration_ns=round(float(values['record_max_file_duration']) * 1e9),
            min_free_bytes=int(values['record_min_free_space']))
        self.recorder = RunRecorder(
            expand_record_path(template).absolute(),
            [(info.topic, info.type_name, info.qos) for info in topics],
            {METADATA_NAME: metadata()}, limits=limits, compression=compression)

    @property
    def path(self) -> Path | None:
        """Return the path of the run's first file (None when not recording)."""
        return None if self.recorder is None else self.recorder.path

    @property
    def paths(self) -> tuple[Path, ...]:
        """Return the paths of the run's files so far (split parts in order)."""
        return () if self.recorder is None else self.recorder.paths

    @property
    def recording(self) -> bool:
        """Tell whether the recording takes messages."""
        return self.recorder is not None and not self.recorder.closed

    @property
    def stopped(self) -> bool:
        """Tell whether the recording is open but its writer stopped on an error."""
        return self.recording and self.recorder.error is not None

    def close(self, end_metadata: Mapping[str, str]) -> tuple[str, str] | None:
        """
        Finish the file (summary, statistics, ``end_metadata``); idempotent.

        Returns the log line (level, text) saying what is in which files, None when there
        was nothing to close.
        """
        recorder = self.recorder
        if recorder is None or recorder.closed:
            return None
        recorder.close(end_metadata=end_metadata)
        files = ', '.join(str(p) for p in recorder.paths)
        if recorder.error is not None:
            self.error = str(recorder.error)
            return 'error', (f'recording stopped: {recorder.error}; '
                             f'{recorder.message_count} messages are in {files}')
        return 'info', f'recorded {recorder.message_count} messages to {files}'
