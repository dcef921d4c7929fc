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
The one parameter table of mlofc_ros.

The node declares these as ROS parameters (with descriptors and ranges built from this table),
:class:`mlofc_ros.pipeline.Pipeline` takes them as keyword arguments, the bag tool exposes them as
options and the README lists them (:func:`markdown_table`). Nothing here imports rclpy.

Doubles accept integers (``-p focal_length:=500`` arrives as an integer; the node declares doubles
with dynamic typing and this module coerces), but document them as ``500.0``.

Example::

    >>> from mlofc_ros import params
    >>> params.validate('window', 1)
    "window must be 0 (the method's own) or in [2, 30], got 1"
    >>> params.coerce('focal_length', 500)
    500.0
"""
from dataclasses import dataclass
import math
from typing import Any, Dict, Iterable, Mapping, Optional, Sequence, Tuple, Union

Number = Union[int, float]

#: Fallback method list while ``mlofc_ros.solver`` does not export ``METHODS``.
_FALLBACK_METHODS = ('robust',)


def solver_methods() -> Tuple[str, ...]:
    """Return the solver's method names (``mlofc_ros.solver.METHODS``)."""
    try:
        from mlofc_ros.solver import METHODS
    except ImportError:  # the solver package is still being written
        return _FALLBACK_METHODS
    return tuple(METHODS)


@dataclass(frozen=True)
class ParamSpec:
    """
    One parameter: its name, Python type, default, meaning and allowed values.

    Attributes
    ----------
    name : str
        Parameter name, the same for the ROS parameter, the Pipeline keyword and the bag option.
    type : type
        ``int``, ``float``, ``str`` or ``bool`` (``float`` parameters also accept ints).
    default : int | float | str | bool
        Default value.
    description : str
        One line with units, for ``ros2 param describe`` and the README.
    range : (lo, hi) or None
        Inclusive numeric range.
    choices : tuple of str or None
        Allowed strings (``method``: resolved from the solver at validation time).
    read_only : bool
        True when the value can only be set at start-up.
    scope : str
        ``'pipeline'`` (passed to :class:`~mlofc_ros.pipeline.Pipeline`) or ``'node'`` (the ROS
        shell only: queues, debug output).

    """

    name: str
    type: type  # noqa: A003 (the table's column name)
    default: Any
    description: str
    range: Optional[Tuple[Number, Number]] = None  # noqa: A003 (the table's column name)
    choices: Optional[Tuple[str, ...]] = None
    read_only: bool = False
    scope: str = 'pipeline'

    def allowed_choices(self) -> Optional[Tuple[str, ...]]:
        """Return the allowed strings, or None when any string is allowed."""
        if self.name == 'method':
            return solver_methods() + ('auto',)
        return self.choices


