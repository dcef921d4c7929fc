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
Read and write rosbag2 bags (mcap and sqlite3) with ``rosbags``, without a ROS install.

Messages stay CDR bytes end to end: the bytes in a bag are exactly what DDS carries, so
``rclpy.serialization.deserialize_message(raw, cls)`` turns them into rclpy messages and
``Publisher.publish(raw)`` sends them unchanged. Writing accepts bytes, rclpy messages or
``rosbags`` messages.

Example::

    with BagWriter('out_bag') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.write('/chatter', 0, raw_cdr_bytes)
    with BagReader('out_bag') as bag:
        for msg in bag.messages():
            print(msg.topic, msg.timestamp_ns, len(msg.rawdata), msg.msgtype)
"""
from functools import lru_cache
import importlib
from pathlib import Path
import shutil
import tempfile
from types import TracebackType
from typing import (Any, Dict, Iterable, Iterator, List, NamedTuple, Optional, Sequence, Type,
                    Union)

from mlofc_ros.bag.recovery import layout, RecoveredBag, RecoveryError
from mlofc_ros.camera import CameraModel
import numpy as np
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
from rosbags.typesys.store import Typestore

#: Storage plugins this module writes; both are read back (``Reader`` detects the format).
STORAGES = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
#: Default storage, as ``ros2 bag record`` uses on Jazzy.
DEFAULT_STORAGE = 'mcap'

IMAGE_TYPE = 'sensor_msgs/msg/Image'
CAMERA_INFO_TYPE = 'sensor_msgs/msg/CameraInfo'

PathLike = Union[str, Path]


class BagError(Exception):
    """A bag could not be read or written; the message names the file and the problem."""


class BagMessage(NamedTuple):
    """One recorded message: ``rawdata`` is CDR bytes of ``msgtype`` (``pkg/msg/Name``)."""

    topic: str
    timestamp_ns: int
    rawdata: bytes
    msgtype: str


def _qos(reliability: QosReliability, depth: int) -> Qos:
    zero = QosTime(0, 0)  # 0 = unspecified, i.e. the rmw default (infinite)
    return Qos(QosHistory.KEEP_LAST, depth, reliability, QosDurability.VOLATILE, zero, zero,
               QosLiveliness.AUTOMATIC, zero, False)


#: Offered QoS recorded with a topic: ``sensor_data`` (best effort, as camera drivers publish)
#: or ``reliable`` (the rclpy default).
QOS_PROFILES: Dict[str, Qos] = {
    'sensor_data': _qos(QosReliability.BEST_EFFORT, 5),
    'reliable': _qos(QosReliability.RELIABLE, 10),
}


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """Return the (cached) ROS 2 Jazzy typestore: message definitions and hashes for writing."""
    return get_typestore(Stores.ROS2_JAZZY)


def message_class(msgtype: str) -> Type[Any]:
    """
    Import the rclpy message class of ``msgtype`` (``'sensor_msgs/msg/Image'``).

    Raises ``BagError`` when the interface package is not installed.
    """
    parts = msgtype.split('/')
    if len(parts) == 2:  # 'pkg/Name', as some tools write it
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise BagError(f'malformed message type {msgtype!r}; expected pkg/msg/Name')
    try:
        module = importlib.import_module(f'{parts[0]}.{parts[1]}')
        return getattr(module, parts[2])
    except (ImportError, AttributeError) as exc:
        raise BagError(f'message type {msgtype!r} is not installed ({exc})') from None


def serialize(msg: Union[bytes, bytearray, memoryview, Any], msgtype: str) -> bytes:
    """CDR bytes of ``msg``: bytes pass through; rclpy and rosbags messages are serialised."""
    if isinstance(msg, (bytes, bytearray, memoryview)):
        return bytes(msg)
    if hasattr(type(msg), 'get_fields_and_field_types'):  # an rclpy (rosidl_generator_py) class
        from rclpy.serialization import serialize_message
        return serialize_message(msg)
    try:
        return bytes(typestore().serialize_cdr(msg, msgtype))
    except Exception as exc:  # rosbags raises several types for a message it cannot encode
        raise BagError(f'cannot serialise {type(msg).__name__} as {msgtype}: {exc}') from None


def deserialize(rawdata: bytes, msgtype: str) -> Any:
    """Turn CDR bytes into an rclpy message of ``msgtype``."""
    from rclpy.serialization import deserialize_message
    return deserialize_message(rawdata, message_class(msgtype))


class BagReader:
    """
    Read a rosbag2 bag (directory with ``metadata.yaml``, or a bare ``.mcap``/``.db3`` file).

    A context manager; ``topics`` maps topic -> message type, ``messages()`` yields
    :class:`BagMessage` in timestamp order. A bag that was not closed (cut short, no
    ``metadata.yaml``, an unapplied journal) is read from its complete messages: ``incomplete``
    is then True and ``problems`` says why; with ``strict`` such a bag raises ``BagError``.
    """

    def __init__(self, path: PathLike, strict: bool = False) -> None:
        self.path = Path(path)
        self.strict = strict
        self._reader: Optional[Reader] = None
        self._recovered: Optional[RecoveredBag] = None
        #: True when the bag was not closed properly and only its complete messages are read
        self.incomplete = False
        self.problems: List[str] = []

    def open(self) -> None:  # noqa: A003 (the context-manager protocol's name)
        """Open the bag; raise ``BagError`` naming the path when it is missing or unreadable."""
        if not self.path.exists():
            raise BagError(f'{self.path}: no such bag (file or directory)')
        try:
            found = layout(self.path)
        except RecoveryError as exc:
            raise BagError(f'{self.path}: {exc}') from None
        problems = list(found.problems)
        if not problems:
            try:
                reader = Reader(self.path)
                reader.open()
                self._reader = reader
                return
            except Exception as exc:  # rosbags, sqlite, yaml and zstd all raise their own types
                # e.g. 'File end magic is invalid.': an mcap file without its summary
                problems.append(f'cannot read it whole: {str(exc).rstrip(".")}')
        self._open_recovered(found.files, problems)

    def _open_recovered(self, files: List[Path], problems: List[str]) -> None:
        try:
            recovered = RecoveredBag(files, problems)
        except RecoveryError as exc:
            raise BagError(f'{self.path}: cannot read bag: {exc}') from None
        why = '; '.join(recovered.problems)
        n = recovered.message_count
        if n == 0:
            recovered.close()
            raise BagError(f'{self.path}: cannot read bag: {why}; no complete message in it')
        if self.strict:
            recovered.close()
            raise BagError(f'{self.path}: incomplete bag: {why}; {n} complete messages could '
                           'be recovered without --strict')
        self._recovered = recovered
        self.incomplete = True
        self.problems = recovered.problems

    @property
    def message_count(self) -> int:
        """Return the number of (complete) messages."""
        return sum(self.message_counts.values())

    def close(self) -> None:
        """Close the bag (idempotent)."""
        reader, self._reader = self._reader, None
        recovered, self._recovered = self._recovered, None
        if reader is not None:
            reader.close()
        if recovered is not None:
            recovered.close()

    def __enter__(self) -> 'BagReader':
        self.open()
        return self

    def __exit__(self, exc_type: Optional[Type[BaseException]], exc: Optional[BaseException],
                 tb: Optional[TracebackType]) -> None:
        self.close()

    @property
    def reader(self) -> Reader:
        """Return the underlying, open ``rosbags`` Reader (not for an incomplete bag)."""
        if self._reader is None:
            raise BagError(f'{self.path}: bag is not open'
                           + (' with rosbags (incomplete)' if self._recovered else ''))
        return self._reader

    @property
    def topics(self) -> Dict[str, str]:
        """Topic name -> message type (``pkg/msg/Name``)."""
        if self._recovered is not None:
            return dict(self._recovered.topics)
        return {c.topic: c.msgtype for c in self.reader.connections}

    @property
    def message_counts(self) -> Dict[str, int]:
        """Topic name -> number of messages."""
        if self._recovered is not None:
            return dict(self._recovered.counts)
        counts: Dict[str, int] = {}
        for c in self.reader.connections:
            counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
        return counts

    @property
    def start_ns(self) -> int:
        """Timestamp (ns) of the first message."""
        if self._recovered is not None:
            return self._recovered.start_ns
        return int(self.reader.start_time)

    @property
    def duration_ns(self) -> int:
        """Nanoseconds between the first and the last message."""
        if self._recovered is not None:
            return self._recovered.duration_ns
        return int(self.reader.duration)

    @property
    def storage(self) -> str:
        """``'mcap'`` or ``'sqlite3'``."""
        files = [self.path] if self.path.is_file() else [*self.path.iterdir()]
        return 'mcap' if any(f.suffix == '.mcap' for f in files) else 'sqlite3'

    def topics_of_type(self, msgtype: str) -> List[str]:
        """Sorted topic names carrying ``msgtype``."""
        return sorted(t for t, m in self.topics.items() if m == msgtype)

    def messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[BagMessage]:
        """Yield the messages of ``topics`` (all when None) in timestamp order."""
        wanted = None if topics is None else set(topics)
        try:
            if self._recovered is not None:
                for topic, stamp, raw, msgtype in self._recovered.messages(wanted):
                    yield BagMessage(topic, stamp, raw, msgtype)
                return
            conns = [c for c in self.reader.connections if wanted is None or c.topic in wanted]
            if not conns:
                return
            for conn, stamp, raw in self.reader.messages(connections=conns):
                yield BagMessage(conn.topic, int(stamp), bytes(raw), conn.msgtype)
        except (BagError, GeneratorExit):
            raise
        except Exception as exc:
            raise BagError(f'{self.path}: error while reading messages: {exc}') from None


def read_bag(path: PathLike, topics: Optional[Iterable[str]] = None, strict: bool = False
             ) -> Iterator[BagMessage]:
    """Yield the messages of ``topics`` (all when None) of the bag at ``path``."""
    with BagReader(path, strict=strict) as bag:
        yield from bag.messages(topics)


class BagWriter:
    """
    Write a new rosbag2 bag (format version 9) in ``mcap`` (default) or ``sqlite3`` storage.

    A context manager. The bag is written in a hidden temporary folder next to ``path`` and
    moved into place only when it is complete, so ``path`` never holds a half-written bag (an
    existing bag there, with ``overwrite``, stays until the new one replaces it). On a clean
    exit the bag is closed with its ``metadata.yaml``; on an exception the temporary folder is
    removed. Topics must be added before writing.
    """

    def __init__(self, path: PathLike, storage: str = DEFAULT_STORAGE,
                 overwrite: bool = False) -> None:
        if storage not in STORAGES:
            raise BagError(f'{path}: unknown storage {storage!r}; expected one of '
                           f'{sorted(STORAGES)}')
        self.path = Path(path)
        self.storage = storage
        self.overwrite = overwrite
        self._writer: Optional[Writer] = None
        self._tmpdir: Optional[Path] = None
        self._connections: Dict[str, Any] = {}
        self.counts: Dict[str, int] = {}

    def _check_target(self) -> None:
        if self.path.exists():
            if not self.overwrite:
                raise BagError(f'{self.path}: output exists already, not overwriting')
            if not self.path.is_dir() or (not (self.path / 'metadata.yaml').exists()
                                          and any(self.path.iterdir())):
                raise BagError(f'{self.path}: exists and is not a bag, not overwriting')
        if not self.path.parent.is_dir():
            raise BagError(f'{self.path}: parent directory does not exist')

    def open(self) -> None:  # noqa: A003 (the context-manager protocol's name)
        """Start the bag; raise ``BagError`` if ``path`` exists (unless ``overwrite``)."""
        self._check_target()
        try:
            # same folder as the target: the final rename stays on one file system (atomic)
            self._tmpdir = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.',
                                                 suffix='.partial', dir=self.path.parent))
        except OSError as exc:
            raise BagError(f'{self.path}: cannot create bag: {exc}') from None
        # the inner folder has the final name: rosbags names the storage file after it
        writer = Writer(self._tmpdir / self.path.name, version=9,
                        storage_plugin=STORAGES[self.storage])
        try:
            writer.open()
        except Exception as exc:
            self._drop_tmpdir()
            raise BagError(f'{self.path}: cannot create bag: {exc}') from None
        self._writer = writer

    def close(self) -> None:
        """Finish the bag, write ``metadata.yaml`` and move it to ``path``."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
            if self.path.exists():
                self._check_target()   # something may have appeared there while writing
        except BaseException:
            self._drop_tmpdir()
            raise
        self._move_into_place()

    def _move_into_place(self) -> None:
        assert self._tmpdir is not None
        done = self._tmpdir / self.path.name
        old = self._tmpdir / (self.path.name + '.old')
        try:
            if self.path.exists():
                self.path.rename(old)
            done.rename(self.path)
        except OSError as exc:
            # keep the finished bag where it is: it is the result of the whole run
            raise BagError(f'{self.path}: cannot move the finished bag into place ({exc}); '
                           f'it is in {done}') from None
        self._drop_tmpdir()

    def _drop_tmpdir(self) -> None:
        tmpdir, self._tmpdir = self._tmpdir, None
        if tmpdir is not None:
            shutil.rmtree(tmpdir, ignore_errors=True)

    def abort(self) -> None:
        """Drop the half-written bag (``path`` is left as it was)."""
        writer, self._writer = self._writer, None
        try:
            if writer is not None:
                writer.abort()
        finally:
            self._drop_tmpdir()

    def __enter__(self) -> 'BagWriter':
        self.open()
        return self

    def __exit__(self, exc_type: Optional[Type[BaseException]], exc: Optional[BaseException],
                 tb: Optional[TracebackType]) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def add_topic(self, topic: str, msgtype: str, qos: Union[str, Qos] = 'reliable') -> None:
        """
        Register ``topic`` of ``msgtype`` with an offered QoS (name in :data:`QOS_PROFILES`).

        Adding a topic again with the same type is a no-op; another type raises ``BagError``.
        """
        if self._writer is None:
            raise BagError(f'{self.path}: bag is not open')
        if topic in self._connections:
            if self._connections[topic].msgtype != msgtype:
                raise BagError(f'{self.path}: topic {topic} already has type '
                               f'{self._connections[topic].msgtype}, not {msgtype}')
            return
        profile = QOS_PROFILES[qos] if isinstance(qos, str) else qos
        try:
            conn = self._writer.add_connection(topic, msgtype, typestore=typestore(),
                                               offered_qos_profiles=[profile])
        except KeyError:
            raise BagError(f'{self.path}: message type {msgtype} unknown to the ROS 2 Jazzy '
                           'typestore') from None
        self._connections[topic] = conn
        self.counts[topic] = 0

    def write(self, topic: str, timestamp_ns: int, msg: Any) -> None:
        """
        Append ``msg`` (CDR bytes, rclpy or rosbags message) to ``topic`` at ``timestamp_ns``.

        ``timestamp_ns`` is the record (log) time in nanoseconds.
        """
        if self._writer is None:
            raise BagError(f'{self.path}: bag is not open')
        conn = self._connections.get(topic)
        if conn is None:
            raise BagError(f'{self.path}: topic {topic} was not added before writing')
        if timestamp_ns < 0:
            raise BagError(f'{self.path}: negative timestamp {timestamp_ns} on {topic}')
        self._writer.write(conn, int(timestamp_ns), serialize(msg, conn.msgtype))
        self.counts[topic] += 1

    def write_message(self, msg: BagMessage) -> None:
        """Copy a :class:`BagMessage` (adding its topic on first use)."""
        self.add_topic(msg.topic, msg.msgtype)
        self.write(msg.topic, msg.timestamp_ns, msg.rawdata)


