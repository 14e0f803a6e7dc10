r"""Procedural animations of a :class:`~.skeleton.Character`: a :class:`~.skeleton.Pose` at
ANY time t.

Poses are smooth functions of t (C^2, except C^1 where a fall starts from rest), so the
central-difference velocities the colliders take from their paths mean something and the
capsules move smoothly within a step.  :func:`walk` (a periodic cycle), :func:`fall`
(dropped from a height, tumbling with flailing limbs, landing face down) and
:func:`transition` (one animation blended into another with a smoothstep).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..checks import check_fields, check_number
from ..objectives.paths import smoothstep
from .maths import bump, rotation, soft_max, soft_min
from .skeleton import J, JOINTS, Character, Pose, angles, blend

GRAVITY = 9.81


class Animation:
    """A pose for every time t (s).  ``start``, ``end``: the clip proper (used to check that
    a transition window lies inside it); poses exist, and stay smooth, outside too."""

    start: float = 0.0
    end: float = np.inf

    def pose(self, t: float) -> Pose:
        raise NotImplementedError

    def shifted(self, delay: float) -> Animation:
        """This animation ``delay`` s later: ``shifted(d).pose(t) == pose(t - d)``."""
        return Shifted(self, float(delay))


@dataclass(frozen=True)
class Shifted(Animation):
    base: Animation
    delay: float

    @property
    def start(self):
        return self.base.start + self.delay

    @property
    def end(self):
        return self.base.end + self.delay

    def pose(self, t):
        return self.base.pose(t - self.delay)


STAND = angles(shoulder_raise=0.12, elbow=0.2)
LIE = angles(neck=0.15, shoulder_raise=0.6, elbow=0.4, hip_raise=0.12, hip_swing=0.08, knee=0.1)


@dataclass(frozen=True)
class Walk(Animation):
    """A periodic walk along ``heading`` (rad from +y, counter-clockwise) at ``speed`` m/s,
    one stride (two steps) per ``period`` s; ``pose(t + period)`` is ``pose(t)`` moved
    ``speed * period`` forward.  Legs swing ``stride`` rad, arms ``arm_swing`` rad in
    opposition, knees flex up to ``knee_lift`` rad early in a leg's swing; the pelvis bobs,
    sways and turns with the steps."""

    character: Character = field(default_factory=Character)
    speed: float = 1.3
    period: float = 1.1
    stride: float = 0.4
    arm_swing: float = 0.35
    knee_lift: float = 0.7
    heading: float = 0.0
    origin: tuple = (0.0, 0.0)

    def __post_init__(self):
        check_fields(self, finite=("speed", "stride", "arm_swing", "knee_lift", "heading"),
                     positive=("period",))

    def pose(self, t: float) -> Pose:
        ph = 2 * np.pi * t / self.period
        sin = np.sin(ph)
        c = self.character
        local = np.array([0.02 * sin, self.speed * t,
                          c.standing_height - 0.04 * (1 - np.cos(2 * ph)) / 2])
        turn = rotation(2, self.heading)
        position = np.array([*self.origin, 0.0]) + turn @ local
        a = np.zeros(len(JOINTS))
        a[J["spine"]], a[J["neck"]] = 0.06, -0.06
        for side, s in (("l", 1.0), ("r", -1.0)):  # the left leg leads while sin > 0
            a[J[f"hip_swing_{side}"]] = s * self.stride * sin
            a[J[f"hip_raise_{side}"]] = 0.03
            lift = (1 + np.cos(ph - 0.6 - (s < 0) * np.pi)) / 2  # 1 early in its swing
            a[J[f"knee_{side}"]] = 0.08 + self.knee_lift * lift ** 3
            a[J[f"shoulder_swing_{side}"]] = -s * self.arm_swing * sin
            a[J[f"shoulder_raise_{side}"]] = 0.12
            a[J[f"elbow_{side}"]] = 0.3 + 0.25 * (1 - s * sin) / 2
        return Pose(position, turn @ rotation(2, -0.08 * sin), a)


@dataclass(frozen=True)
class Fall(Animation):
    """Dropped from rest with the feet ``height`` m above the ground: the centre of mass
    falls under gravity while the body turns ``pitch`` rad forward, ``roll`` rad about its
    long axis and ``yaw`` rad about the vertical, limbs flailing ``flail`` rad (random
    frequencies and phases from ``seed``), drifting ``drift`` m (right, forward), and lies
    face down once the turn ends, which lasts ``spin_time`` times the free-fall time.

    The body is held above the ground by a smooth maximum (over ``cushion`` m) of the
    ballistic height and the height at which its lowest capsule touches the ground, plus
    ``clearance`` (room for cloth caught between a limb and the ground), so it lands within
    a few steps instead of stopping dead.  Before t = 0 it stands still (C^1 at t = 0).
    ``end``: the clip's length in s.  The defaults keep limbs slow enough relative to the
    falling body for a cape at dt = 1/60; a somersault or a full roll sweeps them through it
    fast enough to tear it (docs/problem_notes.md).
    """

    character: Character = field(default_factory=Character)
    height: float = 2.0
    pitch: float = 0.5 * np.pi
    roll: float = 0.0
    yaw: float = 0.6
    flail: float = 0.5
    drift: tuple = (0.15, 0.5)
    spin_time: float = 1.0
    cushion: float = 0.3
    softness: float = 0.005
    clearance: float = 0.025
    seed: int = 0
    heading: float = 0.0
    origin: tuple = (0.0, 0.0)
    end: float = 3.0

    def __post_init__(self):
        check_fields(self, finite=("height", "pitch", "roll", "yaw", "flail", "clearance",
                                    "heading"),
                     positive=("spin_time", "cushion", "softness", "end"))
        if self.height < 0:
            raise ValueError(f"fall height must be >= 0 (feet above the ground), got {self.height}")
        rng = np.random.default_rng(self.seed)
        object.__setattr__(self, "_freq", 2 * np.pi * rng.uniform(0.7, 1.5, len(JOINTS)))
        object.__setattr__(self, "_phase", rng.uniform(0, 2 * np.pi, len(JOINTS)))

    COM = 0.15  # centre of mass above the root, body frame, m

    @cached_property
    def spin_duration(self) -> float:
        """Seconds the turn takes: ``spin_time`` times the free fall onto the final pose."""
        start = self.height + self.character.standing_height + self.COM
        lying = self._support(self._orientation(1.0), LIE)
        return self.spin_time * np.sqrt(2 * max(start - lying, 1e-3) / GRAVITY)

    def _orientation(self, s: float) -> np.ndarray:
        return (rotation(2, self.heading + self.yaw * s) @ rotation(0, -self.pitch * s)
                @ rotation(2, self.roll * s))

    def _support(self, R: np.ndarray, angles: np.ndarray) -> float:
        """Centre-of-mass height at which the body (orientation R, ``angles``) touches z = 0."""
        probe = Pose(-R @ [0, 0, self.COM], R, angles)
        r = self.character.radii
        low = [p[2] - r[k] for k, ends in self.character.segments(probe).items() for p in ends]
        return self.clearance - soft_min(low, self.softness)

    def pose(self, t: float) -> Pose:
        u = max(float(t), 0.0) / self.spin_duration
        s = smoothstep(u)
        R = self._orientation(s)
        a = (1 - s) * STAND + s * LIE + self.flail * bump(u) * np.sin(self._freq * t + self._phase)
        start = self.height + self.character.standing_height + self.COM
        ballistic = start - 0.5 * GRAVITY * max(float(t), 0.0) ** 2
        z = soft_max(ballistic, self._support(R, a), self.cushion)
        turn = rotation(2, self.heading)
        com = np.array([*self.origin, 0.0]) + turn @ [self.drift[0] * s, self.drift[1] * s, 0.0]
        com[2] = z
        return Pose(com - R @ [0, 0, self.COM], R, a)


@dataclass(frozen=True)
class Transition(Animation):
    """``first`` until ``t_a``, then over ``[t_a, t_a + window]`` a smoothstep blend into
    ``second`` played from its time ``t_b`` (``second(t - t_a + t_b)`` moved by ``offset``),
    then ``second`` alone.  Time is ``first``'s clock."""

    first: Animation
    second: Animation
    t_a: float
    t_b: float
    window: float
    offset: np.ndarray

    @property
    def start(self):
        return self.first.start

    @property
    def end(self):
        return self.second.end + self.t_a - self.t_b

    def _second(self, t: float) -> Pose:
        p = self.second.pose(t - self.t_a + self.t_b)
        return Pose(p.position + self.offset, p.rotation, p.angles)

    def pose(self, t: float) -> Pose:
        if t <= self.t_a:
            return self.first.pose(t)
        if t >= self.t_a + self.window:
            return self._second(t)
        return blend(self.first.pose(t), self._second(t), smoothstep((t - self.t_a) / self.window))


