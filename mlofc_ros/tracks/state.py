# Copyright 2026 The mlofc_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.
"""
The live tracks: persistent ids and, per track, its segment and motion, misses and age.

Ids are ``uint32``, given in order of birth from 0 and never reused until a reset.
"""
import numpy as np


class TrackSet:
    """Per-track arrays of the live tracks (reported or coasting), in one consistent order."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Drop every track; ids restart from 0."""
        self.ids = np.zeros(0, np.uint32)
        self.seg = np.zeros((0, 4))           # segments px
        self.vel = np.zeros((0, 4))           # per-frame displacement of both endpoints, px
        self.has_vel = np.zeros(0, bool)      # vel measured (else zero, not a prediction)
        self.misses = np.zeros(0, np.int32)   # consecutive frames neither carried nor detected
        self.omega = np.zeros(0)              # smoothed turn per frame, rad
        self.age = np.zeros(0, np.int32)      # frames since birth
        self.next_id = 0

    @property
    def size(self) -> int:
        """Return the number of live tracks."""
        return int(self.ids.size)

    def advance(self, alive: np.ndarray, seg: np.ndarray, vel: np.ndarray,
                has_vel: np.ndarray, misses: np.ndarray, omega: np.ndarray,
                born: np.ndarray) -> None:
        """
        Keep the tracks ``alive`` (T,) with their new state, then add tracks on ``born`` (B, 4).

        ``seg``, ``vel`` (T, 4), ``has_vel``, ``misses``, ``omega`` (T,): the state of every
        current track after this frame. The survivors age by one frame; the new tracks get the
        next ids, no velocity and age 0.
        """
        nb = born.shape[0]
        new_ids = (self.next_id + np.arange(nb)).astype(np.uint32)
        self.next_id += nb
        self.ids = np.concatenate([self.ids[alive], new_ids])
        self.seg = np.concatenate([seg[alive], born])
        self.vel = np.concatenate([vel[alive], np.zeros((nb, 4))])
        self.has_vel = np.concatenate([has_vel[alive], np.zeros(nb, bool)])
        self.misses = np.concatenate([misses[alive], np.zeros(nb, np.int32)]).astype(np.int32)
        self.omega = np.concatenate([omega[alive], np.zeros(nb)])
        self.age = np.concatenate([self.age[alive] + 1, np.zeros(nb, np.int32)])
