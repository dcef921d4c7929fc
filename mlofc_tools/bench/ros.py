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
The running node under rising image rates: drops, throughput and latency over DDS.

``mlofc_node`` runs in its own process on its own ``ROS_DOMAIN_ID`` (localhost discovery). It is
started through a thin wrapper (``python -m mlofc_tools.bench.ros --child STATS -- --ros-args
...``) that builds the same :class:`~mlofc_ros.node.MlofcNode` as the console script and spins
it the same way, and in addition writes the node's own counters (``stats``: received,
processed, dropped by its bounded queue, skipped, errors; plus the frames pending) to a JSON
file ten times a second, so drops are the node's count, not a guess.

This process renders 640x480 frames (boxes + background), then for each rate publishes
``--frames`` mono8 ``sensor_msgs/Image`` (sensor-data QoS, like a camera driver; a
``CameraInfo`` before each image) on a steady clock, stamped with the wall time at publication,
waits for the node to drain, and counts the ``~/segments`` messages received (reliable QoS).
Latency = reception wall time - image stamp (both clocks of this process). A rate is kept up
with when every published frame is answered and the node dropped none.

Run ``python -m mlofc_tools.bench ros``; writes ``README.md`` and ``ros.png`` to
``docs/results/ros/``.
"""
import argparse
import contextlib
import json
import math
import os
import pathlib
import sys
import tempfile
import threading
import time
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Tuple, Union

# importing any mlofc_ros module first runs mlofc_ros/__init__ (one BLAS thread)
from mlofc_tools.bench import common
import numpy as np

NODE_NAME = 'mlofc'
IMAGE_TOPIC = '/bench/image_raw'
INFO_TOPIC = '/bench/camera_info'
SEG_TOPIC = f'/{NODE_NAME}/segments'
DEFAULT_RATES = '2,3,5,10,15,20,30,45,60,90,120,150'


# --- the node side -------------------------------------------------------------------------

def _write_json(path: str, data: Dict[str, Any]) -> None:
    tmp = path + '.tmp'
    with open(tmp, 'w') as f:
        json.dump(data, f)
    os.replace(tmp, path)


def proc_times_path(stats_path: Union[str, pathlib.Path]) -> str:
    """Return the side file of the per-frame process times, one ``wall cpu`` (ms) line each."""
    return str(stats_path) + '.proc'


def read_proc_times(stats_path: Union[str, pathlib.Path], start: int, stop: int
                    ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the process wall and CPU ms (each ``(stop - start,)`` at most) of solved frames.

    Frames ``start .. stop - 1`` in the order the node solved them (``n_proc`` of two stats
    dumps); empty before the node has written any.
    """
    try:
        lines = pathlib.Path(proc_times_path(stats_path)).read_text().splitlines()[start:stop]
    except OSError:
        lines = []
    vals = np.array([ln.split() for ln in lines], dtype=float).reshape(-1, 2)
    return vals[:, 0], vals[:, 1]


