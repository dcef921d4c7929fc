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
A solver lane: the full solves of a stream, run while the frames go on stepping.

A method that steps (``general``) answers most frames with a tracking step of about 20 ms, but
its schedule (:mod:`mlofc_ros.solver.warm`) asks for a search (1-2 s) at the start and full
solves (0.3-0.8 s) after it and whenever the steps no longer explain the window, and every few
steps for a rescan of one body (a step of about 90 ms). A
:class:`~mlofc_ros.pipeline.Pipeline` given a lane (:meth:`Pipeline.use_lane`) hands those to
the lane instead and steps the frames meanwhile from the running fit; when the lane's answer
comes back it becomes the running fit (a rescan's: the body's motion, when it moved to another
basin; a search's once polished on its window by more jobs), and the next frame steps from
it. The node's solver process does so (:class:`mlofc_ros.solve_process.ProcessLane`: one
more child process); :class:`InlineLane` runs the job at once and hands it back a given
number of frames later (tests, offline replays).

A lane runs one job at a time: :meth:`submit` only when not :attr:`busy`; :meth:`poll`
returns the finished job with its result (or the exception it raised), once.
"""
from dataclasses import dataclass
import time
from typing import Any, Callable, Dict, Optional, Tuple, Union

from mlofc_ros.frame import Observation
from mlofc_ros.solver import segment_lines, SegmentationResult


@dataclass(frozen=True)
class SolveJob:
    """
    A full solve handed to a lane: the window of ``obs`` with ``keywords``.

    ``keywords``: those of :func:`~mlofc_ros.solver.segment_lines` (tracks, bodies, method,
    warm start); ``obs``: the observation it solves (without its image), which the answer
    is published for; ``generation``: the pipeline's solve state it started from (a job
    from before a reset or a reconfiguration is dropped). ``rescan``: a step that rescans a
    body instead (its frame was answered by a step without it; the answer is the body's
    motion, not published). ``polish``: which tracked solve of a search's window this is
    (1, 2, ...), from ``before``, the answer it polishes (0 and None: not a polish).
    """

    obs: Observation
    keywords: Dict[str, Any]
    generation: int
    rescan: bool = False
    polish: int = 0
    before: Optional[SegmentationResult] = None


#: What :meth:`poll` returns: the job and its result, or the exception it raised.
Finished = Tuple[SolveJob, Union[SegmentationResult, Exception]]


def run_job(keywords: Dict[str, Any]) -> Union[SegmentationResult, Exception]:
    """Run a job's ``keywords`` here; the result, or the exception it raised (not raised)."""
    try:
        return segment_lines(**keywords)
    except Exception as exc:  # noqa: B902 (handed to the pipeline with the job)
        return exc


class InlineLane:
    """
    A lane that runs each job at once and hands it back ``delay`` polls later.

    ``delay``: polls (frames) between :meth:`submit` and the answer, or a callable of the
    job's CPU seconds returning them (an offline replay of a solver slower than the camera:
    ``lambda s: math.ceil(s * rate)``). ``cpu``: the CPU seconds of every job run so far.
    """

    def __init__(self, delay: Union[int, Callable[[float], int]] = 0) -> None:
        self.delay = delay
        self.cpu = 0.0
        self._job: Optional[SolveJob] = None
        self._result: Union[SegmentationResult, Exception, None] = None
        self._left = 0

    @property
    def busy(self) -> bool:
        """Whether a job is running (or waiting to be handed back)."""
        return self._job is not None

    def submit(self, job: SolveJob) -> None:
        """Run ``job``; its answer comes back from :meth:`poll` after the delay."""
        if self.busy:
            raise RuntimeError('the lane is busy')
        t = time.thread_time()
        self._result = run_job(job.keywords)
        seconds = time.thread_time() - t
        self.cpu += seconds
        delay = self.delay(seconds) if callable(self.delay) else self.delay
        self._job, self._left = job, max(int(delay), 0)

    def poll(self) -> Optional[Finished]:
        """Return the finished job and its result once its delay is over, else None."""
        if self._job is None:
            return None
        if self._left > 0:
            self._left -= 1
            return None
        job, result = self._job, self._result
        self._job = self._result = None
        return job, result

    def close(self) -> None:
        """Drop the job (nothing runs in the background)."""
        self._job = self._result = None
