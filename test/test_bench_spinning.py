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
"""Scoring of ``python -m mlofc_tools.bench spinning`` on hand-made frames (no rendering)."""
from types import SimpleNamespace

from mlofc_tools.bench import __main__ as dispatcher
from mlofc_tools.bench import spinning
import numpy as np


def _scene():
    truth = SimpleNamespace(segments=np.array([[0, 0, 100, 0], [0, 50, 100, 50],
                                               [0, 100, 100, 100], [0, 150, 100, 150]], float),
                            body_ids=np.array([0, 0, 1, 1]))
    seq = SimpleNamespace(body_names=['background', 'box0'], truth=[truth] * 3,
                          angular_velocities=np.array([[0.0, 0, 0], [0.0, 0, 2.0]]),
                          pivots=np.array([[0.0, 0, 5], [1.0, 0, 0]]))
    return seq


def _frame(labels, omega_box):
    return SimpleNamespace(
        segments=np.array([[1, 0, 90, 0], [1, 50, 90, 50], [1, 100, 90, 100],
                           [1, 150, 90, 150], [300, 300, 400, 400]], float),
        labels=np.array(labels), body_valid=np.array([True, True]),
        angular_velocities=np.array([omega_box, [0.0, 0, 0.01]]))   # labels 0, 1


def test_score_run_counts_wrong_unassigned_and_omega_errors():
    seq = _scene()
    outs = [(_frame([-1, -1, -1, -1, -1], [9.0, 9, 9]), 99.0),      # before the window fills
            (_frame([1, 1, 0, 0, 1], [0.0, 0, 2.2]), 10.0),         # ids swapped, all right
            (_frame([1, 0, -1, 0, 0], [0.0, 0, 1.8]), 30.0)]        # one wrong, one -1
    s = spinning.score_run(seq, outs, first=1)
    assert s['matched'] == 8                     # the fifth segment lies on no true edge
    assert s['mapping'] == {1: 0, 0: 1}
    assert s['wrong'] == 1 / 8 and s['unassigned'] == 1 / 8 and s['wrong_frame'] == 1 / 8
    assert np.isnan(s['omega_err'][0]) and abs(s['omega_err'][1] - 0.1) < 1e-12
    # the box's pivot is on the x axis: the line-of-sight component of (0, 0, 2) is zero
    assert abs(s['los_err'][1] - 1.0) < 1e-12
    assert abs(s['static_deg_s'][0] - np.degrees(0.01)) < 1e-9
    assert list(s['ms']) == [10.0, 30.0]
    row = spinning.build_rows([{'scene': 'x', 'seed': 0, 'method': 'robust', 'window': 5,
                                'score': s}])[0]
    assert row[4] == 12.5 and row[5] == 12.5 and row[7] == '10' and row[10] == 20.0
    rec = {'scene': 'x', 'seed': 0, 'method': 'robust', 'window': 5,
           'score': dict(s, lsd_ms=8.0)}
    summary = spinning.summary_rows([rec, dict(rec, seed=1)])
    assert len(summary) == 1 and summary[0][3] == 2 and summary[0][4] == 12.5
    assert summary[0][6] == 12.5
    assert summary[0][-2] == 20.0 and summary[0][-1] == 2.5    # mean ms and mean / LSD


def test_score_run_per_frame_leaves_out_id_switches():
    seq = _scene()
    right, swapped = _frame([0, 0, 1, 1, 1], [0.0, 0, 2.0]), _frame([1, 1, 0, 0, 1], [0.0, 0, 2])
    s = spinning.score_run(seq, [(right, 1.0), (right, 1.0), (swapped, 1.0)], first=0)
    assert s['mapping'] == {0: 0, 1: 1}
    assert s['wrong'] == 4 / 12 and s['wrong_frame'] == 0.0


def test_spinning_is_registered():
    assert 'spinning' in dispatcher.BENCHMARKS
    assert set(spinning.SCENES) >= {'own2+bg', 'own3+bg', 'own2', 'own3', 'cam2+bg'}


def test_spinning_takes_node_parameters():
    args = spinning.parse_args(['-p', 'detector_scale:=1.0', '-p', 'detect_every:=2'])
    assert args.params == {'detector_scale': 1.0, 'detect_every': 2}
    assert spinning.parse_args([]).params == {}


def test_every_scene_renders_its_own_ranges():
    for name, scene in spinning.SCENES.items():
        seq = spinning.render_scene(name, 0, 2)
        assert len(seq.body_names) == scene.boxes + scene.background, name
        speeds = np.degrees([np.linalg.norm(w) for w in seq.angular_velocities])
        moving = speeds[speeds > 0]
        lo, hi = scene.speed_deg_s
        assert moving.size == scene.boxes and np.all((moving >= lo) & (moving <= hi)), name
