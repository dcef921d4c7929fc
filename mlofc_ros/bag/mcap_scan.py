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
Read the complete records of an mcap file front to back, without its summary section.

A recorder that loses power leaves an mcap file without summary and footer: readers that start
from the footer refuse it, although every chunk written before the cut is intact. This module
walks the data section record by record (magic, header, schemas, channels, chunks, messages),
stops at the first record that is cut short or does not check out, and indexes the messages of
the complete records, so they can be read back in timestamp order.
"""
from binascii import crc32
from dataclasses import dataclass, field
from pathlib import Path
import struct
from typing import BinaryIO, Callable, Dict, Iterator, List, Optional, Set, Tuple

MAGIC = b'\x89MCAP0\r\n'

OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
OP_MESSAGE, OP_CHUNK, OP_DATA_END = 0x05, 0x06, 0x0F
_NAMES = {0x01: 'header', 0x02: 'footer', 0x03: 'schema', 0x04: 'channel', 0x05: 'message',
          0x06: 'chunk', 0x07: 'message index', 0x08: 'chunk index', 0x09: 'attachment',
          0x0C: 'metadata', 0x0F: 'data end'}

_RECORD = struct.Struct('<BQ')
_MESSAGE = struct.Struct('<HIQQ')
_CHUNK = struct.Struct('<QQQI')


class McapScanError(Exception):
    """The file is not an mcap file (its first bytes say so)."""


@dataclass
class McapChannel:
    """A channel of the file: topic, message type (its schema's name) and encoding."""

    topic: str
    msgtype: str
    encoding: str


@dataclass
class _Chunk:
    offset: int          # file offset of the (compressed) records
    size: int            # compressed size
    compression: str
    uncompressed_size: int
    crc: int


@dataclass
class McapIndex:
    """
    What a front-to-back scan found.

    ``entries`` are ``(log_time, channel_id, chunk, offset, length)`` in file order: ``chunk``
    indexes ``chunks`` (offset and length then address its decompressed records) or is -1 for a
    message outside any chunk (offset and length address the file). ``complete`` is False when
    the scan stopped at a cut or damaged record; ``problem`` then says where and why.
    """

    channels: Dict[int, McapChannel] = field(default_factory=dict)
    entries: List[Tuple[int, int, int, int, int]] = field(default_factory=list)
    chunks: List[_Chunk] = field(default_factory=list)
    complete: bool = True
    problem: str = ''


def _decompressor(compression: str) -> Callable[[bytes, int], bytes]:
    if compression == '':
        return lambda data, _: data
    if compression == 'zstd':
        try:
            from compression import zstd  # type: ignore[import-not-found]  # Python >= 3.14
        except ImportError:
            from backports import zstd  # type: ignore[import-not-found,no-redef]
        return lambda data, _: zstd.decompress(data)
    if compression == 'lz4':
        from lz4.frame import decompress  # type: ignore[import-untyped]
        return lambda data, _: decompress(data)
    raise ValueError(f'unsupported chunk compression {compression!r}')


def decompress_chunk(data: bytes, compression: str, size: int, crc: int) -> bytes:
    """Return a chunk's records; ``ValueError`` unless they decompress to ``size`` and ``crc``."""
    decompress = _decompressor(compression)
    try:
        raw = decompress(data, size)
    except Exception as exc:  # zstd and lz4 raise their own error types
        raise ValueError(f'{compression} data does not decompress: {exc}') from None
    if len(raw) != size:
        raise ValueError(f'decompressed to {len(raw)} bytes, not {size}')
    if crc and crc32(raw) != crc:
        raise ValueError('checksum mismatch')
    return raw


def _string(buf: bytes, pos: int) -> Tuple[str, int]:
    (n,) = struct.unpack_from('<I', buf, pos)
    end = pos + 4 + n
    if end > len(buf):
        raise ValueError('string runs past its record')
    return buf[pos + 4:end].decode(), end


class _Scan:
    """One front-to-back pass; fills an :class:`McapIndex`."""

    def __init__(self) -> None:
        self.index = McapIndex()
        self.schemas: Dict[int, str] = {}

    def schema(self, body: bytes) -> None:
        (sid,) = struct.unpack_from('<H', body, 0)
        name, _ = _string(body, 2)
        self.schemas[sid] = name

    def channel(self, body: bytes) -> None:
        cid, sid = struct.unpack_from('<HH', body, 0)
        topic, pos = _string(body, 4)
        encoding, _ = _string(body, pos)
        # schema 0 is "no schema": such a channel has no message type to decode it with
        if sid in self.schemas:
            self.index.channels[cid] = McapChannel(topic, self.schemas[sid], encoding)

    def records(self, buf: bytes, chunk: int) -> None:
        """Index the records of decompressed chunk number ``chunk`` (offsets inside ``buf``)."""
        pos = 0
        while pos < len(buf):
            if pos + _RECORD.size > len(buf):
                raise ValueError('record header runs past the chunk')
            op, length = _RECORD.unpack_from(buf, pos)
            start = pos + _RECORD.size
            end = start + length
            if end > len(buf):
                raise ValueError('record runs past the chunk')
            self.record(op, buf[start:end], start, chunk)
            pos = end

    def record(self, op: int, body: bytes, offset: int, chunk: int) -> None:
        if op == OP_SCHEMA:
            self.schema(body)
        elif op == OP_CHANNEL:
            self.channel(body)
        elif op == OP_MESSAGE:
            if len(body) < _MESSAGE.size:
                raise ValueError('message record shorter than its fields')
            cid, _, log_time, _ = _MESSAGE.unpack_from(body, 0)
            self.index.entries.append((log_time, cid, chunk, offset + _MESSAGE.size,
                                       len(body) - _MESSAGE.size))


def _read_record(bio: BinaryIO, pos: int, size: int) -> Tuple[Optional[int], bytes, str]:
    """Return ``(op, body, '')`` of the record at ``pos``, or ``(None, b'', why)`` when cut."""
    head = bio.read(_RECORD.size)
    if len(head) < _RECORD.size:
        return None, b'', f'file ends inside a record header at byte {pos}' if head else ''
    op, length = _RECORD.unpack(head)
    if pos + _RECORD.size + length > size:
        name = _NAMES.get(op, f'0x{op:02x}')
        return None, b'', (f'file ends inside the {name} record at byte {pos} '
                           f'({size - pos} of its {_RECORD.size + length} bytes are there)')
    return op, bio.read(length), ''


def scan_mcap(path: Path) -> McapIndex:
    """
    Scan ``path`` front to back and index the messages of its complete records.

    Raises ``McapScanError`` when the file does not start like an mcap file and ``OSError``
    when it cannot be read.
    """
    scan = _Scan()
    index = scan.index
    size = path.stat().st_size
    with path.open('rb') as bio:
        magic = bio.read(len(MAGIC))
        if magic != MAGIC[:len(magic)]:
            raise McapScanError('not an mcap file (its first bytes are not the mcap magic)')
        if len(magic) < len(MAGIC):
            index.complete = False
            index.problem = 'file is empty' if not magic else 'file ends inside the mcap magic'
            return index
        pos = len(MAGIC)
        seen_header = False
        while True:
            op, body, cut = _read_record(bio, pos, size)
            if op is None:
                # a file that simply stops after a whole record still lacks its footer
                index.complete = False
                index.problem = cut or f'file ends at byte {pos} without a footer'
                return index
            if not seen_header:
                if op != OP_HEADER:
                    raise McapScanError('not an mcap file (no header record after the magic)')
                seen_header = True
            elif op in (OP_DATA_END, OP_FOOTER):
                return index   # the data section is over: what follows is the summary
            elif op == OP_CHUNK:
                n_chunks, n_entries = len(index.chunks), len(index.entries)
                try:
                    scan.records(_chunk_records(body, pos, index), n_chunks)
                except (ValueError, struct.error) as exc:
                    # a chunk counts whole or not at all
                    del index.chunks[n_chunks:]
                    del index.entries[n_entries:]
                    index.complete = False
                    index.problem = f'chunk at byte {pos} is damaged ({exc})'
                    return index
            else:
                try:
                    scan.record(op, body, pos + _RECORD.size, -1)
                except (ValueError, struct.error, UnicodeDecodeError) as exc:
                    index.complete = False
                    index.problem = f'record at byte {pos} is damaged ({exc})'
                    return index
            pos += _RECORD.size + len(body)


def _chunk_records(body: bytes, pos: int, index: McapIndex) -> bytes:
    """Register the chunk record ``body`` (at file byte ``pos``) and return its records."""
    try:
        _, _, usize, crc = _CHUNK.unpack_from(body, 0)
        compression, at = _string(body, _CHUNK.size)
        (csize,) = struct.unpack_from('<Q', body, at)
    except (struct.error, UnicodeDecodeError) as exc:
        raise ValueError(f'bad chunk fields: {exc}') from None
    at += 8
    if at + csize > len(body):
        raise ValueError('compressed records run past the chunk record')
    index.chunks.append(_Chunk(pos + _RECORD.size + at, csize, compression, usize, crc))
    return decompress_chunk(body[at:at + csize], compression, usize, crc)


def read_messages(path: Path, index: McapIndex, channels: Set[int]
                  ) -> Iterator[Tuple[int, int, bytes]]:
    """
    Yield ``(channel_id, log_time, data)`` of ``channels`` in timestamp order (file order on ties).

    Each chunk is decompressed once and dropped after its last message is yielded, so memory
    holds only the chunks whose time ranges overlap.
    """
    order = sorted((e for e in enumerate(index.entries) if e[1][1] in channels),
                   key=lambda e: (e[1][0], e[0]))
    last_use: Dict[int, int] = {}
    for i, (_, entry) in enumerate(order):
        last_use[entry[2]] = i
    cache: Dict[int, bytes] = {}
    with path.open('rb') as bio:
        for i, (_, (log_time, cid, chunk, offset, length)) in enumerate(order):
            if chunk < 0:
                bio.seek(offset)
                data = bio.read(length)
            else:
                raw = cache.get(chunk)
                if raw is None:
                    info = index.chunks[chunk]
                    bio.seek(info.offset)
                    raw = decompress_chunk(bio.read(info.size), info.compression,
                                           info.uncompressed_size, info.crc)
                    cache[chunk] = raw
                data = raw[offset:offset + length]
                if last_use[chunk] == i:
                    del cache[chunk]
            yield cid, log_time, data
