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

"""The parameter table: defaults valid, validation reasons readable, doubles accept integers."""
import doctest
import math

from mlofc_ros import params
from mlofc_ros.segments.detect import has_ximgproc
from mlofc_ros.solver import METHODS
import pytest

REQUIRED = {'num_bodies': (int, 2), 'window': (int, 0), 'method': (str, 'auto'),
            'min_segment_length': (float, 20.0), 'focal_length': (float, 0.0),
            'publish_debug_image': (bool, False), 'max_pixels': (int, 4096 * 4096),
            'queue_size': (int, 2), 'max_frame_gap': (float, None)}


def test_table_has_the_required_parameters_with_their_types_and_defaults():
    for name, (kind, default) in REQUIRED.items():
        spec = params.PARAMS[name]
        assert spec.type is kind, name
        if default is not None:
            assert spec.default == default and type(spec.default) is kind, name
    assert params.PARAMS['window'].range == (0, 30)
    assert len(params.PARAMS) == len(params.PARAMETERS)


def test_every_default_is_valid_and_every_entry_is_documented():
    for spec in params.PARAMETERS:
        assert params.validate(spec.name, spec.default) is None, spec.name
        assert spec.description.strip(), spec.name
        assert spec.scope in ('pipeline', 'node'), spec.name
        if spec.range is not None:
            assert spec.type in (int, float)
            assert spec.range[0] <= spec.default <= spec.range[1], spec.name


def test_method_choices_come_from_the_solver():
    # and 'auto', which the pipeline resolves to one of them (mlofc_ros.method_choice)
    assert params.PARAMS['method'].allowed_choices() == tuple(METHODS) + ('auto',)
    for m in METHODS + ('auto',):
        assert params.validate('method', m) is None
    reason = params.validate('method', 'magic')
    assert 'magic' in reason and 'robust' in reason


@pytest.mark.parametrize('name, value, words', [
    ('window', 1, ['window', '0', '[2, 30]', '1']),
    ('window', -1, ['window', '[0, 30]']),
    ('window', 31, ['window', '31']),
    ('window', 5.0, ['integer']),
    ('num_bodies', True, ['integer', 'bool']),
    ('num_bodies', -1, ['num_bodies']),
    ('focal_length', -5.0, ['focal_length', '-5.0']),
    ('focal_length', 'f', ['double', '1.0']),
    ('focal_length', math.nan, ['finite']),
    ('focal_length', math.inf, ['finite']),
    ('publish_debug_image', 1, ['bool']),
    ('method', 3, ['string']),
    ('queue_size', 0, ['queue_size']),
    ('max_pixels', None, ['max_pixels', 'no value']),
    ('no_such_thing', 1, ['unknown', 'no_such_thing']),
])
def test_invalid_values_are_rejected_with_a_reason_naming_them(name, value, words):
    reason = params.validate(name, value)
    assert reason is not None
    for w in words:
        assert w in reason, (reason, w)


def test_integers_are_accepted_for_doubles_and_coerced():
    assert params.validate('focal_length', 500) is None
    assert params.validate('min_segment_length', 30) is None
    v = params.coerce('focal_length', 500)
    assert v == 500.0 and isinstance(v, float)
    with pytest.raises(ValueError, match='window'):
        params.coerce('window', 1)


def test_check_all_reports_every_problem_at_once():
    got = params.check_all({'window': 7, 'focal_length': 3})
    assert got == {'window': 7, 'focal_length': 3.0}
    with pytest.raises(ValueError) as err:
        params.check_all({'window': 1, 'queue_size': 0})
    assert 'window' in str(err.value) and 'queue_size' in str(err.value)


def test_scopes_and_defaults():
    node_only = set(params.names('node'))
    assert {'queue_size', 'publish_debug_image'} <= node_only
    assert not node_only & set(params.names('pipeline'))
    assert params.defaults()['window'] == 0
    assert set(params.defaults('pipeline')) == set(params.names('pipeline'))


def test_markdown_table_lists_every_parameter():
    table = params.markdown_table()
    lines = table.splitlines()
    assert len(lines) == 2 + len(params.PARAMETERS)
    for spec in params.PARAMETERS:
        assert f'`{spec.name}`' in table
    assert '[2, 30]' in table and "'auto'" in table


def test_fld_backend_needs_opencv_contrib():
    assert params.validate('detector_backend', 'lsd') is None
    assert 'one of lsd, fld' in params.validate('detector_backend', 'edlines')
    reason = params.validate('detector_backend', 'fld')
    if has_ximgproc():
        assert reason is None
    else:
        assert 'opencv-contrib-python-headless' in reason


def test_module_examples():
    assert doctest.testmod(params).failed == 0
