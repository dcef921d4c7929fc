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
The ROS 2 node: a shell around :class:`mlofc_ros.pipeline.Pipeline`.

Topics (relative names, remap as usual)::

    sub  image               sensor_msgs/Image              sensor-data QoS (best effort)
    sub  camera_info         sensor_msgs/CameraInfo         sensor-data QoS
    pub  ~/segments          sensor_msgs/PointCloud2        one per tracked image (see below)
    pub  ~/body_<i>/twist    geometry_msgs/TwistWithCovarianceStamped, i = 0..num_bodies-1
    pub  ~/debug_image       sensor_msgs/Image bgr8         if publish_debug_image or subscribed
    pub  /diagnostics        diagnostic_msgs/DiagnosticArray  1 Hz, see below

Every output carries the input image's header (stamp, camera optical frame). A twist is
published only for a body solved in that frame (finite angular velocity and covariance, at
least ``pipeline.MIN_BODY_TRACKS`` tracks: a twist is withheld rather than invented). Frames
with an undecodable image or a duplicate stamp are skipped (no output, throttled warning); a
processed frame without lines still gets its (empty) ``~/segments`` cloud. A stamp going back
(bag loop) restarts tracks and window, a gap of ``max_frame_gap`` intervals the window (the
frames the node dropped itself are no gap: their count goes with the next frame). A bad
camera_info (K zero or non-finite, wrong D length, unknown distortion model) is warned about
once per change and ignored: ``focal_length`` is used, or the focal length estimated.

``/diagnostics`` carries one ``DiagnosticStatus`` named ``mlofc: pipeline`` (``ns/mlofc:
pipeline`` in a namespace; hardware_id = the image frame_id) at 1 Hz (steady clock): rate of
processed frames (Hz), tracked lines, window fill, frames received/processed/dropped/skipped, the
focal length (px) and its state (``given``; ``estimated +-x%``, known within 10%; ``not
observable +-x%``), the last problem and its age; level WARN while a problem is less than
:attr:`MlofcNode.problem_hold` seconds old, OK otherwise. Without a camera model the focal
length is estimated from the scene and refined as long as the node runs
(:class:`mlofc_ros.solver.focal.FocalEstimate`); the log says once when it becomes observable
(within 10%) and once when it is not (a still scene, bodies that only translate), and the
twists' covariances carry its uncertainty.

The subscription callback only queues the image (a bounded queue of ``queue_size`` frames that
drops the stalest frame), so the executor is never blocked by the work and any executor
(``rclpy.spin``, a MultiThreadedExecutor, ...) can host the node. The tracking worker
decodes every queued image, tracks its lines and adds them to the window
(:meth:`Pipeline.observe`). A fast solve (the last one under :data:`INLINE_SOLVE_S`) follows in
the same thread (:meth:`Pipeline.solve`, then publishing): so does the default method,
``auto``, until its rotation model misfits the scene and it moves to ``general``
(:mod:`mlofc_ros.method_choice`; logged once, the solver then placed as after a change of
``method``). A slow method's
(:attr:`mlofc_ros.solver.Method.slow`: 1-3 s per window) goes to a solver worker, which
segments the newest window it has not solved yet while the tracking worker goes on: the
tracker still sees every frame, so its tracks survive. With ``solver_process`` (the default)
that worker hands the window to a child process (:class:`mlofc_ros.solve_process.SolveProcess`)
and waits: the solver gets a core of its own instead of half the interpreter. The child
steps the window from the running fit (20-100 ms) and runs the searches and full solves
the method asks for in one more child, a solver lane (:mod:`mlofc_ros.lane`), whose answer
becomes the running fit when it comes back; a frame it cannot step is answered from the
running fit as below (counted ``unsolved``, not processed). Of the frames
tracked while the solver was busy it solves the newest next; the others (``unsolved`` in
``stats``, counted as dropped) are answered from the running fit (:meth:`Pipeline.carry`):
their ``~/segments`` cloud gives each segment the body its track had at the last solve (NaN
residuals; ``carried`` in ``stats``), and no twist (only a solve measures one). The clouds'
stamps only increase, so the frame being solved is answered from the running fit too when a
newer frame is: its solve then publishes its twists but not its cloud (``late``). Every
tracked frame gets a cloud.
Parameters: see :mod:`mlofc_ros.params` (``ros2 param describe /mlofc <name>``); all can be
changed at run time, invalid values are rejected with the reason and the old value kept. Write
doubles as ``-p focal_length:=500.0`` (``:=500`` is accepted too: doubles are declared with
dynamic typing and integers converted).

