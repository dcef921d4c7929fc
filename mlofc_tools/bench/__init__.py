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
Benchmarks: each writes its report and plots to ``docs/results/NAME/`` (or ``--out DIR``).

Run ``python -m mlofc_tools.bench NAME [options]``; ``python -m mlofc_tools.bench --help``
lists them. The report is ``README.md``, its plots are PNGs beside it; a rerun replaces them.
"""
