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
The solve half of a :class:`~mlofc_ros.pipeline.Pipeline` in a child process.

Python runs one thread at a time in a process, and the solver of a slow method (``general``)
is mostly short numpy calls that hold the interpreter: in a thread beside the tracking it got
about half a core. In a child process it gets a core of its own, and the tracking the
interpreter of the parent. The observing pipeline (parent) tracks and windows every frame as
before; :meth:`SolveProcess.solve` sends an :class:`~mlofc_ros.frame.Observation` (without
its image) to a pipeline in the child that only solves, waits for its
:class:`~mlofc_ros.frame.FrameResult`, and hands the child's
:class:`~mlofc_ros.pipeline.SolveState` (the running fit for carried frames, the focal length)
to the parent. The solve side's state (body ids, warm starts, count, focal estimate) lives in
the child; :meth:`SolveProcess.take_over` and :meth:`SolveProcess.hand_over` move it in and
out when the solving moves (the body ids go on). The child is ``python -m
mlofc_ros.solve_process`` (the parent's interpreter and environment) in a process group of its
own, talking over a socket pair: it ends when told to, or when the parent's end closes (the
parent ended, however). Its full solves (a search: 1-2 s) and rescans run in one more child of
its own, a solver lane (:class:`ProcessLane`, :mod:`mlofc_ros.lane`), while it steps the
frames from the running fit (about 20 ms each): a live node at 30 Hz solved 15-57% of the
frames when the full solves ran in turn, 32-70% with the lane, 75-86% with the rescans there
too (bench live, own2+bg; the others answered from the running fit).

Example::

    pipe = Pipeline(method='general', window=10)
    with SolveProcess(pipe.params) as remote:
        for gray, t in frames:
            r = remote.solve(pipe.observe(gray, t), pipe)