Run: ``ros2 run mlofc_ros mlofc_node --ros-args -r image:=/cam/image_raw -p num_bodies:=3``.
"""
from collections import deque
import math
import re
import signal
import threading
import time
from typing import Any, Deque, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TwistWithCovarianceStamped
from mlofc_ros import params as P
from mlofc_ros.camera import CameraModel
from mlofc_ros.image import image_msg_to_gray
from mlofc_ros.messages.debug import draw_debug
from mlofc_ros.method_choice import AUTO, TRANSLATION_METHOD
from mlofc_ros.pipeline import FrameResult, Observation, Pipeline, window_frames
from mlofc_ros.ros_messages import (camera_info_size, camera_model_from_info, debug_image_msg,
                                    segments_msg, stamp_to_seconds, twist_msg)
from mlofc_ros.solve_process import SolveProcess, SolverProcessEnded, SolverProcessError
from mlofc_ros.solver import get_method
import numpy as np
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

#: Reliable output QoS: keeps up to this many messages per topic for slow subscribers.
OUTPUT_DEPTH = 10
#: Seconds between two ``/diagnostics`` messages.
DIAGNOSTICS_PERIOD = 1.0
#: Default seconds a problem keeps the diagnostic level at WARN.
PROBLEM_HOLD = 5.0
#: The tracking worker solves a frame itself when the solver worker is idle and the last
#: solve took less than this (s); otherwise the solver worker does, while tracking goes on.
INLINE_SOLVE_S = 0.03
#: After this many solver child processes in a row ended before a solve came back, the node
#: solves in its own process (``solver_process``).
REMOTE_ENDED_MAX = 3


#: Most kinds of problem remembered for throttling (a flood of new kinds restarts the table).
MAX_PROBLEM_KINDS = 256


def problem_kind(text: str) -> str:
    """Return ``text`` with numbers and quoted values blanked: the kind of a problem."""
    return re.sub(r"'[^']*'|\"[^\"]*\"|\d+", '#', text)


def focal_state(r: FrameResult) -> Optional[str]:
    """Return ``'given'``, ``'estimated'`` (within 10%) or ``'not observable'`` (None: no f)."""
    if not (math.isfinite(r.focal_length) and r.focal_log_sigma >= 0):
        return None
    if r.focal_log_sigma == 0:
        return 'given'
    return 'estimated' if r.focal_observable else 'not observable'


def focal_text(r: Optional[FrameResult]) -> str:
    """Return the focal length's state for ``/diagnostics``, with its relative spread."""
    state = None if r is None else focal_state(r)
    if state is None:
        return 'unknown'
    return state if state == 'given' else f'{state} +-{100.0 * r.focal_log_sigma:.1f}%'


def parameter_descriptor(spec: P.ParamSpec) -> ParameterDescriptor:
    """ROS descriptor of a table entry (doubles use dynamic typing so ``:=1`` also works)."""
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.type is int and spec.range is not None:
        d.integer_range = [IntegerRange(from_value=int(spec.range[0]),
                                        to_value=int(spec.range[1]), step=1)]
    elif spec.type is float:
        d.dynamic_typing = True      # an integer override (-p x:=1) must not kill the node
        if spec.range is not None:
            d.floating_point_range = [FloatingPointRange(from_value=float(spec.range[0]),
                                                         to_value=float(spec.range[1]),
                                                         step=0.0)]
        d.additional_constraints = 'double (integers are accepted and converted)'
    choices = spec.allowed_choices()
    if choices is not None:
        d.additional_constraints = 'one of: ' + ', '.join(choices)
    return d


