r"""A character made of capsules, driven by procedural animations: a moving collider for cloth.

A :class:`Character` is a skeleton of named capsules (pelvis, torso, head, upper and lower
arms and legs) with fixed lengths and radii.  An :class:`Animation` gives a :class:`Pose` at
ANY time t (root position and orientation plus joint angles) as smooth functions of t (C^2,
except C^1 where a fall starts from rest), so the central-difference velocities the colliders
take from their paths mean something and the capsules move smoothly within a step.  Forward
kinematics (:meth:`Character.segments`) turns a pose into capsule end points.

Body frame: x to the character's right, y forward, z up; the root is the pelvis centre.
The ground is the plane z = 0.  Animations: :func:`walk` (a periodic cycle), :func:`fall`
(dropped from a height, tumbling with flailing limbs, landing face down) and
:func:`transition` (one animation blended into another with a smoothstep).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
from scipy.spatial.transform import Rotation

from .models.colliders import Capsule, Contact

JOINTS = ("spine", "neck",
          "shoulder_swing_l", "shoulder_raise_l", "elbow_l",
          "shoulder_swing_r", "shoulder_raise_r", "elbow_r",
          "hip_swing_l", "hip_raise_l", "knee_l",
          "hip_swing_r", "hip_raise_r", "knee_r")
J = {name: k for k, name in enumerate(JOINTS)}
CAPSULES = ("pelvis", "torso", "head", "upper_arm_l", "lower_arm_l", "upper_arm_r",
            "lower_arm_r", "upper_leg_l", "lower_leg_l", "upper_leg_r", "lower_leg_r")
GRAVITY = 9.81


def rot(axis: int, angle: float) -> np.ndarray:
    """3x3 rotation by ``angle`` (rad) about coordinate axis 0, 1 or 2."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def smoothstep(u):
    """Quintic 0 -> 1 on [0, 1], clamped outside; first and second derivatives vanish at
    both ends, so a blend through it keeps C^2 poses C^2."""
    u = np.clip(u, 0.0, 1.0)
    return u ** 3 * (10 - 15 * u + 6 * u ** 2)


def bump(u):
    """``64 u^3 (1 - u)^3`` on [0, 1] (peak 1 at u = 1/2), zero outside; C^2."""
    u = np.clip(u, 0.0, 1.0)
    return 64 * (u * (1 - u)) ** 3


def soft_min(values, softness: float) -> float:
    """A smooth lower bound of ``min(values)`` (log-sum-exp), within ``softness log n``."""
    v = np.asarray(values, float)
    low = v.min()
    return low - softness * np.log(np.exp(-(v - low) / softness).sum())


def soft_max(a: float, b: float, softness: float) -> float:
    """A smooth upper bound of ``max(a, b)``, within ``softness log 2``."""
    return max(a, b) + softness * np.log1p(np.exp(-abs(a - b) / softness))


@dataclass(frozen=True)
class Pose:
    """Root (pelvis centre) ``position`` (3,) m, ``rotation`` (3, 3) body -> world and joint
    ``angles`` (len(JOINTS),) rad: swings and flexions positive forward, raises outward."""

    position: np.ndarray
    rotation: np.ndarray
    angles: np.ndarray


def blend(p: Pose, q: Pose, s: float) -> Pose:
    """``(1 - s) p + s q``: positions and angles linearly, the orientation along the
    geodesic (so a blend of two rigid motions stays a rigid motion)."""
    turn = Rotation.from_matrix(p.rotation.T @ q.rotation).as_rotvec()
    rotation = p.rotation @ Rotation.from_rotvec(s * turn).as_matrix()
    return Pose((1 - s) * p.position + s * q.position, rotation,
                (1 - s) * p.angles + s * q.angles)