#: The parameter table, in the order the README lists it.
PARAMETERS: Tuple[ParamSpec, ...] = (
    ParamSpec('num_bodies', int, 2,
              'Number of independently moving rigid bodies, the static background counting as '
              'one; 0 = found from the scene and kept up as bodies start, stop and leave '
              '(a new body gets an id no body held in the last minute, one that stops the '
              "background's). A count given is the most: bodies the rotation model cannot "
              'tell apart (a still scene, a body that stops) are published as one, under the '
              'older id (mlofc_ros.alike).',
              range=(0, 8)),
    ParamSpec('window', int, 0,
              'Sliding window length in frames, 0 or 2-30 (one frame shows no motion); the '
              "solver runs on the last `window` frames at every frame. 0 = the method's own: "
              '10 for general and auto (a translation needs them), 5 for the others.',
              range=(0, 30)),
    ParamSpec('method', str, 'auto',
              'Solver method: auto = robust (rotation about the camera, fast) until its '
              'rotation model misfits the scene (bodies translate relative to the camera), '
              'then general for good (mlofc_ros.method_choice), its labels voted over the '
              "solves, the rotation model's too (mlofc_ros.label_votes); or one of "
              'mlofc_ros.solver.METHODS.'),
    ParamSpec('min_segment_length', float, 20.0,
              'Shortest line segment detected and tracked, in pixels.',
              range=(2.0, 10000.0)),
    ParamSpec('detect_every', int, 3,
              'Run the line detector on every n-th frame (the shortest interval of detection '
              'on demand, see detect_every_max); tracks are carried between. Larger values '
              'cut the mean cost per frame (the detector is most of a detection frame) but '
              'new edges get a track later.',
              range=(1, 100)),
    ParamSpec('detect_every_max', int, 12,
              'Detection on demand: after the first detect_every_max frames at the base rate, '
              'a detection that finds almost nothing new (new segments <= 3% of the tracks) '
              'doubles the interval between detections, up to '
              'this many frames; the detector runs at once (from detect_every frames on) when '
              'edges show that no track explains or more than 5% of the tracks are lost, and '
              'a detection that finds more brings the interval back to detect_every. A static '
              'camera watching a few moving objects then pays for the detector rarely. '
              '<= detect_every: a fixed rate.',
              range=(1, 100)),
    ParamSpec('detect_regions', bool, False,
              'Detection on demand in a quiet scene (the interval has grown past '
              'detect_every): run the detector only on the image regions whose edges no track '
              'explains and around lost tracks, when they cover at most half of the image; the '
              'whole image at the first detection after detect_every_max frames, in the first '
              'detect_every_max frames and while the scene is busy. Saves most of the detector '
              'on a static camera watching a few moving objects, for segment endpoints 10-12% '
              'further off; textured or moving views fall back to the whole image.'),
    ParamSpec('detector_scale', float, 0.8,
              'The line detector runs on the image resized by this factor (area average). '
              'With lsd, 0.8 tracks as many edges as full resolution (1.0) for about a quarter '
              'less front-end CPU; lower values save more and lose new edges (0.5: about 2 '
              'points fewer edges tracked). With fld use 1.0 (0.8: 1 point fewer).',
              range=(0.25, 1.0)),
    ParamSpec('detector_backend', str, 'lsd',
              "The line detector: 'lsd' (OpenCV's LSD) or 'fld' (FastLineDetector of OpenCV's "
              'contrib module ximgproc: install opencv-contrib-python-headless in place of '
              'opencv-python-headless). fld at detector_scale 1.0 cuts the mean CPU per frame '
              'by about a quarter at 640x480 and tracks about as many edges over 5 frames '
              '(-0.7 / +0.6 points on two sets of rendered sequences), with lines ~30% and '
              'endpoints about 2x further off; use it with detector_scale:=1.0.',
              choices=('lsd', 'fld')),
    ParamSpec('bridge_crossings', bool, True,
              'Also find lines that other lines cross at short intervals (tiles, grids, '
              'shelving), which the detector alone loses in pieces; about 4-7 ms more CPU per '
              'detection frame at 640x480 (false saves it).'),
    ParamSpec('min_track_frames', int, 2,
              'A track must be seen in at least this many frames of the window to be segmented '
              '(capped at `window`).',
              range=(2, 30)),
    ParamSpec('label_memory', int, 10,
              'A track the solver leaves unassigned (outlier in this window) keeps the body id '
              "it was last assigned for up to this many frames; 0 = report the solver's -1.",
              range=(0, 1000)),
    ParamSpec('focal_length', float, 0.0,
              'Focal length in pixels. 0 = use camera_info (or estimate it when there is none); '
              '> 0 = fx = fy = focal_length with the principal point at the image centre, '
              'overriding camera_info (no undistortion).',
              range=(0.0, 1.0e6)),
    ParamSpec('max_frame_gap', float, 3.0,
              'Restart the window when consecutive stamps are further apart than this many '
              'nominal frame intervals (median of recent intervals), beyond the frames the '
              'node dropped itself (its full queue); 0 = never.',
              range=(0.0, 1000.0)),
    ParamSpec('seed', int, 0,
              'Random seed of the solver (results are reproducible for a given seed).',
              range=(0, 2 ** 31 - 1)),
    ParamSpec('max_pixels', int, 4096 * 4096,
              'Reject images with more pixels than this (width * height).',
              range=(1, 2 ** 31 - 1)),
    ParamSpec('publish_debug_image', bool, False,
              'Always publish ~/debug_image (it is also published whenever it has subscribers).',
              scope='node'),
    ParamSpec('queue_size', int, 2,
              'Images waiting for the tracking worker; when full, the stalest is dropped '
              '(the solver takes the newest tracked frame, see the README).',
              range=(1, 100), scope='node'),
    ParamSpec('carry_labels', bool, True,
              'Answer the frames the solver has no time for from the running fit: each '
              'segment labelled as its track was at the last solve (NaN residuals, no twist); '
              'false = publish solved frames only.',
              scope='node'),
    ParamSpec('solver_process', bool, True,
              'Solve a slow method (general) in a child process of the node, so that the '
              'solver has a core of its own beside the tracking (in a thread, the two share '
              "one: Python's interpreter lock), its searches and full solves in one more "
              'child while the frames step; false = a thread, every solve in turn. Changing '
              'it, or method between a slow and a fast one, at run time restarts the body ids.',
              scope='node'),
    ParamSpec('warn_period', float, 5.0,
              'Minimum seconds between two warnings about the same kind of bad input.',
              range=(0.0, 3600.0), scope='node'),
)

#: The table keyed by name.
PARAMS: Dict[str, ParamSpec] = {p.name: p for p in PARAMETERS}


def _type_name(t: type) -> str:
    return {int: 'integer', float: 'double', str: 'string', bool: 'bool'}[t]