def child_main(stats_path: str, ros_args: Sequence[str]) -> int:
    """
    Run ``MlofcNode`` like ``mlofc_node`` does, dumping ``node.stats`` to ``stats_path``.

    The process time of every solved frame is appended to :func:`proc_times_path` as it is
    dumped: a JSON dump of the whole history every 0.1 s took the executor thread about a
    fifth of its time (and the lock from the workers) by the end of a run.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from mlofc_ros.node import MlofcNode

    rclpy.init(args=['mlofc_node', *ros_args])
    node = None
    proc_wall: List[float] = []
    proc_cpu: List[float] = []
    written = 0
    open(proc_times_path(stats_path), 'w').close()

    def dump() -> None:
        nonlocal written
        if node is None:
            return
        n = min(len(proc_wall), len(proc_cpu))     # the solver worker appends wall first
        if n > written:
            with open(proc_times_path(stats_path), 'a') as f:
                f.writelines(f'{w!r} {c!r}\n' for w, c in zip(proc_wall[written:n],
                                                              proc_cpu[written:n]))
            written = n
        # after the times: a reader that sees n_proc finds its lines
        _write_json(stats_path, dict(node.stats, pending=node.pending_frames(),
                                     time=time.time(), n_proc=n))

    observe_cpu: Dict[float, float] = {}      # stamp -> CPU ms of the tracking worker

    def timed_observe(observe: Any) -> Any:
        def wrapper(*a: Any, **kw: Any) -> Any:
            c = time.thread_time()
            obs = observe(*a, **kw)
            observe_cpu[obs.stamp] = 1e3 * (time.thread_time() - c)
            return obs
        return wrapper

    def timed_solve(solve: Any) -> Any:
        # a published frame's process time: its observe (tracking worker) + its solve
        def wrapper(obs: Any) -> Any:
            t, c = time.perf_counter(), time.thread_time()
            try:
                return solve(obs)
            finally:
                proc_wall.append(obs.elapsed_ms + 1e3 * (time.perf_counter() - t))
                for k in [k for k in list(observe_cpu) if k < obs.stamp]:
                    observe_cpu.pop(k, None)          # frames tracked, not solved
                proc_cpu.append(observe_cpu.pop(obs.stamp, math.nan)
                                + 1e3 * (time.thread_time() - c))
        return wrapper
    try:
        node = MlofcNode()
        pipe = node._pipeline        # time Pipeline.observe + solve inside the node
        pipe.observe, pipe.solve = timed_observe(pipe.observe), timed_solve(pipe.solve)
        node.create_timer(0.1, dump)
        dump()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            dump()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


# --- the bench side ------------------------------------------------------------------------

class BenchError(Exception):
    """The benchmark cannot go on (node did not start, died, ...)."""


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='python -m mlofc_tools.bench ros',
                                 description='Node drops and latency at rising image rates.')
    ap.add_argument('--rates', default=DEFAULT_RATES, help=f'Hz, comma separated '
                    f'({DEFAULT_RATES})')
    ap.add_argument('--frames', type=int, default=100, help='frames published per rate (100)')
    ap.add_argument('--size', default='640x480', help='WxH (640x480)')
    ap.add_argument('--boxes', type=int, default=2, help='moving boxes (2) + background')
    ap.add_argument('--queue-size', type=int, default=None,
                    help='node queue_size parameter (default: the node default)')
    ap.add_argument('--startup-timeout', type=float, default=90.0)
    ap.add_argument('--drain-timeout', type=float, default=60.0,
                    help='max seconds to wait for the node to finish a rate')
    ap.add_argument('--domain-id', type=int, default=None)
    ap.add_argument('--quick', action='store_true',
                    help='smoke run: 5 and 10 Hz, 4 frames of 320x240')
    ap.add_argument('--out', default=None, help='output folder (default docs/results/ros)')
    args = ap.parse_args(list(argv))
    if args.quick:
        args.rates, args.frames, args.size = '5,10', 4, '320x240'
    args.rate_list = [float(r) for r in args.rates.split(',') if r.strip()]
    w, _, h = args.size.lower().partition('x')
    args.wh = (int(w), int(h))
    if not args.rate_list or min(args.rate_list) <= 0 or args.frames < 1:
        ap.error('rates must be > 0 and --frames >= 1')
    return args


def read_stats(path: pathlib.Path) -> Optional[Dict[str, Any]]:
    """Return the node's last stats dump, or None before the first one."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


