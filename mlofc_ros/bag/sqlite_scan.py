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
Read the rows of a rosbag2 sqlite3 file that was not closed (cut short, or never finished).

A recorder that dies leaves its ``.db3`` with a hot ``-journal`` (or a ``-wal``) next to it:
the committed rows are in the database only once SQLite has rolled the journal back (or
replayed the log). That needs write access, so the files are copied to a temporary directory
first and the copy is opened; the original stays untouched. Rows are then read in insertion
order until the first one that cannot be read (a file cut inside its pages).
"""
from dataclasses import dataclass, field
from pathlib import Path
import shutil
import sqlite3
import tempfile
from typing import Dict, Iterator, List, Set, Tuple

#: Files SQLite keeps next to a database that is being written.
SIDECARS = ('-journal', '-wal')


class SqliteScanError(Exception):
    """The file is not a rosbag2 sqlite3 database."""


@dataclass
class SqliteIndex:
    """
    What a scan found: topics ``id -> (name, type)`` and rows ``(timestamp, row id, topic id)``.

    ``complete`` is False when the scan stopped at an unreadable row (``problem`` then says
    where) or had to apply a journal.
    """

    topics: Dict[int, Tuple[str, str]] = field(default_factory=dict)
    rows: List[Tuple[int, int, int]] = field(default_factory=list)
    complete: bool = True
    problem: str = ''


def sidecars(path: Path) -> List[Path]:
    """Return the journal / write-ahead-log files SQLite left next to ``path``."""
    return [p for p in (path.with_name(path.name + s) for s in SIDECARS) if p.exists()]


class SqliteScan:
    """
    An open, scanned copy (or read-only view) of a db3 file; a context manager.

    ``index`` holds what was found; :meth:`messages` reads the data of the scanned rows.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.index = SqliteIndex()
        self._tmp = ''
        self._conn: sqlite3.Connection

    def __enter__(self) -> 'SqliteScan':
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:  # noqa: A003 (the context-manager protocol's name)
        """Open (a copy of) the file and scan its rows; ``SqliteScanError`` when not a bag."""
        journals = sidecars(self.path)
        if journals:
            self._tmp = tempfile.mkdtemp(prefix='mlofc_db3_')
            for src in [self.path, *journals]:
                shutil.copyfile(src, Path(self._tmp) / src.name)
            uri = f'file:{Path(self._tmp) / self.path.name}'
        else:
            uri = f'file:{self.path}?immutable=1'
        try:
            self._conn = sqlite3.connect(uri, uri=True)
            # a file shorter than its header's page count is "malformed" to SQLite unless the
            # schema is writable; then it reads the pages that are there (nothing is written)
            self._conn.execute('PRAGMA writable_schema = ON')
            self._scan()
        except sqlite3.DatabaseError as exc:
            self.close()
            raise SqliteScanError(f'not a readable sqlite3 database ({exc})') from None
        except BaseException:
            self.close()
            raise
        # a journal is reported by recovery.layout, which also decides to come here for it
        self.index.complete = self.index.complete and not journals

    def _scan(self) -> None:
        tables = {r[0] for r in self._conn.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table'")}
        if not {'topics', 'messages'} <= tables:
            raise SqliteScanError('a sqlite3 database without the rosbag2 tables '
                                  '(topics, messages)')
        self.index.topics = {int(i): (str(n), str(t)) for i, n, t in self._conn.execute(
            'SELECT id, name, type FROM topics')}
        rows = self.index.rows
        cursor = self._conn.execute('SELECT id, topic_id, timestamp, data FROM messages '
                                    'ORDER BY id')
        try:
            # the data is read too: a row whose overflow pages are cut off is not complete
            for rid, tid, stamp, _ in cursor:
                rows.append((int(stamp), int(rid), int(tid)))
        except sqlite3.DatabaseError as exc:
            self.index.complete = False
            self.index.problem = f'unreadable after {len(rows)} messages ({exc})'

    def messages(self, topic_ids: Set[int]) -> Iterator[Tuple[int, int, bytes]]:
        """Yield ``(topic_id, timestamp, data)`` of ``topic_ids`` in timestamp order."""
        for stamp, rid, tid in sorted(r for r in self.index.rows if r[2] in topic_ids):
            (data,) = self._conn.execute('SELECT data FROM messages WHERE id = ?',
                                         (rid,)).fetchone()
            yield tid, stamp, bytes(data)

    def close(self) -> None:
        """Close the database and remove the temporary copy (idempotent)."""
        conn = getattr(self, '_conn', None)
        if conn is not None:
            conn.close()
            del self._conn
        if self._tmp:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = ''