def validate(name: str, value: Any) -> Optional[str]:
    """
    Check one parameter value; return None when valid, else a reason a person can read.

    Integers are accepted for doubles (and converted by :func:`coerce`); booleans are not
    integers here. Unknown names are rejected.
    """
    spec = PARAMS.get(name)
    if spec is None:
        return f'unknown parameter {name!r}; known: {", ".join(PARAMS)}'
    if value is None:
        return f'{name} must be set to a {_type_name(spec.type)} value, got no value'
    if spec.type is bool:
        if not isinstance(value, bool):
            return f'{name} must be a bool (true/false), got {type(value).__name__} {value!r}'
        return None
    if spec.type is str:
        if not isinstance(value, str):
            return f'{name} must be a string, got {type(value).__name__} {value!r}'
        choices = spec.allowed_choices()
        if choices is not None and value not in choices:
            return f'{name} must be one of {", ".join(choices)}, got {value!r}'
        if name == 'detector_backend' and value == 'fld':
            from mlofc_ros.segments.detect import has_ximgproc   # cv2 only for this value
            if not has_ximgproc():
                return ('detector_backend fld needs OpenCV contrib (cv2.ximgproc, not in this '
                        'OpenCV): install opencv-contrib-python-headless in place of '
                        'opencv-python-headless')
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        hint = ' (write e.g. 1.0)' if spec.type is float else ''
        return (f'{name} must be a{"n" if spec.type is int else ""} {_type_name(spec.type)}'
                f'{hint}, got {type(value).__name__} {value!r}')
    if spec.type is int and not isinstance(value, int):
        return f'{name} must be an integer, got double {value!r}'
    if not math.isfinite(float(value)):
        return f'{name} must be finite, got {value!r}'
    if spec.range is not None:
        lo, hi = spec.range
        if not lo <= value <= hi:
            return f'{name} must be in [{lo}, {hi}], got {value!r}'
    if name == 'window' and value == 1:       # a window of one frame observes no motion
        return f"window must be 0 (the method's own) or in [2, {hi}], got 1"
    return None


def coerce(name: str, value: Any) -> Any:
    """Return ``value`` converted to the parameter's Python type; ``ValueError`` when invalid."""
    reason = validate(name, value)
    if reason is not None:
        raise ValueError(reason)
    return PARAMS[name].type(value)


def defaults(scope: Optional[str] = None) -> Dict[str, Any]:
    """Return ``{name: default}`` for all parameters, or only those of ``scope``."""
    return {p.name: p.default for p in PARAMETERS if scope is None or p.scope == scope}


def check_all(values: Mapping[str, Any]) -> Dict[str, Any]:
    """Validate and coerce a mapping of parameters; ``ValueError`` listing every problem."""
    problems = [r for r in (validate(k, v) for k, v in values.items()) if r is not None]
    if problems:
        raise ValueError('; '.join(problems))
    return {k: PARAMS[k].type(v) for k, v in values.items()}


def parse_param(item: str) -> Tuple[str, Any]:
    """Parse ``name:=value`` as ``ros2 run ... -p`` does (YAML scalars: true, 3, 2.5, text)."""
    name, sep, text = item.partition(':=')
    if not sep or not name:
        raise ValueError(f'parameter {item!r} is not of the form name:=value')
    low = text.strip().lower()
    value: Any
    if low in ('true', 'false'):
        value = low == 'true'
    else:
        try:
            value = int(text)
        except ValueError:
            try:
                value = float(text)
            except ValueError:
                value = text.strip().strip('\'"')
    return name, value


def parse_params(items: Sequence[str]) -> Dict[str, Any]:
    """Parse and validate ``-p`` items (:func:`parse_param`); ``ValueError`` lists all."""
    return check_all(dict(parse_param(i) for i in items))


def names(scope: Optional[str] = None) -> Iterable[str]:
    """Return the parameter names in table order (only those of ``scope`` when given)."""
    return [p.name for p in PARAMETERS if scope is None or p.scope == scope]


def _fmt(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return f"'{value}'"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def markdown_table() -> str:
    """Return the parameter table as GitHub Markdown (for the README)."""
    rows = ['| name | type | default | range | dynamic | description |',
            '|---|---|---|---|---|---|']
    for p in PARAMETERS:
        if p.range is not None:
            allowed = f'[{_fmt(p.range[0])}, {_fmt(p.range[1])}]'
        elif p.allowed_choices() is not None:
            allowed = ', '.join(p.allowed_choices())
        else:
            allowed = ''
        rows.append(f'| `{p.name}` | {_type_name(p.type)} | `{_fmt(p.default)}` | {allowed} | '
                    f'{"no" if p.read_only else "yes"} | {p.description} |')
    return '\n'.join(rows)