class MlofcNode(Node):
    """
    Segment a camera stream into independently rotating rigid bodies (see module doc).

    ``kwargs`` go to :class:`rclpy.node.Node` (namespace, parameter_overrides, context, ...).
    """

    def __init__(self, node_name: str = 'mlofc', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.add_pre_set_parameters_callback(self._convert_parameters)
        self.add_on_set_parameters_callback(self._validate_parameters)
        for spec in P.PARAMETERS:
            self.declare_parameter(spec.name, spec.default, parameter_descriptor(spec))
        # an integer override of a double (-p focal_length:=500) is declared as given: store
        # it converted, as a runtime set is (declaration skips the pre-set callbacks)
        self.set_parameters([self.get_parameter(spec.name) for spec in P.PARAMETERS
                             if spec.type is float
                             and self.get_parameter(spec.name).type_ == Parameter.Type.INTEGER])
        values = {name: P.coerce(name, self.get_parameter(name).value) for name in P.PARAMS}
        self._values: Dict[str, Any] = values

        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        # (image, camera, camera size, frames the node dropped just before this one)
        self._queue: Deque[List[Any]] = deque()
        self._unpassed = 0      # frames received, not given to the pipeline since the last one
        self._pending: Dict[str, Any] = {}
        # method 'auto' moved to a slow method in a solve: place the solver anew (tracking
        # worker, the solver idle), as after a change of method
        self._move_solver = False
        self._camera: Optional[CameraModel] = None
        self._camera_size: Optional[Tuple[int, int]] = None
        self._last_warn: Dict[str, float] = {}
        self._problem: Optional[Tuple[float, str]] = None   # (monotonic s, text) of the last
        self._camera_problem: Optional[str] = None
        self._frame_id = ''
        #: Seconds a problem keeps ``/diagnostics`` at WARN.
        self.problem_hold = PROBLEM_HOLD
        #: frame counters: received = processed (solved and published) + dropped + skipped +
        #: errors; dropped counts the queue's drops and the ``unsolved`` frames (tracked, then
        #: replaced by a newer one before the solver was free, or answered by the solver from
        #: the running fit); ``carried``: clouds from the
        #: running fit (Pipeline.carry) of unsolved frames and of frames still being solved
        #: when a newer one was answered; ``late``: processed frames whose own cloud was not
        #: published (newer frames were answered first). One cloud per processed frame, less
        #: the late ones, plus the carried ones.
        self.stats = {'received': 0, 'processed': 0, 'dropped': 0, 'skipped': 0, 'errors': 0,
                      'unsolved': 0, 'carried': 0, 'late': 0}
        self.last_result: Optional[FrameResult] = None
        self._focal_state: Optional[str] = None   # focal_state() of the last solved frame

        self._pipeline = Pipeline(**{k: values[k] for k in P.names('pipeline')})
        # the solve side in a child process (solver_process, a slow method), or None: here
        self._remote: Optional[SolveProcess] = None
        self._remote_method = ''            # the method it was started or reconfigured with
        self._remote_ended = 0              # children ended since the last remote solve
        # method 'auto' on the rotation model: the general model's child, started and idle
        self._standby: Optional[SolveProcess] = None
        self._place_solver({})

        out_qos = QoSProfile(depth=OUTPUT_DEPTH)
        self._seg_pub = self.create_publisher(PointCloud2, '~/segments', out_qos)
        self._debug_pub = self.create_publisher(Image, '~/debug_image', out_qos)
        self._pub_lock = threading.Lock()
        self._twist_pubs: List = []
        self._make_twist_publishers(values['num_bodies'])

        self.create_subscription(Image, 'image', self._on_image, qos_profile_sensor_data)
        self.create_subscription(CameraInfo, 'camera_info', self._on_camera_info,
                                 qos_profile_sensor_data)
        self.add_post_set_parameters_callback(self._apply_parameters)

        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics',
                                               QoSProfile(depth=OUTPUT_DEPTH))
        self._diag_last = (time.monotonic(), 0, 0)
        self.create_timer(DIAGNOSTICS_PERIOD, self._publish_diagnostics,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))

        # the newest observation waiting for the solver (with its image header and debug
        # flag), and whether the solver is busy: guarded by _lock, signalled by _solve_wake
        self._observed: Optional[Tuple[Any, Observation, bool]] = None
        # (epoch, stamp) of the last ~/segments published: a solve that ends after newer
        # frames went out from the running fit publishes its twists, not its stale cloud
        self._cloud_key: Tuple[int, float] = (-1, -math.inf)
        self._cloud_lock = threading.Lock()
        self._solving = False
        # (header, observation) the solver worker is solving and nobody answered yet
        self._in_solve: Optional[Tuple[Any, Observation]] = None
        self._last_solve_s = 0.0            # wall time of the last solve
        self._solve_wake = threading.Condition(self._lock)
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._run, name='mlofc_tracking', daemon=True)
        self._solver = threading.Thread(target=self._run_solver, name='mlofc_solver',
                                        daemon=True)
        self._worker.start()
        self._solver.start()
        self.get_logger().info(
            f'listening on {self.resolve_topic_name("image")} with '
            f'num_bodies={values["num_bodies"]}, window={window_frames(values)}, '
            f'method={values["method"]}')

    # --- parameters ----------------------------------------------------------------------

    def _convert_parameters(self, parameters: List[Parameter]) -> List[Parameter]:
        """
        Convert integers given for double parameters to doubles before they are stored.

        Doubles are declared with dynamic typing so that ``-p focal_length:=500`` and ``ros2
        param set /mlofc focal_length 500`` are accepted; without this they would be stored
        (and read back) as integers.
        """
        return [Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
                if (p.name in P.PARAMS and P.PARAMS[p.name].type is float
                    and p.type_ == Parameter.Type.INTEGER) else p
                for p in parameters]

    def _validate_parameters(self, parameters: List[Parameter]) -> SetParametersResult:
        """Accept or reject a parameter change with a readable reason (nothing changes here)."""
        for p in parameters:
            if p.name not in P.PARAMS:
                continue                    # use_sim_time & co. belong to others
            reason = P.validate(p.name, p.value)
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: List[Parameter]) -> None:
        """Apply accepted changes: pipeline ones before the next frame's tracking, others now."""
        changed = {p.name: P.coerce(p.name, p.value) for p in parameters if p.name in P.PARAMS}
        if not changed or not hasattr(self, '_worker'):
            return                          # declaration time: the constructor reads values
        with self._lock:
            self._values.update(changed)
            self._pending.update({k: v for k, v in changed.items()
                                  if P.PARAMS[k].scope == 'pipeline'
                                  or k == 'solver_process'})
            self._trim_queue()
        if 'num_bodies' in changed:
            self._make_twist_publishers(changed['num_bodies'])
        self.get_logger().info('parameters set: ' +
                               ', '.join(f'{k}={v!r}' for k, v in changed.items()))

    def _make_twist_publishers(self, n: int) -> None:
        """(Re)create ``~/body_<i>/twist`` for i < n (n = 0: created as bodies appear)."""
        with self._pub_lock:
            for pub in self._twist_pubs:
                self.destroy_publisher(pub)
            self._twist_pubs = []
            self._grow_twist_publishers(n)

    def _grow_twist_publishers(self, n: int) -> None:
        while len(self._twist_pubs) < n:
            self._twist_pubs.append(self.create_publisher(
                TwistWithCovarianceStamped, f'~/body_{len(self._twist_pubs)}/twist',
                QoSProfile(depth=OUTPUT_DEPTH)))

    # --- input ---------------------------------------------------------------------------

    def _trim_queue(self) -> None:
        """Drop the stalest frames beyond ``queue_size`` (call with the lock held)."""
        while len(self._queue) > self._values['queue_size']:
            dropped = self._queue.popleft()
            # the next frame carries the count: its stamp gap is the node's doing, not the
            # camera's, and must not restart the window (Pipeline.observe's ``dropped``)
            self._queue[0][3] += dropped[3] + 1
            self.stats['dropped'] += 1

    def _on_image(self, msg: Image) -> None:
        with self._lock:
            self.stats['received'] += 1
            self._frame_id = msg.header.frame_id
            self._queue.append([msg, self._camera, self._camera_size, 0])
            self._trim_queue()
            self._wake.notify()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        """Keep the camera model; warn once per change of problem (it comes with every frame)."""
        try:
            camera, size, problem = camera_model_from_info(msg), camera_info_size(msg), None
        except Exception as exc:  # noqa: B902 (a malformed message must not stop the executor)
            camera, size, problem = None, None, str(exc)
        with self._lock:
            self._camera, self._camera_size = camera, size
            changed, self._camera_problem = problem != self._camera_problem, problem
            focal = self._values['focal_length']
        if problem is None:
            if changed:
                self.get_logger().info('camera_info is usable again')
            return
        fallback = (f'using focal_length = {focal:g} px' if focal > 0 else
                    'the focal length is estimated from the images')
        text = f'ignoring camera_info: {problem}; {fallback}'
        self._note_problem(text)
        if changed:
            self.get_logger().warning(text)

    def _note_problem(self, text: str) -> None:
        """Remember ``text`` as the last problem (for ``/diagnostics``)."""
        self._problem = (time.monotonic(), text)

    def _warn(self, key: str, text: str) -> None:
        """Log a warning, at most once per ``warn_period`` seconds per kind of problem."""
        now = time.monotonic()
        self._note_problem(text)
        key = f'{key}:{problem_kind(text)}'
        if len(self._last_warn) > MAX_PROBLEM_KINDS:
            self._last_warn.clear()
        if now - self._last_warn.get(key, -1e300) >= self._values['warn_period']:
            self._last_warn[key] = now
            self.get_logger().warning(text)

    def _publish_diagnostics(self) -> None:
        """Publish the node's ``DiagnosticStatus`` on ``/diagnostics`` (timer, 1 Hz)."""
        now = time.monotonic()
        with self._lock:
            stats, problem, frame_id = dict(self.stats), self._problem, self._frame_id
            window = window_frames(self._values)
        # answered: every ~/segments message, solved or from the running fit
        answered = stats['processed'] + stats['carried']
        last_t, last_solved, last_answered = self._diag_last
        self._diag_last = (now, stats['processed'], answered)
        span = max(now - last_t, 1e-9)
        rate = (answered - last_answered) / span
        solved_rate = (stats['processed'] - last_solved) / span
        r, remote = self.last_result, self._remote
        recent = problem is not None and now - problem[0] <= self.problem_hold
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if recent else DiagnosticStatus.OK,
            name=f'{self.get_fully_qualified_name().lstrip("/")}: pipeline',
            hardware_id=frame_id,
            message=problem[1] if recent else 'ok')
        values = {
            'rate (Hz)': f'{rate:.2f}',
            'solved rate (Hz)': f'{solved_rate:.2f}',
            'tracked lines': len(r.track_ids) if r is not None else 0,
            'tracks in window': r.n_tracks if r is not None else 0,
            'window fill': f'{r.window_fill if r is not None else 0}/{window}',
            'frames received': stats['received'],
            'frames processed': stats['processed'],
            'frames dropped': stats['dropped'],
            'frames tracked, not solved': stats['unsolved'],
            'frames carried from the running fit': stats['carried'],
            'frames skipped': stats['skipped'],
            'errors': stats['errors'],
            'focal length (px)': f'{r.focal_length:.1f}' if r is not None else 'nan',
            'focal length': focal_text(r),
            'solver': 'thread' if remote is None else f'child process {remote.pid}',
            'solver method': self._method,
            'last problem': problem[1] if problem is not None else 'none',
            'last problem age (s)': f'{now - problem[0]:.1f}' if problem is not None else '',
        }
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(msg)

    # --- worker --------------------------------------------------------------------------

    def _run(self) -> None:
        """Tracking worker: decode, track and window every queued image."""
        while not self._stop.is_set():
            with self._lock:
                while not self._queue and not self._stop.is_set():
                    self._wake.wait(0.2)
                if self._stop.is_set():
                    return
                item = self._queue.popleft()
                pending, self._pending = self._pending, {}
                move, self._move_solver = self._move_solver, False
                debug = self._values['publish_debug_image']
                if pending or move:
                    # the solver must not run during a reconfiguration: let it finish what it
                    # has (a window of the old settings), then change both halves at once
                    while (self._observed is not None or self._solving) and \
                            not self._stop.is_set():
                        self._solve_wake.wait(0.2)
            try:
                if pending or move:
                    self._reconfigure(pending)
                self._observe(*item, debug=debug)
            except Exception as exc:  # noqa: B902 (the worker must survive anything)
                self._count('errors')
                if self._stop.is_set() or not self.context.ok():
                    return
                self._warn('error', f'frame failed: {type(exc).__name__}: {exc}')

    def _reconfigure(self, pending: Dict[str, Any]) -> None:
        """Apply pipeline parameters to both halves (the solver idle): see _place_solver."""
        changes = {k: v for k, v in pending.items() if P.PARAMS[k].scope == 'pipeline'}
        self._pipeline.reconfigure(**changes)
        self._place_solver(changes)

    def _place_solver(self, changes: Dict[str, Any]) -> None:
        """
        Solve in a child process or here, as ``solver_process`` and the method ask.

        ``changes``: the pipeline parameters just applied here, for the children too. The
        solve side's state moves with the solving (body ids, count, focal estimate, running
        fit: :meth:`Pipeline.hand_over`). With method 'auto' still on the rotation model the
        child of the general model is started beforehand and waits (:attr:`_standby`), so
        that the switch solves at once.
        """
        self._method = self._pipeline.method
        process = self._values['solver_process']
        wanted = process and get_method(self._method).slow
        standby = process and not wanted and self._pipeline.params['method'] == AUTO
        if self._remote is not None and changes:
            # the method it solves with from now on, or until it is closed or waits
            method = self._method if wanted else self._remote_method
            self._remote.reconfigure(**dict(changes, method=method))
            self._remote_method = method
            if wanted and changes.get('method', AUTO) != AUTO:
                self._drop_votes(self._remote)
        if self._standby is not None and changes:
            try:
                self._standby.reconfigure(**dict(changes, method=TRANSLATION_METHOD))
            except SolverProcessError:
                self._standby.close()           # it ended while it waited: a new one below
                self._standby = None
        if not wanted and self._remote is not None:
            remote, self._remote = self._remote, None
            self._take_solve_side(remote)
            if (standby and self._standby is None
                    and self._remote_method == TRANSLATION_METHOD):
                self._standby = remote                  # it waits for the next switch
            else:
                remote.close()
            self.get_logger().info('solving in the node process')
        elif wanted and self._remote is None:
            self._start_remote()
        if not standby and self._standby is not None:
            self._standby.close()
            self._standby = None
        elif standby and self._standby is None:
            self._standby = self._spawn(TRANSLATION_METHOD)

    def _spawn(self, method: str) -> Optional[SolveProcess]:
        """Start a child process that solves with ``method``; None (logged) when it cannot."""
        try:
            return SolveProcess(dict(self._pipeline.params, method=method))
        except OSError as exc:
            self.get_logger().error(f'cannot start the solver process ({exc}): solving '
                                    'in the node process')
            return None

    def _start_remote(self) -> None:
        """Solve in a child process from now on: the standby's, or a new one."""
        remote, self._standby = self._standby, None
        if remote is None or self._method != TRANSLATION_METHOD or not remote.alive:
            if remote is not None:
                remote.close()
            remote = self._spawn(self._method)
            if remote is None:
                return
        remote.take_over(self._pipeline.hand_over())     # sent with its first solve
        self._remote, self._remote_method = remote, self._method
        self._remote_ended = 0
        self.get_logger().info(f'solving in a child process (pid {remote.pid})')

    def _drop_votes(self, remote: SolveProcess) -> None:
        """
        Have a child that solves for a method set by hand publish its own labels.

        After the switch of ``method:=auto`` the child goes on with auto's label votes
        (:meth:`Pipeline.take_over`); set to a method by hand, it stops them (its warm
        starts restart, as after any change of method).
        """
        try:
            remote.take_over(remote.hand_over()._replace(votes=None))
        except SolverProcessError as exc:
            self.get_logger().warning(f'the solver process kept its state ({exc})')

    def _take_solve_side(self, remote: SolveProcess) -> None:
        """Take the solve side's state back from a child before solving here."""
        try:
            self._pipeline.take_over(remote.hand_over())
        except SolverProcessError as exc:
            self.get_logger().warning(f'the solver process kept its state ({exc}): the body '
                                      'ids restart')
            self._pipeline.forget_solves()

    def _count(self, key: str) -> None:
        with self._lock:
            self.stats[key] += 1

    def _observe(self, msg: Image, camera: Optional[CameraModel],
                 camera_size: Optional[Tuple[int, int]], dropped: int, debug: bool) -> None:
        # frames the node itself did not pass on since the last one: the queue's drops and
        # undecodable images (tracking worker only)
        self._unpassed += dropped
        try:
            gray = image_msg_to_gray(msg, max_pixels=self._values['max_pixels'])
        except ValueError as exc:
            self._unpassed += 1
            self._count('skipped')
            self._warn('image', f'bad image on {self.resolve_topic_name("image")}: {exc}; '
                       'frame skipped')
            return
        size = (int(gray.shape[1]), int(gray.shape[0]))
        if camera is not None and camera_size is not None and camera_size != size:
            self._warn('camera_size', f'camera_info is for {camera_size[0]}x{camera_size[1]} '
                       f'images but the image is {size[0]}x{size[1]}; ignoring camera_info')
            camera = None
        try:
            obs = self._pipeline.observe(gray, stamp_to_seconds(msg.header.stamp), camera,
                                         dropped=self._unpassed)
            self._unpassed = 0
        except ValueError as exc:
            self._unpassed += 1
            self._count('skipped')
            self._warn('input', f'{exc}; frame skipped')
            return
        if obs.skipped:
            self._count('skipped')
            self._warn('pipeline', '; '.join(obs.problems))
            return
        with self._lock:
            # a fast solver runs here, in turn with the tracking: handing every frame over to
            # the solver worker would make two Python threads contend for the GIL (measured:
            # 60 Hz no longer kept up with); a slow method (its first search takes seconds)
            # always runs in its own worker
            inline = (self._observed is None and not self._solving
                      and self._last_solve_s < INLINE_SOLVE_S
                      and not get_method(self._pipeline.method).slow)
            older = in_solve = None
            if inline:
                self._solving = True
            else:
                if self._observed is not None:
                    # the solver is behind: the newer window replaces the unsolved one, which
                    # is answered from the running fit, and so is the frame being solved (its
                    # own cloud would come after that one's: late)
                    older = self._observed
                    obs = obs.replacing(older[1])
                    self.stats['dropped'] += 1
                    self.stats['unsolved'] += 1
                    in_solve, self._in_solve = self._in_solve, None
                self._observed = (msg.header, obs, debug)
                self._solve_wake.notify_all()
        if inline:
            self._solve_guarded(msg.header, obs, debug)
        elif older is not None and self._values['carry_labels']:
            if in_solve is not None:
                self._publish_carried(*in_solve)
            self._publish_carried(older[0], older[1])

    def _publish_carried(self, header: Any, obs: Observation) -> None:
        """Publish the ``~/segments`` of an unsolved frame from the running fit."""
        r = self._pipeline.carry(obs)
        if np.any(r.carried) and self._publish_cloud(header, obs, r):
            self._count('carried')

    def _publish_cloud(self, header: Any, obs: Observation, r: FrameResult) -> bool:
        """Publish the ``~/segments`` of ``obs`` if newer than the last one; return whether."""
        key = (obs.epoch, obs.stamp)
        # held while publishing: the other worker's cloud must not go out in between
        with self._cloud_lock:
            if key <= self._cloud_key:
                return False
            self._cloud_key = key
            self._seg_pub.publish(segments_msg(header, r.segments, r.track_ids, r.labels,
                                               r.residuals, r.rays))
            return True

    def _run_solver(self) -> None:
        """Solver worker: solve the newest observation and publish its frame's outputs."""
        while not self._stop.is_set():
            with self._lock:
                while self._observed is None and not self._stop.is_set():
                    self._solve_wake.wait(0.2)
                if self._stop.is_set():
                    return
                (header, obs, debug), self._observed = self._observed, None
                self._solving = True
                self._in_solve = (header, obs)
            self._solve_guarded(header, obs, debug)

    def _solve_guarded(self, header: Any, obs: Observation, debug: bool) -> None:
        """Solve and publish (``_solving`` set by the caller); count and warn on failure."""
        try:
            self._solve(header, obs, debug)
        except Exception as exc:  # noqa: B902 (the workers must survive anything)
            self._count('errors')
            if not self._stop.is_set() and self.context.ok():
                self._warn('error', f'frame failed: {type(exc).__name__}: {exc}')
        finally:
            with self._lock:
                self._solving = False
                self._in_solve = None
                self._solve_wake.notify_all()

    def _solve(self, header: Any, obs: Observation, debug: bool) -> None:
        t = time.monotonic()
        remote = self._remote
        if remote is None:
            result = self._pipeline.solve(obs)
        else:
            try:
                result = remote.solve(obs, self._pipeline)
            except SolverProcessEnded as exc:
                self._remote_ended += 1
                if self._remote_ended >= REMOTE_ENDED_MAX:
                    # a child that cannot live (it cannot import, it is killed at once): not
                    # a frame's failure, solve here (a solver_process or method change retries)
                    self._remote = None
                    remote.close()
                    self.get_logger().error(
                        f'the solver process ended {self._remote_ended} times in a row '
                        f'({exc}): solving in the node process from now on')
                else:
                    # the restarted child takes the solve side as a new one does (the next
                    # observation restarts its body ids): an 'auto' stream's votes go on
                    remote.take_over(self._pipeline.hand_over())
                raise
            self._remote_ended = 0
        self._last_solve_s = time.monotonic() - t
        if result.problem:
            self._warn('pipeline', result.problem)
        self.last_result = result           # before publishing: a subscriber may look at it
        self._log_focal(result)
        if remote is None and self._pipeline.method != self._method:
            self._method_chosen()
        if result.from_running_fit:
            # the solver answered from the running fit (a step that did not hold while a full
            # solve runs beside it): not processed but unsolved, its cloud a carried one
            with self._lock:
                self.stats['dropped'] += 1
                self.stats['unsolved'] += 1
            if not self._values['carry_labels']:
                return                                            # solved frames only
            if self._publish_cloud(header, obs, result):
                self._count('carried')
            self._publish(header, obs.gray, result, debug)    # no body valid: no twist
            return
        if not self._publish_cloud(header, obs, result):
            self._count('late')
        self._publish(header, obs.gray, result, debug)
        self._count('processed')

    def _publish(self, header: Any, gray: Any, r: FrameResult, debug: bool) -> None:
        """Publish a solved frame's twists and debug image (its cloud: _publish_cloud)."""
        with self._pub_lock:
            if self._values['num_bodies'] == 0:
                self._grow_twist_publishers(len(r.angular_velocities))
            for i, pub in enumerate(self._twist_pubs):
                if i < len(r.body_valid) and r.body_valid[i]:
                    pub.publish(twist_msg(header, r.angular_velocities[i],
                                          r.angular_covariances[i]))
        if debug or self._debug_pub.get_subscription_count() > 0:
            bgr = draw_debug(gray, r.segments, r.labels, r.track_ids, r.angular_velocities,
                             r.body_valid)
            self._debug_pub.publish(debug_image_msg(header, bgr))

    def _method_chosen(self) -> None:
        """Say that method 'auto' moved to the general model, and place the solver anew."""
        choice = self._pipeline.method_choice
        self.get_logger().info(
            "method auto: the rotation model misfits the scene (its tracks' residuals: "
            f"the median {choice.ratio:.1f}x the tracks' jitter, the 75th percentile "
            f'{choice.quartile_ratio:.1f}x their own: bodies translate relative to the camera); '
            f'solving with {self._pipeline.method} from now on')
        with self._lock:
            self._move_solver = True
            self._method = self._pipeline.method    # said once

    def _log_focal(self, r: FrameResult) -> None:
        """Log once when the focal length becomes observable or not (estimated only)."""
        state = focal_state(r)
        if state is None or state == self._focal_state:
            return
        self._focal_state = state
        spread = f'{r.focal_length:.0f} px +-{100.0 * r.focal_log_sigma:.0f}%'
        if state == 'not observable':
            self.get_logger().warning(
                f'the focal length is not observable from the scene so far ({spread}: a '
                'still scene, or bodies that do not rotate about the camera); the covariances '
                'of the twists carry it; give camera_info or focal_length for calibrated rates')
        elif state == 'estimated':
            self.get_logger().info(f'focal length estimated from the scene: {spread}')

    # --- lifecycle -----------------------------------------------------------------------

    def pending_frames(self) -> int:
        """Frames not answered yet: waiting in the queue, for the solver, or being solved."""
        with self._lock:
            return len(self._queue) + (self._observed is not None) + self._solving

    def destroy_node(self) -> None:
        """Stop the worker, then destroy the node."""
        self._stop.set()
        with self._lock:
            self._wake.notify_all()
            self._solve_wake.notify_all()
        for worker in (self._worker, self._solver):
            if worker.is_alive() and threading.current_thread() is not worker:
                worker.join(timeout=10.0)
        for child in (self._remote, self._standby):
            if child is not None:
                child.close()
        super().destroy_node()


def main(args: Optional[List[str]] = None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = MlofcNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
        rclpy.logging.get_logger('mlofc').fatal(f'cannot start: {exc}')
        raise SystemExit(1)
    finally:
        # a second Ctrl-C (a terminal signals the whole process group, and ros2 launch
        # forwards its own) must not break the shutdown under way: the workers may need a
        # moment to finish a solve
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
