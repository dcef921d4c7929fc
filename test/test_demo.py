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

"""The demo: scoring helpers, a short run with the node as a subprocess, a clean failure."""
import re
import subprocess
import sys

from mlofc_tools import demo, demo_node
import numpy as np
import pytest


def test_match_segments_accepts_parts_of_edges():
    truth = np.array([[0.0, 0.0, 100.0, 0.0], [0.0, 50.0, 0.0, 150.0]])
    det = np.array([[10.0, 1.0, 60.0, -1.0],      # part of edge 0
                    [-1.0, 60.0, 1.5, 140.0],     # part of edge 1
                    [10.0, 20.0, 60.0, 20.0],     # parallel, 20 px off: no edge
                    [120.0, 0.0, 150.0, 0.0]])    # beyond the end of edge 0
    np.testing.assert_array_equal(demo.match_segments(det, truth), [0, 1, -1, -1])
    assert demo.match_segments(np.zeros((0, 4)), truth).shape == (0,)
    np.testing.assert_array_equal(demo.match_segments(det, np.zeros((0, 4))), [-1] * 4)


def test_match_bodies_maximises_overlap():
    conf = np.array([[0, 40, 2], [30, 0, 1], [1, 3, 25]])
    assert demo.match_bodies(conf) == {0: 1, 1: 0, 2: 2}
    # more node labels than true bodies: the weakest label stays unmatched
    conf = np.array([[5, 0], [0, 7], [1, 2]])
    assert demo.match_bodies(conf) == {0: 0, 1: 1}


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize('method', [[], ['--method', 'robust', '--motion', 'camera_centre']])
def test_demo_runs_the_node_as_a_subprocess(tmp_path, method):
    # the default (auto, moving to general on the spinning boxes; fed in lock-step, every
    # frame solved) and the rotation model on its own scene
    proc = subprocess.run(
        [sys.executable, '-m', 'mlofc_tools.demo', '--frames', '20', '--out', str(tmp_path)]
        + method, capture_output=True, text=True, timeout=150)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    assert 'node: 20/20 frames answered' in out, out
    for body in ('background', 'box0', 'box1'):
        assert re.search(rf'^{body}\s+\d+\s+\(', out, re.M), out
    accuracy = float(re.search(r'label accuracy ([\d.]+) %', out).group(1))
    assert accuracy > 80.0, out
    assert (tmp_path / 'demo_strip.png').stat().st_size > 10_000
    report = (tmp_path / 'README.md').read_text()
    assert 'label accuracy' in report and '![segments coloured by body](demo_strip.png)' in report


@pytest.mark.ros
def test_demo_fails_cleanly_when_the_node_does_not_answer(tmp_path, monkeypatch, capsys):
    # a "node" that never subscribes to anything
    monkeypatch.setattr(demo_node, 'node_command',
                        lambda: [sys.executable, '-c', 'import time; time.sleep(30)'])
    rc = demo.main(['--frames', '3', '--size', '64x48', '--out', str(tmp_path),
                    '--startup-timeout', '2'])
    err = capsys.readouterr().err
    assert rc == 1
    assert 'did not come up' in err and 'Traceback' not in err
    assert not (tmp_path / 'README.md').exists()


def test_demo_renders_boxes_that_translate_by_default():
    assert demo._parser().parse_args([]).motion == 'own_centre'
    assert demo._parser().parse_args(['--motion', 'camera_centre']).motion == 'camera_centre'
    assert set(demo.MOTIONS) == {'camera_centre', 'own_centre'}


def test_demo_solves_a_slow_method_in_the_nodes_own_thread():
    general = demo_node._node_command_line(demo_node.DemoConfig(method='general'))
    assert 'method:=general' in general and 'solver_process:=false' in general
    # the default, 'auto', may move to 'general'
    assert 'solver_process:=false' in demo_node._node_command_line(demo_node.DemoConfig())
    assert not any('solver_process' in a for a in demo_node._node_command_line(
        demo_node.DemoConfig(method='robust')))


def test_demo_uses_the_domain_the_environment_sets(monkeypatch):
    monkeypatch.setenv('ROS_DOMAIN_ID', '42')
    assert demo_node.fresh_domain_id() == 42
    monkeypatch.delenv('ROS_DOMAIN_ID')
    assert 1 <= demo_node.fresh_domain_id() <= 100


def test_summary_survives_a_node_that_found_nothing():
    from types import SimpleNamespace
    seq = SimpleNamespace(body_names=['background', 'box0'],
                          angular_velocities=np.zeros((2, 3)),
                          truth=[SimpleNamespace(segments=np.zeros((0, 4)),
                                                 body_ids=np.zeros(0, np.int64))] * 3)
    collected = demo.Collected()
    collected.frames[2] = demo.FrameOutput(np.zeros((0, 4)), np.zeros(0), np.zeros(0, np.int64),
                                           np.zeros(0))
    ev = demo.evaluate(seq, collected, warmup=1)
    lines = demo.summary_lines(seq, ev, collected, demo.DemoConfig(frames=3, boxes=1))
    assert any('not found: background, box0' in line for line in lines)
