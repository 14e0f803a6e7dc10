r"""The character a cape is sewn to: a skeleton of capsules, its poses and its geometry.

A :class:`Character` is a skeleton of named capsules (pelvis, torso, head, upper and lower
arms and legs) with fixed lengths and radii; a :class:`Pose` is its root position and
orientation plus joint angles.  Forward kinematics (:meth:`Character.segments`) turns a pose
into capsule end points; :meth:`Character.capsules` and :meth:`Character.shoulder_points`
follow a :class:`Motion` (a pose at any time: an :class:`~.animations.Animation`) as moving
colliders and as the line a cape is sewn to.

Body frame: x to the character's right, y forward, z up; the root is the pelvis centre.
The ground is the plane z = 0.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Protocol

import numpy as np

from ..checks import check_fields
from ..models.contact.colliders import Capsule, Contact
from .maths import rotation, slerp

JOINTS = ("spine", "neck",
          "shoulder_swing_l", "shoulder_raise_l", "elbow_l",
          "shoulder_swing_r", "shoulder_raise_r", "elbow_r",
          "hip_swing_l", "hip_raise_l", "knee_l",
          "hip_swing_r", "hip_raise_r", "knee_r")
J = {name: k for k, name in enumerate(JOINTS)}
CAPSULES = ("pelvis", "torso", "head", "upper_arm_l", "lower_arm_l", "upper_arm_r",
            "lower_arm_r", "upper_leg_l", "lower_leg_l", "upper_leg_r", "lower_leg_r")


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
    return Pose((1 - s) * p.position + s * q.position, slerp(p.rotation, q.rotation, s),
                (1 - s) * p.angles + s * q.angles)


class Motion(Protocol):
    """What a moving body needs of an animation (:class:`~.animations.Animation`): a pose at
    any time t (s)."""

    def pose(self, t: float) -> Pose: ...


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
        check_fields(self, positive=[f.name for f in fields(self)])

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
        return pose.position, pose.rotation @ rotation(0, -pose.angles[J["spine"]])

    def segments(self, pose: Pose) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Forward kinematics: each capsule's end points ``(a, b)`` in world coordinates."""
        a = pose.angles
        root, R = pose.position, pose.rotation
        _, S = self.torso_frame(pose)
        up = np.array([0.0, 0.0, 1.0])
        out = {"pelvis": (root + R @ [-self.hip_width, 0, 0], root + R @ [self.hip_width, 0, 0]),
               "torso": (root + S @ (self.torso[0] * up), root + S @ (self.torso[1] * up))}
        neck = root + S @ (self.neck_height * up)
        H = S @ rotation(0, -a[J["neck"]])
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
        U = parent @ rotation(1, -sign * raise_) @ rotation(0, swing)
        middle = joint + upper * (U @ down)
        return (joint, middle), (middle, middle + lower * (U @ rotation(0, flex) @ down))

    def lowest_point(self, pose: Pose) -> float:
        """Height of the body's lowest surface point (min over capsules of end z - radius)."""
        r = self.radii
        return min(min(a[2], b[2]) - r[k] for k, (a, b) in self.segments(pose).items())

    def clearance(self, pose: Pose, points) -> np.ndarray:
        """Signed distance of each point (n, 3) to the body's surface (negative inside)."""
        return capsule_clearance(points, self.segments(pose), self.radii)

    def capsules(self, animation: Motion, contact: Contact | None = None,
                 lead: float = 0.0) -> list[Capsule]:
        """The body as :class:`Capsule` colliders whose end points follow ``animation``,
        looked up ``lead`` seconds ahead (see :func:`.capes.cape_model` for why)."""
        at = _posed(self, animation)
        return [Capsule(lambda t, k=k: at(t + lead)[0][k][0],
                        lambda t, k=k: at(t + lead)[0][k][1], radius, contact)
                for k, radius in self.radii.items()]

    def shoulder_points(self, animation: Motion, offsets, *, back: float = 0.02):
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


def _posed(character: Character, animation: Motion):
    """``at(t) -> (segments, torso frame)``, memoised: a step asks every capsule end for its
    position at t and t +- h, and forward kinematics once per time is enough."""
    @lru_cache(maxsize=32)
    def at(t: float):
        pose = animation.pose(t)
        return character.segments(pose), character.torso_frame(pose)
    return at


def angles(**values) -> np.ndarray:
    """A joint-angle vector from ``joint=value`` (rad); ``elbow=0.3`` sets both sides."""
    a = np.zeros(len(JOINTS))
    for name, value in values.items():
        keys = [k for k in (name, f"{name}_l", f"{name}_r") if k in J]
        if not keys:
            raise ValueError(f"unknown joint {name!r}; joints are {JOINTS}")
        a[[J[k] for k in keys]] = value
    return a
