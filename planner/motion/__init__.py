"""Time law and sampling: feed profiles along the exact PH arc length, poses at the controller rate.

``plan_feed(path, feed, limits, ...)`` gives a jerk-limited :class:`FeedProfile` s(t) (closed form per
phase) honouring per-span feeds and speed, acceleration, jerk and tool angular speed limits;
``sample_poses(path, profile, orientation, rate=500)`` turns it into a :class:`PoseStream` of UR poses
``p[x, y, z, rx, ry, rz]`` with a continuous rotation vector, TCP offset and base transform.
:class:`FeedCaps` lower the feed on arc-length windows (``plan_feed(..., caps=...)``, :func:`cap_feed`);
:func:`lower_feed_locally` places them where a sampled trajectory (e.g. robot joints) is too fast.
"""

from planner.motion.caps import CapWindow, FeedCaps
from planner.motion.evaluator import SplineEvaluator, evaluator_for, span_bounds
from planner.motion.events import (
    OUTPUT_PINS,
    IOEvent,
    IOEventWarning,
    ScheduledEvent,
    io_states,
    io_window,
    schedule_events,
)
from planner.motion.feed import cap_feed, plan_feed, span_feeds_from_point_feeds
from planner.motion.limits import MotionInputError, MotionLimits
from planner.motion.local_feed import LoweredFeed, Measurement, lower_feed_locally
from planner.motion.orientation import (
    ConstantOrientation,
    FrameOrientation,
    orientation_rate,
    tool_orientation,
)
from planner.motion.profile import FeedProfile
from planner.motion.rotvec import continuous_rotvec, rotvec_from_quaternions
from planner.motion.stream import RATES, PoseStream, as_transform, poses_at_length, sample_poses, transform_to_pose

__all__ = [
    "OUTPUT_PINS",
    "RATES",
    "CapWindow",
    "ConstantOrientation",
    "FeedCaps",
    "FeedProfile",
    "FrameOrientation",
    "IOEvent",
    "IOEventWarning",
    "LoweredFeed",
    "Measurement",
    "MotionInputError",
    "MotionLimits",
    "PoseStream",
    "ScheduledEvent",
    "SplineEvaluator",
    "as_transform",
    "cap_feed",
    "continuous_rotvec",
    "evaluator_for",
    "io_states",
    "io_window",
    "lower_feed_locally",
    "orientation_rate",
    "plan_feed",
    "poses_at_length",
    "rotvec_from_quaternions",
    "sample_poses",
    "schedule_events",
    "span_bounds",
    "span_feeds_from_point_feeds",
    "tool_orientation",
    "transform_to_pose",
]

# Names of version 0.1.0 removed since, importable for the next release with a DeprecationWarning naming the
# replacement (planner._deprecated).
from planner._deprecated import module_getattr as _module_getattr  # noqa: E402

__getattr__ = _module_getattr(__name__)