def stamp_ns(seconds: float) -> int:
    """Seconds (float) -> integer nanoseconds, rounded."""
    return int(round(float(seconds) * 1e9))


def _header(stamp: int, frame_id: str) -> Any:
    types = typestore().types
    time = types['builtin_interfaces/msg/Time'](sec=stamp // 10**9, nanosec=stamp % 10**9)
    return types['std_msgs/msg/Header'](stamp=time, frame_id=frame_id)


def image_cdr(frame: np.ndarray, stamp: int, frame_id: str = 'camera') -> bytes:
    """
    CDR bytes of a ``sensor_msgs/Image`` holding ``frame`` (H, W) uint8 as ``mono8``.

    ``stamp`` is the header stamp in nanoseconds.
    """
    frame = np.asarray(frame)
    if frame.ndim != 2 or frame.dtype != np.uint8:
        raise ValueError(f'frame must be (H, W) uint8, got {frame.shape} {frame.dtype}')
    h, w = frame.shape
    msg = typestore().types[IMAGE_TYPE](
        header=_header(stamp, frame_id), height=h, width=w, encoding='mono8', is_bigendian=0,
        step=w, data=np.ascontiguousarray(frame).reshape(-1))
    return bytes(typestore().serialize_cdr(msg, IMAGE_TYPE))


def camera_info_cdr(camera: CameraModel, width: int, height: int, stamp: int,
                    frame_id: str = 'camera') -> bytes:
    """CDR bytes of a ``sensor_msgs/CameraInfo`` for ``camera`` (k, d, distortion_model, p)."""
    types = typestore().types
    fx, fy, cx, cy = camera.intrinsics
    k = np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0])
    p = np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    roi = types['sensor_msgs/msg/RegionOfInterest'](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    msg = types[CAMERA_INFO_TYPE](
        header=_header(stamp, frame_id), height=int(height), width=int(width),
        distortion_model=camera.distortion_model or 'plumb_bob',
        d=np.asarray(camera.d, dtype=np.float64), k=k, r=np.eye(3).reshape(-1), p=p,
        binning_x=0, binning_y=0, roi=roi)
    return bytes(typestore().serialize_cdr(msg, CAMERA_INFO_TYPE))


def write_image_bag(path: PathLike, frames: Sequence[np.ndarray], stamps: Sequence[float],
                    camera: Optional[CameraModel], frame_id: str = 'camera',
                    image_topic: str = '/camera/image_raw',
                    info_topic: str = '/camera/camera_info', storage: str = DEFAULT_STORAGE,
                    overwrite: bool = False) -> Path:
    """
    Write ``frames`` ((H, W) uint8) as mono8 images, each preceded by its CameraInfo.

    ``stamps`` are seconds (header stamp and record time; must be >= 0). With ``camera`` None
    no CameraInfo topic is written. Returns the bag path.
    """
    if len(frames) != len(stamps):
        raise ValueError(f'{len(frames)} frames but {len(stamps)} stamps')
    with BagWriter(path, storage=storage, overwrite=overwrite) as bag:
        if camera is not None:
            bag.add_topic(info_topic, CAMERA_INFO_TYPE, 'reliable')
        bag.add_topic(image_topic, IMAGE_TYPE, 'sensor_data')
        for frame, seconds in zip(frames, stamps):
            t = stamp_ns(seconds)
            if camera is not None:
                h, w = np.shape(frame)[:2]
                bag.write(info_topic, t, camera_info_cdr(camera, w, h, t, frame_id))
            bag.write(image_topic, t, image_cdr(frame, t, frame_id))
    return Path(path)