class Bench:
    """The publishing/receiving side; one instance per run (owns an rclpy context)."""

    def __init__(self, args: argparse.Namespace, domain: int) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import CameraInfo, Image, PointCloud2

        self.args = args
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('mlofc_bench_ros', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.image_pub = self.node.create_publisher(Image, IMAGE_TOPIC, qos_profile_sensor_data)
        self.info_pub = self.node.create_publisher(CameraInfo, INFO_TOPIC,
                                                   qos_profile_sensor_data)
        self.lock = threading.Lock()
        self.received: Dict[int, float] = {}      # image stamp ns -> reception wall time
        self.node.create_subscription(PointCloud2, SEG_TOPIC, self._on_segments,
                                      QoSProfile(depth=500,
                                                 reliability=ReliabilityPolicy.RELIABLE))
        self._spin = threading.Thread(target=self._spin_loop, daemon=True)
        self._stop = threading.Event()
        self._spin.start()
        self.Image, self.CameraInfo = Image, CameraInfo

    def _spin_loop(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: B902 (shutdown races)
                if self._stop.is_set():
                    return
                raise

    def _on_segments(self, msg: Any) -> None:
        now = time.time()
        key = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        with self.lock:
            self.received[key] = now

    def close(self) -> None:
        import rclpy
        self._stop.set()
        self._spin.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)

    def make_messages(self, frames: Sequence[np.ndarray], camera: Any) -> None:
        """Pre-build the Image (mono8) and CameraInfo messages; stamps are set on publishing."""
        self.images = []
        for f in frames:
            m = self.Image()
            m.header.frame_id = 'camera'
            m.height, m.width = int(f.shape[0]), int(f.shape[1])
            m.encoding, m.is_bigendian, m.step = 'mono8', 0, int(f.shape[1])
            m.data = np.ascontiguousarray(f).tobytes()
            self.images.append(m)
        info = self.CameraInfo()
        info.header.frame_id = 'camera'
        info.height, info.width = int(frames[0].shape[0]), int(frames[0].shape[1])
        info.distortion_model = 'plumb_bob'
        info.d = [0.0] * 5
        info.k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
        info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        info.p = [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0,
                  0.0, 0.0, 1.0, 0.0]
        self.info = info

    def publish_at(self, rate: float, n: int) -> Dict[str, Any]:
        """Publish ``n`` frames at ``rate`` Hz on a steady schedule; return stamps and times."""
        period = 1.0 / rate
        stamps: List[int] = []
        sent: List[float] = []
        t_next = time.perf_counter()
        for i in range(n):
            delay = t_next - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            ns = time.time_ns()
            msg = self.images[i % len(self.images)]
            for m in (self.info, msg):
                m.header.stamp.sec = ns // 1_000_000_000
                m.header.stamp.nanosec = ns % 1_000_000_000
            self.info_pub.publish(self.info)
            self.image_pub.publish(msg)
            stamps.append(ns)
            sent.append(time.perf_counter())
            t_next += period
        return {'stamps': stamps, 'sent': sent}


def _wait(cond: Any, timeout: float, step: float = 0.05) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(step)
    return cond()


def run(args: argparse.Namespace, work: pathlib.Path) -> Dict[str, Any]:
    """Start the node, sweep the rates; returns the per-rate rows and run facts."""
    from mlofc_tools.demo_node import fresh_domain_id
    from mlofc_tools.render import render_sequence

    load = os.getloadavg()
    code = common.commit()            # before the node imports the code
    domain = args.domain_id if args.domain_id is not None else fresh_domain_id()
    common.eprint(f'ros: rendering {args.frames} frames {args.wh[0]}x{args.wh[1]}')
    seq = render_sequence(args.boxes, min(args.frames, 120), size=args.wh,
                          motion='camera_centre', background=True, noise_sigma=2.0, seed=0)
    stats_path = work / 'node_stats.json'
    ros_args = ['-p', f'num_bodies:={args.boxes + 1}']
    if args.queue_size is not None:
        ros_args += ['-p', f'queue_size:={args.queue_size}']
    rows: List[Dict[str, Any]] = []
    with running_node(ros_args, domain, stats_path, work / 'node.log',
                      lambda: Bench(args, domain), args.startup_timeout) as (bench, proc, startup,
                                                                             command):
        common.eprint(f'ros: node up after {startup:.1f} s (ROS_DOMAIN_ID={domain})')
        bench.make_messages(seq.frames, seq.camera)
        # warm-up (imports, first window) at a rate the node surely keeps up with
        bench.publish_at(2.0, 4)
        _drain(bench, stats_path, proc, args.drain_timeout)
        for rate in args.rate_list:
            rows.append(_one_rate(bench, stats_path, proc, rate, args))
            r = rows[-1]
            common.eprint(f'ros: {rate:g} Hz: {r["answered"]}/{r["published"]} answered, '
                          f'{r["dropped"]} dropped, latency median {r["lat_median"]:.0f} '
                          f'ms, p99 {r["lat_p99"]:.0f} ms')
    return {'rows': rows, 'domain': domain, 'startup': startup, 'load': load, 'code': code,
            'command': command, 'seq': seq}


@contextlib.contextmanager
def running_node(ros_args: Sequence[str], domain: int, stats_path: pathlib.Path,
                 log_path: pathlib.Path, make_bench: Callable[[], Bench],
                 startup_timeout: float) -> Iterator[Tuple[Bench, Any, float, List[str]]]:
    """
    Run the node (``--child``, writing ``stats_path``) on ``domain`` with ``ros_args``.

    Yields ``(bench, process, startup seconds, command)`` once the node subscribes to the
    image topic and publishes ``~/segments``; ``make_bench`` builds the publishing side (in
    this process's environment set to the domain). Raises :class:`BenchError` when the node
    does not come up in ``startup_timeout`` s. The environment is restored afterwards.
    """
    from mlofc_tools.demo_node import NodeProcess
    command = [sys.executable, '-m', 'mlofc_tools.bench.ros', '--child', str(stats_path),
               '--ros-args', '-r', f'__node:={NODE_NAME}', '-r', f'image:={IMAGE_TOPIC}',
               '-r', f'camera_info:={INFO_TOPIC}', *ros_args]
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
               ROS_AUTOMATIC_DISCOVERY_RANGE=os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE',
                                                            'LOCALHOST'),
               HOME=os.environ.get('HOME', tempfile.gettempdir()))
    saved = {k: os.environ.get(k) for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE',
                                            'HOME')}
    os.environ.update({k: env[k] for k in saved})
    bench = None
    try:
        with NodeProcess(command, env, log_path) as proc:
            bench = make_bench()
            t0 = time.monotonic()
            up = _wait(lambda: (bench.image_pub.get_subscription_count() > 0
                                and bench.node.count_publishers(SEG_TOPIC) > 0
                                and read_stats(stats_path) is not None)
                       or not proc.alive(), startup_timeout, 0.1)
            if not up or not proc.alive():
                raise BenchError(f'the node did not come up within {startup_timeout:g} s '
                                 f'(ROS_DOMAIN_ID={domain}):\n{proc.log_tail()}')
            yield bench, proc, time.monotonic() - t0, command
    finally:
        if bench is not None:
            bench.close()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _drain(bench: Bench, stats_path: pathlib.Path, proc: Any, timeout: float) -> None:
    """Wait until the node's queue is empty and no answer arrived for 0.5 s."""
    last = {'n': -1, 't': time.monotonic()}

    def idle() -> bool:
        if not proc.alive():
            raise BenchError(f'the node exited:\n{proc.log_tail()}')
        with bench.lock:
            n = len(bench.received)
        now = time.monotonic()
        if n != last['n']:
            last['n'], last['t'] = n, now
        s = read_stats(stats_path) or {}
        return s.get('pending', 1) == 0 and now - last['t'] > 0.5 and \
            now - s.get('time', 0) < 5.0 and time.time() - s.get('time', 0) < 1.0
    _wait(idle, timeout, 0.05)


