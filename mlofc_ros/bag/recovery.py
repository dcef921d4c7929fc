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
Find out whether a bag was closed properly, and read what an unfinished one holds.

:func:`layout` checks what a path is (bag folder, storage file, or neither) and names what a
clean read would miss: no ``metadata.yaml``, a journal SQLite did not apply, a ``.db3`` shorter
than its header says. :class:`RecoveredBag` then reads the complete messages of the storage
files themselves (:mod:`.mcap_scan`, :mod:`.sqlite_scan`), in timestamp order.
"""
from dataclasses import dataclass, field
import heapq
from pathlib import Path
import re
import struct
from typing import Dict, Iterable, Iterator, List, Optional, Set, Tuple

from mlofc_ros.bag.mcap_scan import McapScanError, read_messages, scan_mcap
from mlofc_ros.bag.sqlite_scan import sidecars, SqliteScan, SqliteScanError

STORAGE_SUFFIXES = ('.mcap', '.db3')
EXPECTED = ('expected a rosbag2 bag: a folder with metadata.yaml and .mcap or .db3 files, or '
            'a .mcap or .db3 file')


class RecoveryError(Exception):
    """A path is not a bag, or a storage file cannot be read; the text says which and why."""


@dataclass
class Layout:
    """What a bag path holds: its storage files and why it looks unfinished (if it does)."""

    files: List[Path]
    problems: List[str] = field(default_factory=list)


def _natural(path: Path) -> Tuple[str, int]:
    # split bags are name_0.mcap, name_1.mcap, ..., name_10.mcap: order by the number
    m = re.search(r'_(\d+)$', path.stem)
    return (path.stem[:m.start()], int(m.group(1))) if m else (path.stem, -1)


def db3_shortfall(path: Path) -> Optional[str]:
    """Say how a ``.db3`` is shorter than its header's page count, or None when it is not."""
    with path.open('rb') as f:
        head = f.read(100)
    if len(head) < 100 or not head.startswith(b'SQLite format 3\x00'):
        return None   # not sqlite at all: the reader says so
    (page_size,) = struct.unpack_from('>H', head, 16)
    page_size = 65536 if page_size == 1 else page_size
    (pages,) = struct.unpack_from('>I', head, 28)
    need, size = pages * page_size, path.stat().st_size
    return f'{path.name} is cut short ({size} of {need} bytes)' if size < need else None


def layout(path: Path) -> Layout:
    """
    Return the storage files of ``path`` and the signs that it was not closed.

    Raises ``RecoveryError`` for an empty folder, a folder or file that is not a bag.
    """
    if path.is_file():
        if path.suffix not in STORAGE_SUFFIXES:
            raise RecoveryError(f'not a bag file (suffix {path.suffix or "none"!r}); {EXPECTED}')
        files = [path]
        problems: List[str] = []
    elif path.is_dir():
        entries = list(path.iterdir())
        if not entries:
            raise RecoveryError(f'empty folder; {EXPECTED}')
        files = sorted((p for p in entries if p.suffix in STORAGE_SUFFIXES and p.is_file()),
                       key=_natural)
        has_meta = (path / 'metadata.yaml').is_file()
        if not files:
            if has_meta:
                raise RecoveryError('metadata.yaml but no .mcap or .db3 file next to it; the '
                                    'storage files are missing')
            raise RecoveryError(f'not a bag: no metadata.yaml and no .mcap or .db3 file in the '
                                f'folder; {EXPECTED}')
        problems = [] if has_meta else ['no metadata.yaml (the recording was not closed)']
    else:
        raise RecoveryError(f'neither a file nor a folder; {EXPECTED}')
    for f in files:
        if f.suffix == '.db3':
            if sidecars(f):
                problems.append(f'{f.name} was not closed by its writer (journal next to it)')
            short = db3_shortfall(f)
            if short:
                problems.append(short)
    return Layout(files, problems)


class _Source:
    """One storage file: topics by id, ``(stamp, id)`` of each complete message, and reading."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.topics: Dict[int, Tuple[str, str]] = {}
        self.stamps: List[Tuple[int, int]] = []
        self.problem = ''
        self._sqlite: Optional[SqliteScan] = None
        try:
            if path.suffix == '.mcap':
                self._mcap = scan_mcap(path)
                self.topics = {i: (c.topic, c.msgtype) for i, c in self._mcap.channels.items()
                               if c.encoding == 'cdr'}
                self.stamps = [(e[0], e[1]) for e in self._mcap.entries]
                self.problem = self._mcap.problem
            else:
                self._sqlite = SqliteScan(path)
                self._sqlite.open()
                self.topics = dict(self._sqlite.index.topics)
                self.stamps = [(r[0], r[2]) for r in self._sqlite.index.rows]
                self.problem = self._sqlite.index.problem
        except (McapScanError, SqliteScanError) as exc:
            raise RecoveryError(f'{path.name}: {exc}') from None
        except OSError as exc:
            raise RecoveryError(f'{path.name}: cannot read ({exc.strerror or exc})') from None

    def messages(self, ids: Set[int]) -> Iterator[Tuple[int, int, bytes]]:
        if self._sqlite is not None:
            return self._sqlite.messages(ids)
        return read_messages(self.path, self._mcap, ids)

    def close(self) -> None:
        if self._sqlite is not None:
            self._sqlite.close()


class RecoveredBag:
    """
    The complete messages of the storage files of an unfinished bag.

    ``topics`` maps topic -> type, ``counts`` topic -> complete messages, ``problems`` lists
    why the bag is incomplete. Raises ``RecoveryError`` when a file cannot be read at all.
    """

    def __init__(self, files: Iterable[Path], problems: Iterable[str] = ()) -> None:
        self.sources: List[_Source] = []
        try:
            for f in files:
                self.sources.append(_Source(f))
        except BaseException:
            self.close()
            raise
        self.problems = list(problems) + [f'{s.path.name}: {s.problem}' for s in self.sources
                                          if s.problem]
        self.topics: Dict[str, str] = {}
        self.counts: Dict[str, int] = {}
        stamps = []
        for src in self.sources:
            for topic, msgtype in src.topics.values():
                self.topics.setdefault(topic, msgtype)
                self.counts.setdefault(topic, 0)
            for stamp, tid in src.stamps:
                if tid in src.topics:
                    self.counts[src.topics[tid][0]] += 1
                    stamps.append(stamp)
        self.message_count = len(stamps)
        self.start_ns = min(stamps) if stamps else 0
        self.duration_ns = max(stamps) - self.start_ns + 1 if stamps else 0

    def messages(self, topics: Optional[Set[str]] = None
                 ) -> Iterator[Tuple[str, int, bytes, str]]:
        """Yield ``(topic, timestamp, data, msgtype)`` of ``topics`` (all when None), in order."""
        streams = []
        for src in self.sources:
            ids = {i for i, (t, m) in src.topics.items()
                   if (topics is None or t in topics) and self.topics[t] == m}
            if ids:
                streams.append(((stamp, src.topics[i][0], data, src.topics[i][1])
                                for i, stamp, data in src.messages(ids)))
        for stamp, topic, data, msgtype in heapq.merge(*streams, key=lambda m: m[0]):
            yield topic, stamp, data, msgtype

    def close(self) -> None:
        """Release the files (idempotent)."""
        for src in self.sources:
            src.close()