walk, fall = Walk, Fall  # walk(character, speed=...), fall(character, height=...)


def transition(first: Animation, second: Animation, t_a: float, t_b: float, window: float,
               offset=None) -> Transition:
    """``first`` blended into ``second`` over ``window`` s from ``first``'s time ``t_a``,
    where ``second`` is at its time ``t_b`` (see :class:`Transition`).

    ``offset`` (3,) m moves ``second``; by default horizontally so that its root at ``t_b``
    stands where ``first``'s is at ``t_a`` (the two clips line up where the blend begins).
    """
    t_a = check_number("transition t_a", t_a)
    t_b = check_number("transition t_b", t_b)
    window = check_number("transition window", window, positive=True)
    for name, clip, t in (("first", first, t_a), ("second", second, t_b)):
        if not isinstance(clip, Animation):
            raise ValueError(f"transition: {name} must be an Animation, got {clip!r}")
        if not (clip.start <= t and t + window <= clip.end):
            raise ValueError(
                f"transition window [{t}, {t + window}] lies outside the {name} clip "
                f"[{clip.start}, {clip.end}]; choose t_{'a' if name == 'first' else 'b'} "
                "and window so that the blend happens while both clips play")
    if offset is None:
        offset = first.pose(t_a).position - second.pose(t_b).position
        offset[2] = 0.0
    offset = np.asarray(offset, float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)):
        raise ValueError(f"transition offset must be 3 finite numbers, got {offset!r}")
    return Transition(first, second, t_a, t_b, window, offset)