def _one_rate(bench: Bench, stats_path: pathlib.Path, proc: Any, rate: float,
              args: argparse.Namespace) -> Dict[str, Any]:
    time.sleep(0.3)
    before = read_stats(stats_path) or {}
    pub = bench.publish_at(rate, args.frames)
    _drain(bench, stats_path, proc, args.drain_timeout)
    time.sleep(0.3)              # one more stats dump after the last frame
    after = read_stats(stats_path) or {}
    with bench.lock:
        got = {s: bench.received[s] for s in pub['stamps'] if s in bench.received}
    lat = np.array([1e3 * (t - s * 1e-9) for s, t in got.items()])
    sent = pub['sent']
    achieved = (len(sent) - 1) / (sent[-1] - sent[0]) if len(sent) > 1 else math.nan

    def delta(k: str) -> int:
        return int(after.get(k, 0)) - int(before.get(k, 0))
    proc_wall, proc_cpu = read_proc_times(stats_path, int(before.get('n_proc', 0)),
                                          int(after.get('n_proc', 0)))
    published = len(pub['stamps'])
    recv_times = sorted(got.values())
    span = (recv_times[-1] - recv_times[0]) if len(recv_times) > 1 else math.nan
    return {'rate': rate, 'achieved': achieved, 'published': published,
            'received': delta('received'), 'answered': len(got), 'dropped': delta('dropped'),
            'skipped': delta('skipped'), 'errors': delta('errors'),
            'lost': published - delta('received'),
            'out_rate': (len(got) - 1) / span if span and span > 0 else math.nan,
            'lat_median': float(np.median(lat)) if lat.size else math.nan,
            'lat_p99': float(np.percentile(lat, 99)) if lat.size else math.nan,
            'lat_max': float(lat.max()) if lat.size else math.nan,
            'proc_wall': float(np.median(proc_wall)) if proc_wall.size else math.nan,
            'proc_cpu': float(np.median(proc_cpu)) if proc_cpu.size else math.nan,
            'proc_max': float(proc_wall.max()) if proc_wall.size else math.nan}


