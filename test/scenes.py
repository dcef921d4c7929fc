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
"""Small self-contained scene generator for solver tests (independent of mlofc_tools.synthetic)."""
from mlofc_ros.solver.lines import rotation_matrix
import numpy as np


def random_scene(n_bodies, lines_per_body, n_frames=2, noise=0.0, f=1000.0, size=1000,
                 deg=(2.0, 6.0), seed=0, vertical=0, own_centre=False):
    """
    Make bodies rotating about the camera centre (or their own centre).

    Returns tracks, labels, rotation vectors per frame and intrinsics.
    """
    rng = np.random.default_rng(seed)
    cx = cy = size / 2.0
    K = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    tracks, labels, omegas = [], [], []
    for i in range(n_bodies):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        w = np.deg2rad(rng.uniform(*deg)) * axis
        omegas.append(w)
        R = rotation_matrix(w)
        centre = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), 6.5]) if own_centre else 0.0
        got = 0
        while got < lines_per_body:
            z = rng.uniform(5, 8, 2)
            uv = rng.uniform(0.2 * size, 0.8 * size, (2, 2))
            if got < vertical:
                uv[1, 0] = uv[0, 0]
            if np.linalg.norm(uv[0] - uv[1]) < 60:
                continue
            P = (np.linalg.inv(K) @ np.c_[uv, np.ones(2)].T * z).T      # (2, 3)
            frames = []
            for k in range(n_frames):
                Pk = (P - centre) @ np.linalg.matrix_power(R, k).T + centre
                # slide endpoints along the 3D line: only the line matters
                d = Pk[1] - Pk[0]
                a, b = rng.uniform(-0.1, 0.1, 2)
                Q = np.stack([Pk[0] + a * d, Pk[1] + b * d])
                q = (K @ Q.T).T
                frames.append((q[:, :2] / q[:, 2:]).ravel())
            tracks.append(frames)
            labels.append(i)
            got += 1
    tracks = np.array(tracks)
    tracks = tracks + rng.normal(scale=noise, size=tracks.shape) if noise else tracks
    return tracks, np.array(labels), np.array(omegas), (f, f, cx, cy)
