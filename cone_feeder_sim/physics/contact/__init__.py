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
Contact between two pieces: the soft-sphere law of the discrete element method (compiled).

As LIGGGHTS writes it (``normal_model_hertz.h``, ``tangential_model_history.h``,
``cohesion_model_sjkr.h``), one part in a module of its own, so that a part can be read
and swapped alone (doc/model.md, "Contact between pieces"):

- :mod:`.normal`: Hertz's elastic force with a damping set by the restitution coefficient;
- :mod:`.tangential`: a Mindlin spring on the tangential displacement of the contact (its
  history), capped by Coulomb;
- :mod:`.cohesion`: a pull in proportion to the contact area (SJKR), sized by a pull-off
  force;
- :mod:`.law`: the pair's constants from the two pieces' products, the whole force and the
  history's update.

For contact a piece is a sphere of radius s0 without spin; the relative velocity is taken
in the frame turning with the cone (the integrator's velocities). The cone contact stays
the paper's law (:mod:`..model`).
"""

from .law import (
    contact_force, contact_force_py, force_between, history_update, I_BETA, I_COHESION,
    I_MU, interaction_row, INTERACTION_WIDTH, moved_force, pair_constants)

__all__ = ['contact_force', 'contact_force_py', 'force_between', 'history_update',
           'I_BETA', 'I_COHESION', 'I_MU', 'interaction_row', 'INTERACTION_WIDTH',
           'moved_force', 'pair_constants']