@dataclass(frozen=True)
class Character:
    """Segment lengths and capsule radii (m) of a ~1.8 m adult; see :meth:`segments`."""

    hip_width: float = 0.10        # half the distance between the hip joints
    pelvis_radius: float = 0.12
    torso: tuple = (0.05, 0.40)    # torso segment, heights above the root along the spine
    torso_radius: float = 0.14
    shoulder_height: float = 0.45
    shoulder_width: float = 0.19   # half the distance between the shoulder joints
    neck_height: float = 0.52
    head: tuple = (0.12, 0.18)     # head segment, heights above the neck
    head_radius: float = 0.10
    upper_arm: float = 0.30
    lower_arm: float = 0.38        # forearm and hand
    arm_radii: tuple = (0.05, 0.045)
    upper_leg: float = 0.45
    lower_leg: float = 0.45
    leg_radii: tuple = (0.07, 0.055)

    def __post_init__(self):
        for name, value in self.__dict__.items():
            if not np.all(np.isfinite(value)) or np.any(np.asarray(value) <= 0):
                raise ValueError(f"Character.{name} must be positive and finite, got {value}")

    @property
    def radii(self) -> dict[str, float]:
        """Capsule name -> radius, in :data:`CAPSULES` order."""
        r = {"pelvis": self.pelvis_radius, "torso": self.torso_radius, "head": self.head_radius,
             "upper_arm": self.arm_radii[0], "lower_arm": self.arm_radii[1],
             "upper_leg": self.leg_radii[0], "lower_leg": self.leg_radii[1]}
        return {name: r[name.removesuffix("_l").removesuffix("_r")] for name in CAPSULES}

    @property
    def standing_height(self) -> float:
        """Root height with straight legs and the lower legs' capsules on the ground."""
        return self.upper_leg + self.lower_leg + self.leg_radii[1]

    def torso_frame(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """Origin (the root) and orientation of the torso (the root bent by the spine)."""
        return pose.position, pose.rotation @ rot(0, -pose.angles[J["spine"]])

    def segments(self, pose: Pose) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Forward kinematics: each capsule's end points ``(a, b)`` in world coordinates."""
        a = pose.angles
        root, R = pose.position, pose.rotation
        _, S = self.torso_frame(pose)
        up = np.array([0.0, 0.0, 1.0])
        out = {"pelvis": (root + R @ [-self.hip_width, 0, 0], root + R @ [self.hip_width, 0, 0]),
               "torso": (root + S @ (self.torso[0] * up), root + S @ (self.torso[1] * up))}
        neck = root + S @ (self.neck_height * up)
        H = S @ rot(0, -a[J["neck"]])
        out["head"] = (neck + H @ (self.head[0] * up), neck + H @ (self.head[1] * up))
        for side, sign in (("l", -1.0), ("r", 1.0)):
            shoulder = root + S @ [sign * self.shoulder_width, 0, self.shoulder_height]
            out[f"upper_arm_{side}"], out[f"lower_arm_{side}"] = self._limb(
                shoulder, S, sign, a[J[f"shoulder_raise_{side}"]],
                a[J[f"shoulder_swing_{side}"]], a[J[f"elbow_{side}"]],
                self.upper_arm, self.lower_arm)
            hip = root + R @ [sign * self.hip_width, 0, 0]
            out[f"upper_leg_{side}"], out[f"lower_leg_{side}"] = self._limb(
                hip, R, sign, a[J[f"hip_raise_{side}"]], a[J[f"hip_swing_{side}"]],
                -a[J[f"knee_{side}"]], self.upper_leg, self.lower_leg)
        return out

    @staticmethod
    def _limb(joint, parent, sign, raise_, swing, flex, upper, lower):
        """Upper and lower segments of a limb hanging down from ``joint`` at rest: raised
        outward about the forward axis, swung forward, the lower part flexed forward."""
        down = np.array([0.0, 0.0, -1.0])
        U = parent @ rot(1, -sign * raise_) @ rot(0, swing)
        middle = joint + upper * (U @ down)
        return (joint, middle), (middle, middle + lower * (U @ rot(0, flex) @ down))

    def lowest_point(self, pose: Pose) -> float:
        """Height of the body's lowest surface point (min over capsules of end z - radius)."""
        r = self.radii
        return min(min(a[2], b[2]) - r[k] for k, (a, b) in self.segments(pose).items())

    def clearance(self, pose: Pose, points) -> np.ndarray:
        """Signed distance of each point (n, 3) to the body's surface (negative inside)."""
        return capsule_clearance(points, self.segments(pose), self.radii)

    def capsules(self, animation: Animation, contact: Contact | None = None,
                 lead: float = 0.0) -> list[Capsule]:
        """The body as :class:`Capsule` colliders whose end points follow ``animation``,
        looked up ``lead`` seconds ahead (see :func:`.capes.cape_model` for why)."""
        at = _posed(self, animation)
        return [Capsule(lambda t, k=k: at(t + lead)[0][k][0],
                        lambda t, k=k: at(t + lead)[0][k][1], radius, contact)
                for k, radius in self.radii.items()]

    def shoulder_points(self, animation: Animation, offsets, *, back: float = 0.02):
        """``path(t) -> (k, 3)``: points on the shoulder line across the back of the torso,
        ``offsets`` (m, to the right; or an int k: evenly over the shoulders) from the spine,
        ``back`` m behind the torso's surface: where a cape is sewn on."""
        if np.ndim(offsets) == 0:
            if int(offsets) != offsets or offsets < 1:
                raise ValueError(f"shoulder_points needs k >= 1 points or offsets, got {offsets}")
            offsets = np.linspace(-self.shoulder_width, self.shoulder_width, int(offsets))
        local = np.zeros((np.size(offsets), 3))
        local[:, 0] = np.ravel(offsets)
        local[:, 1] = -(self.torso_radius + back)
        local[:, 2] = self.shoulder_height
        at = _posed(self, animation)

        def path(t):
            origin, S = at(t)[1]
            return origin + local @ S.T
        return path


def capsule_clearance(points, segments: dict, radii: dict) -> np.ndarray:
    """Signed distance (n,) of points (n, 3) to the union of capsules ``name -> (a, b)``."""
    p = np.asarray(points, float)
    best = np.full(len(p), np.inf)
    for name, (a, b) in segments.items():
        ab = b - a
        s = np.clip((p - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
        d = np.linalg.norm(p - (a + s[:, None] * ab), axis=1) - radii[name]
        best = np.minimum(best, d)
    return best


def _posed(character: Character, animation: Animation):
    """``at(t) -> (segments, torso frame)``, memoised: a step asks every capsule end for its
    position at t and t +- h, and forward kinematics once per time is enough."""
    @lru_cache(maxsize=32)
    def at(t: float):
        pose = animation.pose(t)
        return character.segments(pose), character.torso_frame(pose)
    return at


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


def angles(**values) -> np.ndarray:
    """A joint-angle vector from ``joint=value`` (rad); ``elbow=0.3`` sets both sides."""
    a = np.zeros(len(JOINTS))
    for name, value in values.items():
        keys = [k for k in (name, f"{name}_l", f"{name}_r") if k in J]
        if not keys:
            raise ValueError(f"unknown joint {name!r}; joints are {JOINTS}")
        a[[J[k] for k in keys]] = value
    return a


STAND = angles(shoulder_raise=0.12, elbow=0.2)
LIE = angles(neck=0.15, shoulder_raise=0.6, elbow=0.4, hip_raise=0.12, hip_swing=0.08, knee=0.1)


def _finite(name: str, value, positive: bool = False) -> float:
    if not np.isfinite(value) or (positive and value <= 0):
        kind = "positive and finite" if positive else "finite"
        raise ValueError(f"{name} must be {kind}, got {value}")
    return float(value)


def _check(clip, finite=(), positive=()):
    """ValueError naming the first option of ``clip`` that is not finite (or positive)."""
    label = type(clip).__name__.lower()
    for name in finite:
        _finite(f"{label} {name}", getattr(clip, name))
    for name in positive:
        _finite(f"{label} {name}", getattr(clip, name), positive=True)


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
        _check(self, ("speed", "stride", "arm_swing", "knee_lift", "heading"), ("period",))

    def pose(self, t: float) -> Pose:
        ph = 2 * np.pi * t / self.period
        sin = np.sin(ph)
        c = self.character
        local = np.array([0.02 * sin, self.speed * t,
                          c.standing_height - 0.04 * (1 - np.cos(2 * ph)) / 2])
        turn = rot(2, self.heading)
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
        return Pose(position, turn @ rot(2, -0.08 * sin), a)


@dataclass(frozen=True)
class Fall(Animation):
    """Dropped from rest with the feet ``height`` m above the ground: the centre of mass
    falls under gravity while the body turns ``pitch`` rad forward (about its right axis),
    ``roll`` rad about its long axis and ``yaw`` rad about the vertical, limbs flailing
    ``flail`` rad (random frequencies and phases from ``seed``), drifting ``drift`` m
    (right, forward), and lies face down once the turn ends (pitch = pi/2 mod 2 pi and roll
    = 0 mod 2 pi keep it face down).  The turn lasts ``spin_time`` times the free-fall time.

    The body is held above the ground by a smooth maximum (over ``cushion`` m) of the
    ballistic height and the height at which its lowest capsule touches the ground (a soft
    minimum over the capsules' ends, within ``softness * log 22`` m) plus ``clearance``, so it
    never goes below z = 0 and lands within a few steps instead of stopping dead (which
    snaps the cape).  The clearance leaves room for cloth caught between a limb and the
    ground: with none, the body's and the ground's contact layers overlap and squeeze the
    cloth out at metres per second.
    Before t = 0 it stands still (C^1 at t = 0: it starts at rest).  ``end``: the clip's
    length in s.  The defaults keep limbs under ~6 m/s relative to the falling body: a
    somersault (``pitch=-1.5 * pi``) or ``roll=2 * pi`` sweeps limbs through a cape at over
    10 m/s, which tears a 16 x 26 cape at dt = 1/60 (stretch 2.1-2.3, 5-9 cm deep).
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
        _check(self, ("height", "pitch", "roll", "yaw", "flail", "clearance", "heading"),
               ("spin_time", "cushion", "softness", "end"))
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
        return rot(2, self.heading + self.yaw * s) @ rot(0, -self.pitch * s) @ rot(2, self.roll * s)

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
        turn = rot(2, self.heading)
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
    t_a = _finite("transition t_a", t_a)
    t_b = _finite("transition t_b", t_b)
    window = _finite("transition window", window, positive=True)
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
