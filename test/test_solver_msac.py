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
"""Sequential MSAC, the robust solver's sampled start: its scoring quantile."""
from mlofc_ros.solver.robust import column_quantile
import numpy as np
import pytest


@pytest.mark.parametrize('rows', [1, 2, 7, 200])
@pytest.mark.parametrize('q', [0.0, 1.0 / 6.0, 0.25, 0.5, 0.999, 1.0])
def testcolumn_quantile_is_numpys(rows, q):
    x = np.random.default_rng(rows).normal(size=(rows, 30))
    x[:, 3] = 1.0                                     # ties
    assert np.array_equal(column_quantile(x, q), np.quantile(x, q, axis=0))