def kept_up(row: Dict[str, Any]) -> bool:
    """Every published frame answered, none dropped by the node."""
    return row['dropped'] == 0 and row['answered'] == row['published']


def rate_headline(rows: Sequence[Dict[str, Any]]) -> str:
    """
    Headline line: the highest rate kept up with, at it and every lower rate (rising rows).

    When the node keeps up with every rate run, the limit is above the highest: the line says
    so instead of calling that rate the limit.
    """
    if not rows:
        return '- No rate was run.'
    best = None
    for r in rows:
        if not kept_up(r):
            break
        best = r
    if best is None:
        return f'- The node kept up with none of the rates (lowest {rows[0]["rate"]:g} Hz).'
    text = (f'- Highest rate kept up with (all frames answered, none dropped, and the same at '
            f'every lower rate): **{best["rate"]:g} Hz**; latency there median '
            f'**{best["lat_median"]:.0f} ms**, p99 {best["lat_p99"]:.0f} ms.')
    if best is rows[-1]:
        text += (' That is the highest rate run: the limit lies above it (run higher '
                 '`--rates`).')
    else:
        text += f' At {rows[rows.index(best) + 1]["rate"]:g} Hz it no longer does.'
    return text


def plot(path: pathlib.Path, rows: Sequence[Dict[str, Any]]) -> None:
    fig, (a, b) = common.new_figure(2)
    rates = [r['rate'] for r in rows]
    common.plot_series(a, rates, {
        'answered %': [100.0 * r['answered'] / r['published'] for r in rows],
        'dropped by node %': [100.0 * r['dropped'] / r['published'] for r in rows]},
        'image rate (Hz)', '% of published frames', 'answered / dropped')
    a.legend(fontsize=7)
    common.plot_series(b, rates, {'median': [r['lat_median'] for r in rows],
                                  'p99': [r['lat_p99'] for r in rows]},
                       'image rate (Hz)', 'stamp -> ~/segments (ms)', 'latency')
    b.set_yscale('log')
    common.save_figure(fig, path, legend_ax=b)


