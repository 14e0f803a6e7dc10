"""The character as a triangle mesh: each capsule's surface meshed and moved with its
segment frame by frame (:func:`character_body`), written as a point cache beside its rest
mesh (:func:`write_body`) and read back (the cape's ``body`` option, :func:`cape_body`).

A capsule's mesh keeps its place around its axis from frame to frame: its side vector is
carried along as the axis turns (the previous one, made square to the new axis), so the
vertices do not spin about a limb.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..export.obj import write_obj
from ..export.pc2 import write_pc2
from ..geometry import basis
from ..loading import OverrideError
from ..meshes import MeshError
from ..models.contact.colliders import MeshBody
from .skeleton import Character, Motion

AROUND, RINGS = 32, 8  # vertices around a capsule, rings on each of its half-spheres
BODIES = ("capsules", "mesh")


def capsule_mesh(around: int = AROUND, rings: int = RINGS) -> tuple[np.ndarray, np.ndarray]:
    """``(places, faces)``: a closed capsule mesh as, per vertex, ``(end, cos, sin, lift)``:
    the vertex is ``end`` (0: a, 1: b) ``+ r (cos e1 + sin e2 + lift axis)``; outward faces."""
    phi = 2 * np.pi * np.arange(around) / around
    theta = np.r_[np.linspace(-np.pi / 2, 0, rings + 1)[1:], np.linspace(0, np.pi / 2,
                                                                          rings + 1)[:-1]]
    end = np.r_[np.zeros(rings), np.ones(rings)]
    ring = np.array([[e, np.cos(t) * np.cos(p), np.cos(t) * np.sin(p), np.sin(t)]
                     for e, t in zip(end, theta) for p in phi])
    places = np.vstack([[0, 0, 0, -1.0], ring, [1, 0, 0, 1.0]])
    top = len(places) - 1
    k = np.arange(around)
    faces = [np.c_[np.zeros(around, int), 1 + (k + 1) % around, 1 + k]]
    for r in range(2 * rings - 1):
        a, b = 1 + r * around + k, 1 + r * around + (k + 1) % around
        faces += [np.c_[a, b, b + around], np.c_[a, b + around, a + around]]
    last = 1 + (2 * rings - 1) * around
    faces.append(np.c_[last + k, last + (k + 1) % around, np.full(around, top)])
    return places, np.vstack(faces)


def character_frames(character: Character, animation: Motion, times) -> tuple:
    """``(frames (k, v, 3), faces)``: every capsule of ``character`` meshed and placed at
    each of ``times`` as ``animation`` poses it (one mesh of several pieces)."""
    places, faces = capsule_mesh()
    radii = character.radii
    sides = {}
    frames = []
    for t in times:
        parts = []
        for name, (a, b) in character.segments(animation.pose(float(t))).items():
            axis = (b - a) / np.linalg.norm(b - a)
            side = sides.get(name, basis(axis)[1])
            side = side - (side @ axis) * axis
            side /= np.linalg.norm(side)
            sides[name] = side
            centre = np.where(places[:, :1] > 0.5, b, a)
            parts.append(centre + radii[name] * (places[:, 1:2] * side + places[:, 2:3]
                                                 * np.cross(axis, side) + places[:, 3:] * axis))
        frames.append(np.vstack(parts))
    count = len(places)
    every = np.vstack([faces + k * count for k in range(len(radii))])
    return np.array(frames), every


def character_body(character: Character, animation: Motion, seconds: float, dt: float,
                   contact=None) -> MeshBody:
    """The character's capsules as one :class:`MeshBody` with a frame every ``dt`` from 0
    to ``seconds`` (and one more)."""
    times = np.arange(int(np.ceil(seconds / dt)) + 2) * dt
    frames, faces = character_frames(character, animation, times)
    return MeshBody(frames[0], faces, frames, times=times, contact=contact)


def write_body(path, body: MeshBody, seconds: float, dt: float) -> Path:
    """``body``'s world vertices every ``dt`` from 0 to ``seconds`` as the PC2 cache
    ``path`` beside its rest mesh ``NAME_rest.obj`` (frame 0), for :meth:`MeshBody.from_file`
    at ``fps = 1 / dt``."""
    path = Path(path)
    times = np.arange(int(np.ceil(seconds / dt)) + 2) * dt
    frames = np.array([body.world_vertices(t) for t in times])
    write_obj(path.with_name(f"{path.stem}_rest.obj"), frames[0], body.faces,
              comment=f"rest mesh for {path.name} ({1 / dt:.6g} frames per second)")
    return write_pc2(path, frames)


def cape_body(problem: str, body: str, character: Character, animation: Motion,
              seconds: float, dt: float, contact) -> list | None:
    """The colliders a cape's ``body`` option names: None for "capsules" (the character's
    own), the capsules as a mesh for "mesh", else the mesh file ``body`` (a PC2 cache at one
    frame per ``dt``), refused by the option's name when it cannot be read."""
    if body == "capsules":
        return None
    if body == "mesh":
        return [character_body(character, animation, seconds, dt, contact)]
    try:
        return [MeshBody.from_file(Path(body).expanduser(), fps=1 / dt, contact=contact)]
    except (MeshError, ImportError, ValueError) as err:
        raise OverrideError(f"{problem}: body: {err} (give {' or '.join(BODIES)} or a mesh "
                            "file)", problem, listed=False) from None
