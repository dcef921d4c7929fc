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

"""The parameter file and the launch file a ROS user starts the node with."""
import importlib.util
from pathlib import Path

from mlofc_ros import params as P
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / 'config' / 'mlofc.yaml'
LAUNCH = ROOT / 'launch' / 'mlofc.launch.py'


def test_parameter_file_holds_every_parameter_at_its_default():
    data = yaml.safe_load(CONFIG.read_text())
    assert list(data) == ['/**'] and list(data['/**']) == ['ros__parameters']
    values = data['/**']['ros__parameters']
    assert list(values) == list(P.PARAMS)          # exactly the table's, in its order
    for spec in P.PARAMETERS:
        value = values[spec.name]
        # the YAML type is the ROS type: a double written as 0 would be declared an integer
        assert type(value) is spec.type, (spec.name, value)
        assert P.validate(spec.name, value) is None, (spec.name, value)
        assert value == spec.default, (spec.name, value)


@pytest.mark.ros
def test_node_reads_a_parameter_file_and_keeps_doubles_doubles(tmp_path):
    import rclpy
    from rclpy.parameter import Parameter

    from mlofc_ros.node import MlofcNode

    data = yaml.safe_load(CONFIG.read_text())
    data['/**']['ros__parameters'].update(window=7, method='general', focal_length=450,
                                          max_frame_gap=2)   # integers for doubles
    path = tmp_path / 'mlofc.yaml'
    path.write_text(yaml.safe_dump(data))
    context = rclpy.Context()
    rclpy.init(args=['--ros-args', '--params-file', str(path)], context=context)
    try:
        node = MlofcNode(context=context)
        try:
            got = {name: node.get_parameter(name) for name in P.PARAMS}
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    kinds = {int: Parameter.Type.INTEGER, float: Parameter.Type.DOUBLE,
             str: Parameter.Type.STRING, bool: Parameter.Type.BOOL}
    for spec in P.PARAMETERS:
        assert got[spec.name].type_ == kinds[spec.type], spec.name
    assert got['window'].value == 7 and got['method'].value == 'general'
    assert got['focal_length'].value == 450.0 and got['max_frame_gap'].value == 2.0


@pytest.mark.ros
def test_launch_file_remaps_the_camera_and_passes_the_parameter_file():
    # launch and launch_ros come with a ROS install (not on PyPI): this one test needs them
    launch_ros_actions = pytest.importorskip('launch_ros.actions')
    launch = pytest.importorskip('launch')
    spec = importlib.util.spec_from_file_location('mlofc_launch', LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    arguments = {a.name: a for a in description.get_launch_arguments()}
    assert set(arguments) == {'image', 'camera_info', 'params_file', 'namespace', 'node_name'}
    context = launch.LaunchContext()
    for a in arguments.values():
        if a.name != 'params_file':      # its default is the installed package's share
            context.launch_configurations[a.name] = launch.utilities.perform_substitutions(
                context, a.default_value)
    assert context.launch_configurations['image'] == '/camera/image_raw'
    context.launch_configurations.update(
        image='/cam/image_raw', camera_info='/cam/camera_info', params_file=str(CONFIG),
        namespace='front', node_name='segmenter')
    nodes = [e for e in description.entities if isinstance(e, launch_ros_actions.Node)]
    assert len(nodes) == 1
    node = nodes[0]
    node._perform_substitutions(context)
    assert node.node_package == 'mlofc_ros' and node.node_executable == 'mlofc_node'
    assert node.node_name == '/front/segmenter'
    assert node.expanded_remapping_rules == [('image', '/cam/image_raw'),
                                             ('camera_info', '/cam/camera_info')]
    # (path, is_file) pairs; launch_ros has no public accessor for them
    expanded = getattr(node, '_Node__expanded_parameter_arguments') or []
    assert (str(CONFIG), True) in [(str(path), is_file) for path, is_file in expanded], expanded