"""
import dataclasses
from multiprocessing.connection import Connection
import signal
import socket
import subprocess
import sys
from typing import Any, Mapping, Optional, Tuple, TYPE_CHECKING

if TYPE_CHECKING:                      # the child imports the pipeline after its signals
    from mlofc_ros.frame import FrameResult, Observation
    from mlofc_ros.lane import Finished, SolveJob
    from mlofc_ros.pipeline import Pipeline, SolveSide

#: Seconds to wait for the child to end on :meth:`SolveProcess.close` before killing it.
CLOSE_TIMEOUT = 5.0


class SolverProcessError(RuntimeError):
    """The child process failed (an exception in it, or it ended); see the message."""


class SolverProcessEnded(SolverProcessError):
    """The child process ended (killed, crashed); a new one was started."""


def _serve(conn: Connection) -> None:
    """Child: solve the observations received on ``conn`` until told to stop or it closes."""
    from mlofc_ros.pipeline import Pipeline
    from mlofc_ros.solver import get_method
    try:
        params, lane = conn.recv()
    except (EOFError, OSError):
        return
    if params is None:                  # a lane's child: it only runs jobs
        _serve_requests(conn, None)
        return
    pipeline = Pipeline(**params)
    if lane:
        # the full solves of a stepping method in a lane of their own: the frames step
        # meanwhile (its child started now for such a method, else at its first job)
        pipeline.use_lane(ProcessLane())
        if get_method(pipeline.method).accepts('step_only'):
            pipeline.lane.start()
    try:
        _serve_requests(conn, pipeline)
    finally:
        if pipeline.lane is not None:
            pipeline.lane.close()                       # its job is not wanted any more


def _serve_requests(conn: Connection, pipeline: Optional['Pipeline']) -> None:
    """
    Child: answer the requests on ``conn`` until told to stop or it closes.

    ``pipeline`` solves and is reconfigured; None in a lane's child, which only runs jobs.
    """
    from mlofc_ros.lane import run_job
    while True:
        try:
            request, payload = conn.recv()
        except (EOFError, OSError):
            return                                      # the parent is gone
        if request == 'stop':
            return
        try:
            if request == 'job':
                reply: Any = run_job(payload)   # a lane's: its exception is its answer
            elif pipeline is None:
                raise ValueError(f'a lane runs jobs only, not {request!r}')
            elif request == 'solve':
                reply = (pipeline.solve(payload), pipeline.solve_state())
            elif request == 'reconfigure':
                pipeline.reconfigure(**payload)
                reply = None
            elif request == 'take_over':
                pipeline.take_over(payload)
                reply = None
            elif request == 'hand_over':
                reply = pipeline.hand_over()
            else:
                raise ValueError(f'unknown request {request!r}')
        except Exception as exc:  # noqa: B902 (reported to the parent, the child lives on)
            status, reply = 'error', f'{type(exc).__name__}: {exc}'
        else:
            status = 'ok'
        try:
            conn.send((status, reply))
        except OSError:
            return                                      # the parent went while we solved


def _spawn(params: Optional[Mapping[str, Any]], lane: bool, group: bool = True
           ) -> Tuple[subprocess.Popen, Connection]:
    """
    Start a child that serves a pipeline made with ``params``; its process and our end.

    ``params`` None: a lane's child, which runs jobs only (no pipeline).

    ``lane``: the child's pipeline runs its full solves in a :class:`ProcessLane`; ``group``:
    the child in a process group of its own.
    """
    # a fresh interpreter (not a fork: the parent runs threads, DDS's and the node's, whose
    # locks a fork would copy held) in a process group of its own: a terminal's Ctrl-C
    # reaches the node's group, and the node decides when its solver stops (a Unix session of
    # its own would also schedule it apart from the node's: about 10% fewer frames
    # solved in bench live, within its runs' spread). Over a socket pair the child sees
    # the parent end as its input's end.
    ours, theirs = socket.socketpair()
    with theirs:
        process = subprocess.Popen(
            [sys.executable, '-m', 'mlofc_ros.solve_process', str(theirs.fileno())],
            pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
            process_group=0 if group else None)
    conn = Connection(ours.detach())
    conn.send((None if params is None else dict(params), lane))
    return process, conn


def _end(process: subprocess.Popen, conn: Connection) -> None:
    """Kill a child that still runs, wait for it, close our end of its socket."""
    if process.poll() is None:
        process.kill()
        process.wait(CLOSE_TIMEOUT)
    conn.close()


class SolveProcess:
    """
    A child process that solves a pipeline's observations (see the module docstring).

    ``params``: the pipeline's parameters (``Pipeline.params``). ``lane``: the child runs the
    full solves of a stepping method (``general``) in a lane of its own
    (:class:`ProcessLane`, :meth:`Pipeline.use_lane`) and steps the frames meanwhile; without
    it every solve the schedule asks for runs in turn. The child is started at once (it
    imports numpy and OpenCV: about a second); the first :meth:`solve` waits for it. Use
    from one thread at a time; :meth:`close` (or the ``with`` block) ends the child, which
    also ends when the parent does.
    """

    def __init__(self, params: Mapping[str, Any], lane: bool = True) -> None:
        self._params = dict(params)
        self._lane = bool(lane)
        self._closed = False
        self._conn: Any = None
        self._process: Optional[subprocess.Popen] = None
        self._handed: Optional['SolveSide'] = None      # take_over's, not sent yet
        self._start()

    def _start(self) -> None:
        self._process, self._conn = _spawn(self._params, self._lane)

    def _call(self, request: str, payload: Any) -> Any:
        if self._process is None and not self._closed:     # a restart failed: try again
            try:
                self._start()
            except OSError as failed:
                raise SolverProcessEnded(f'cannot start the solver process: {failed}') from None
        try:
            self._conn.send((request, payload))
            status, reply = self._conn.recv()
        except (EOFError, OSError) as exc:
            code = self._process.poll() if self._process is not None else None
            if self._closed:
                raise SolverProcessError('the solver process was closed') from None
            self._stop(kill=True)
            try:
                self._start()
            except OSError as failed:
                raise SolverProcessEnded(f'the solver process ended (exit code {code}: '
                                         f'{type(exc).__name__}); cannot restart it: '
                                         f'{failed}') from None
            raise SolverProcessEnded(f'the solver process ended (exit code {code}: '
                                     f'{type(exc).__name__}); restarted') from None
        if status == 'error':
            raise SolverProcessError(f'in the solver process: {reply}')
        return reply

    def solve(self, obs: 'Observation', pipeline: 'Pipeline') -> 'FrameResult':
        """
        Solve ``obs`` (from ``pipeline.observe``) in the child; hand its state to ``pipeline``.

        Like ``pipeline.solve(obs)``, with the solve side in the child. Raises
        :class:`SolverProcessError` when the child fails; a child that ended is restarted
        and ``pipeline`` told to forget the solves (body ids restart).
        """
        try:
            if self._handed is not None:
                self._call('take_over', self._handed)
                self._handed = None
            result, state = self._call('solve', dataclasses.replace(obs, gray=None))
        except SolverProcessEnded:
            self._handed = None
            pipeline.forget_solves()        # the new child starts without the solve state
            raise
        pipeline.adopt(state)
        return result

    def reconfigure(self, **changes: Any) -> None:
        """Apply :meth:`Pipeline.reconfigure` in the child (the caller's own pipeline too)."""
        self._call('reconfigure', changes)
        self._params.update(changes)        # accepted: a restarted child starts with them

    def take_over(self, side: 'SolveSide') -> None:
        """
        Have the child solve from ``side`` on (:meth:`Pipeline.take_over`).

        Sent with the next :meth:`solve` (this returns at once, even while the child starts);
        a child that ends before then starts without it, as after any restart.
        """
        self._handed = side

    def hand_over(self) -> 'SolveSide':
        """Return the child's solve side (:meth:`Pipeline.hand_over`), to solve elsewhere."""
        if self._handed is not None:                    # not sent yet: still ours
            side, self._handed = self._handed, None
            return side
        return self._call('hand_over', None)

    @property
    def alive(self) -> bool:
        """Return whether the child process runs."""
        return self._process is not None and self._process.poll() is None

    @property
    def pid(self) -> Optional[int]:
        """Return the child's process id (None once closed)."""
        return None if self._process is None else self._process.pid

    def _stop(self, kill: bool = False) -> None:
        process, self._process = self._process, None
        if process is None:
            return
        if not kill:
            try:
                self._conn.send(('stop', None))
                process.wait(CLOSE_TIMEOUT)
            except (OSError, ValueError, subprocess.TimeoutExpired):
                pass
        _end(process, self._conn)

    def close(self) -> None:
        """End the child process (idempotent)."""
        self._closed = True
        self._stop()

    def __enter__(self) -> 'SolveProcess':
        return self

    def __exit__(self, *exc: Tuple[Any, ...]) -> None:
        self.close()


class ProcessLane:
    """
    A solver lane (:mod:`mlofc_ros.lane`) in a child process: full solves beside the steps.

    The child (the same program as :class:`SolveProcess`'s, in the caller's process group:
    it ends with it) starts at :meth:`start` or the first :meth:`submit`. A child that ended
    is started again at the next :meth:`submit`; the job it held comes back from
    :meth:`poll` with a :class:`SolverProcessEnded`.
    """

    def __init__(self) -> None:
        self._process: Optional[subprocess.Popen] = None
        self._conn: Any = None
        self._job: Any = None

    @property
    def busy(self) -> bool:
        """Whether a job is running."""
        return self._job is not None

    def start(self) -> None:
        """Start the child now (it imports numpy and OpenCV: about a second) if not running."""
        if self._process is not None and self._process.poll() is not None:
            self.close()                                # it ended while idle
        if self._process is None:
            self._process, self._conn = _spawn(None, lane=False, group=False)

    def submit(self, job: 'SolveJob') -> None:
        """Send ``job`` to the child (started if need be); returns at once."""
        if self.busy:
            raise RuntimeError('the lane is busy')
        self.start()
        try:
            self._conn.send(('job', job.keywords))
        except OSError:                                 # it ended since: once more, afresh
            self.close()
            self.start()
            self._conn.send(('job', job.keywords))
        self._job = job

    def poll(self) -> Optional['Finished']:
        """Return the finished job and its result (or exception) once, else None; no wait."""
        if self._job is None:
            return None
        try:
            if not self._conn.poll():
                return None
            status, reply = self._conn.recv()
        except (EOFError, OSError):
            job, code = self._job, self._process.poll()
            self.close()
            return job, SolverProcessEnded(f'the solver lane process ended (exit code '
                                           f'{code}); restarted at the next job')
        job, self._job = self._job, None
        if status == 'error':
            reply = SolverProcessError(f'in the solver lane process: {reply}')
        return job, reply

    def close(self) -> None:
        """End the child (at once: a job it holds is dropped)."""
        process, self._process, self._job = self._process, None, None
        if process is not None:
            _end(process, self._conn)


if __name__ == '__main__':
    # the child (SolveProcess._start): argv[1] is the socket to the parent
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _serve(Connection(int(sys.argv[1])))