def build_report(args: argparse.Namespace, argv: Sequence[str], res: Dict[str, Any],
                 wall: float) -> str:
    from mlofc_ros import params
    rows = res['rows']
    queue = args.queue_size if args.queue_size is not None else \
        params.PARAMS['queue_size'].default
    head = common.run_header(
        'ROS: the running node at rising image rates', common.command_line('ros', argv),
        {'Node': f'separate process, `MlofcNode` via `python -m mlofc_tools.bench.ros --child` '
                 f'(stats dump), `num_bodies:={args.boxes + 1}`, `queue_size` {queue}, other '
                 f'parameters default; fresh ROS_DOMAIN_ID, localhost discovery; started in '
                 f'{res["startup"]:.1f} s',
         'Input': f'{args.wh[0]}x{args.wh[1]} rendered boxes + background, mono8, '
                  f'{args.frames} frames per rate, sensor-data QoS, CameraInfo before each '
                  'image; 4 warm-up frames at 2 Hz not counted',
         'Wall time': f'{wall:.0f} s on a shared 2-core machine (bench and node compete for it)',
         'Load average (1 min) at start / end':
             f'{res["load"][0]:.1f} / {os.getloadavg()[0]:.1f}'}, res['code'])
    fastest = max((r['out_rate'] for r in rows if math.isfinite(r['out_rate'])),
                  default=math.nan)
    lines = [head, '## Headline', '', rate_headline(rows)]
    cpu = np.array([r['proc_cpu'] for r in rows], dtype=float)
    wall_ms = np.array([r['proc_wall'] for r in rows], dtype=float)
    cpu_med = float(np.nanmedian(cpu)) if np.isfinite(cpu).any() else math.nan
    wall_med = float(np.nanmedian(wall_ms)) if np.isfinite(wall_ms).any() else math.nan
    lines += [f'- Highest answer rate seen: {fastest:.1f} segments messages/s (throughput '
              'limit: above it the node drops the stalest queued frames).',
              f'- Inside the node a published frame took {wall_med:.0f} ms wall but '
              f'{cpu_med:.0f} ms of worker-thread CPU (`Pipeline.observe` in the tracking '
              'worker + `Pipeline.solve` in the solver worker; medians over the rates): the '
              f'node waited for a core (or the GIL) {"most" if wall_med > 2 * cpu_med else "part"}'
              ' of the time on this shared machine. Were it alone on a core, '
              f'the CPU time alone would allow about {1e3 / cpu_med:.0f} Hz (an estimate, not '
              'measured here).', '',
              '## Per rate', '',
              common.markdown_table(
                  ['rate Hz', 'achieved Hz', 'published', 'node received', 'answered',
                   'dropped (node)', 'lost before node', 'skipped', 'answers/s',
                   'latency median ms', 'latency p99 ms', 'latency max ms',
                   'process wall ms', 'process CPU ms', 'process wall max ms', 'kept up'],
                  [[r['rate'], r['achieved'], r['published'], r['received'], r['answered'],
                    r['dropped'], r['lost'], r['skipped'], r['out_rate'], r['lat_median'],
                    r['lat_p99'], r['lat_max'], r['proc_wall'], r['proc_cpu'],
                    r['proc_max'], 'yes' if kept_up(r) else 'no']
                   for r in rows]),
              "- published: images sent; node received / dropped / skipped: the node's own "
              'counters (`MlofcNode.stats`) over the rate (dropped: by its bounded queue, or '
              'tracked but replaced by a newer frame before the solver was free); lost before '
              'node = published - received (best-effort transport); answered: `~/segments` '
              'messages received for those stamps.',
              '- latency: wall time at `~/segments` reception - image stamp (= wall time at '
              "publication), over the answered frames; it includes waiting in the node's "
              'queue, decode, tracking, waiting for the solver, solving, packing and DDS both '
              'ways.',
              "- process wall / CPU ms: median over the rate of a published frame's "
              '`Pipeline.observe` (tracking worker) + `Pipeline.solve` (solver worker) inside '
              "the node, wall time and the two workers' CPU time (`time.thread_time`); wall "
              'well above CPU means the node waited for a core (shared machine) or the GIL. '
              'When the node drops frames before tracking, the frames it does track are '
              'farther apart: larger motion between them makes tracking and solving costlier '
              'per frame. `process wall max`: the slowest frame (a latency max far above it '
              'was spent outside the two calls: queues, transport, scheduling).', '',
              '![drops and latency](ros.png)', '']
    return '\n'.join(lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(argv or [])
    if argv[:1] == ['--child']:
        rest = argv[2:]
        if rest[:1] == ['--']:
            rest = rest[1:]
        return child_main(argv[1], rest)
    args = parse_args(argv)
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix='mlofc_bench_ros_') as tmp:
        try:
            res = run(args, pathlib.Path(tmp))
        except BenchError as exc:
            print(f'bench ros: error: {exc}', file=sys.stderr)
            return 1
    report = build_report(args, argv, res, time.monotonic() - t0)
    plot(common.results_dir('ros', args.out) / 'ros.png', res['rows'])
    common.write_report('ros', args.out, report)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
