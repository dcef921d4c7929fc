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
ament_copyright's rules for the Apache-2.0 license, for machines without ament_copyright.

ament_copyright (ament_lint 0.17) is not on PyPI. This module applies its checks to the files
it visits: every ``.py``/C/C++/CMake file under the given paths (not in folders starting with
``.`` or ``_``, nor below an ``AMENT_IGNORE`` marker, nor the ``setup.py`` beside a
``package.xml``) must open, after a shebang or coding line, with a comment block holding a
``Copyright YEAR NAME`` notice followed by the Apache-2.0 header, in order, whitespace aside.
A repository root (a folder with ``.git``) must hold ``LICENSE`` with the Apache-2.0 text and
``CONTRIBUTING.md`` with the Apache-2.0 contribution clause.
"""
import os
import re
import sys
from typing import Dict, List, Optional

EXTENSIONS = ('c', 'cc', 'cpp', 'cxx', 'h', 'hh', 'hpp', 'hxx', 'cmake', 'py')

#: ament_copyright's ``apache2_header.txt``, split at its ``{copyright}`` placeholder.
APACHE2_HEADER = (
    'Licensed under the Apache License, Version 2.0 (the "License"); you may not use this '
    'file except in compliance with the License. You may obtain a copy of the License at '
    'http://www.apache.org/licenses/LICENSE-2.0 Unless required by applicable law or agreed '
    'to in writing, software distributed under the License is distributed on an "AS IS" '
    'BASIS, WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied. See the '
    'License for the specific language governing permissions and limitations under the '
    'License.')

#: The opening and the closing words of ``apache2_license.txt`` (the whole text, in order).
APACHE2_LICENSE = (
    'Apache License Version 2.0, January 2004 http://www.apache.org/licenses/',
    'TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION',
    'END OF TERMS AND CONDITIONS')

#: ament_copyright's ``apache2_contributing.txt``.
APACHE2_CONTRIBUTING = (
    'Any contribution that you make to this repository will be under the Apache 2 License, as '
    'dictated by that [license](http://www.apache.org/licenses/LICENSE-2.0.html): ~~~ 5. '
    'Submission of Contributions. Unless You explicitly state otherwise, any Contribution '
    'intentionally submitted for inclusion in the Work by You to the Licensor shall be under '
    'the terms and conditions of this License, without any additional terms or conditions. '
    'Notwithstanding the above, nothing herein shall supersede or modify the terms of any '
    'separate license agreement you may have executed with Licensor regarding such '
    'Contributions. ~~~')

_YEARS = r'(?:\d{4}-\d{4}|\d{4})'
NOTICE = re.compile(r'^[^\n\r]?\s*(?:\\copyright\s*)?copyright(?:\s+\(c\))?\s+'
                    r'(%s(?:,\s*%s)*),?\s+([^\n\r]+)$' % (_YEARS, _YEARS),
                    re.DOTALL | re.MULTILINE | re.IGNORECASE)


def flat(text: str) -> str:
    """Collapse all whitespace, as ament_copyright compares texts."""
    return ' '.join(text.split())


def in_order(content: str, sections) -> bool:
    """Return whether every section occurs in ``content``, each after the previous one."""
    content, last = flat(content), -1
    for section in sections:
        index = content.find(flat(section))
        if index == -1 or index <= last:
            return False
        last = index
    return True


def first_comment_block(content: str) -> Optional[str]:
    """Return the first ``#`` comment block after shebang and coding lines, markers removed."""
    lines = content.splitlines()
    i = 0
    while i < len(lines) and lines[i].startswith('#') and (
            lines[i].startswith('#!') or 'coding=' in lines[i] or 'coding:' in lines[i]):
        i += 1
    while i < len(lines) and not lines[i].startswith('#'):
        i += 1
    block = []
    while i < len(lines) and lines[i].startswith('#'):
        block.append(lines[i][2:])
        i += 1
    return '\n'.join(block) if block else None


def check_source(path: str) -> Optional[str]:
    """Return the problem with one source file's header, or None."""
    with open(path, encoding='utf-8') as f:
        content = f.read()
    if not content:
        return None          # an empty file is reported, not an error
    block = first_comment_block(content)
    match = NOTICE.search(block) if block else None
    if not match:
        return 'could not find copyright notice'
    if not in_order(block[match.end():], [APACHE2_HEADER]):
        return 'copyright=%s (%s), license=<unknown>' % (match.group(2), match.group(1))
    return None


def files_to_check(paths: List[str]) -> Dict[str, str]:
    """Map each visited file to its kind: ``source``, ``license`` or ``contributing``."""
    files = {}

    def add_root_files(folder: str) -> None:
        files[os.path.join(folder, 'LICENSE')] = 'license'
        files[os.path.join(folder, 'CONTRIBUTING.md')] = 'contributing'

    def is_root(folder: str) -> bool:
        return any(os.path.exists(os.path.join(folder, m)) for m in ('.git', '.hg'))

    for path in paths:
        if os.path.isdir(path):
            for dirpath, dirnames, filenames in os.walk(path):
                if 'AMENT_IGNORE' in dirnames + filenames:
                    dirnames[:] = []
                    continue
                if is_root(dirpath):
                    add_root_files(dirpath)
                dirnames[:] = sorted(d for d in dirnames if d[0] not in '._')
                for name in sorted(filenames):
                    if name == 'setup.py' and os.path.exists(
                            os.path.join(dirpath, 'package.xml')):
                        continue
                    if name.rsplit('.', 1)[-1] in EXTENSIONS and '.' in name:
                        files[os.path.join(dirpath, name)] = 'source'
        elif path.rsplit('.', 1)[-1] in EXTENSIONS:
            files[path] = 'source'
    return {os.path.normpath(p): kind for p, kind in files.items()}


def main(argv: List[str]) -> int:
    """Check the paths as ``ament_copyright PATHS`` does; print problems; 0 when none."""
    errors = 0
    checked = files_to_check(argv or ['.'])
    for path, kind in sorted(checked.items()):
        if kind == 'source':
            problem = check_source(path)
        elif not os.path.exists(path):
            problem = 'file not found'
        else:
            with open(path, encoding='utf-8') as f:
                text = f.read()
            sections = APACHE2_LICENSE if kind == 'license' else [APACHE2_CONTRIBUTING]
            problem = None if in_order(text, sections) else '<unknown> license'
        if problem:
            errors += 1
            print('%s: %s' % (path, problem), file=sys.stderr)
    if errors:
        print('%d errors, checked %d files' % (errors, len(checked)), file=sys.stderr)
        return 1
    print('No problems found, checked %d files' % len(checked))
    return 0
