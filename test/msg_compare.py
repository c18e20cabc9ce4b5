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

"""Comparison helper shared by the message tests: decoded messages as plain Python data."""

import array
from typing import Any

import numpy as np


def normalize(value: Any) -> Any:
    """Return plain Python data (lists, dicts, numbers, str) for comparisons."""
    if isinstance(value, dict):
        return {key: normalize(item) for key, item in value.items()}
    if hasattr(value, '__dataclass_fields__'):  # rosbags message; constants are upper case
        return {
            key: normalize(getattr(value, key))
            for key in value.__dataclass_fields__ if key != '__msgtype__' and not key.isupper()}
    if isinstance(value, (bytes, bytearray, memoryview, array.array)):
        return list(bytes(value)) if not isinstance(value, array.array) else value.tolist()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [normalize(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
