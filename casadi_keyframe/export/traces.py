"""The viewer's pieces as plotly traces (:mod:`.viewer` assembles them): a cloth surface, a
flock's agents and trails, colliders, keyframe targets, the ring and the centre-of-mass path.

Each builder returns ``(trace, update)``: the trace at frame 0 and, for what moves, a
function giving the trace's data at frame ``n`` (None for what stays).  Positions go out as
float32 arrays, which plotly writes into the page as compact binary; gaps in a polyline are
NaN.
"""
from __future__ import annotations

import numpy as np

from ..geometry import circle
from ..models.topology import mesh_edges
from ..objectives.markers import Outline, Points, WholeShape

CLOTH, CLIP, BLEND, AGENT, HIGHLIGHT = "#6a8fc7", "#8d9bb0", "#e1812c", "#4c72b0", "#e1812c"
TARGET, BODY, RING, COM, REGION = "#d62728", "#9a9a9a", "#e1812c", "#7b4ea3", "#3a923a"
TRAIL = 10  # frames of a flock agent's trail
LIGHT = dict(ambient=0.45, diffuse=0.7, specular=0.1, roughness=0.8)


def f32(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float32)


def xyz(points) -> dict:
    """``{"x": ..., "y": ..., "z": ...}`` of ``(k, 3)`` points, as float32."""
    p = f32(points)
    return {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]}


def polylines(lines) -> np.ndarray:
    """Several ``(k, 3)`` polylines as one array, separated by NaN rows (gaps)."""
    gap = np.full((1, 3), np.nan)
    return np.vstack([np.vstack([np.asarray(line, float), gap]) for line in lines])


def surface(go, positions, faces, color, name, scene, group=None):
    """A cloth as a lit triangle mesh (depth-correct in the browser); moves every frame."""
    faces = np.asarray(faces, int)
    trace = go.Mesh3d(**xyz(positions[0]), i=faces[:, 0], j=faces[:, 1], k=faces[:, 2],
                      color=color, flatshading=True, lighting=LIGHT, name=name, scene=scene,
                      legendgroup=group, showlegend=True, hoverinfo="skip")
    return trace, lambda n: xyz(positions[n])


def bodies_mesh(body_list, n: int, mid, half, k: int = 6):
    """``(vertices, triangles)`` of every collider at frame ``n`` (planes as a square of
    half-side ``half`` below ``mid``, round bodies as coarse capsule grids)."""
    verts, tris = [], []
    for body in body_list:
        v, t = body.at(n).triangles(mid, half, k)
        tris.append(t + sum(len(x) for x in verts))
        verts.append(v)
    return np.vstack(verts), np.vstack(tris)


def colliders(go, body_list, mid, half, scene, frames: int):
    """All colliders of a panel as one translucent grey mesh; moves if any body moves."""
    verts, tris = bodies_mesh(body_list, 0, mid, half)
    trace = go.Mesh3d(**xyz(verts), i=tris[:, 0], j=tris[:, 1], k=tris[:, 2], color=BODY,
                      opacity=0.45, flatshading=True, lighting=LIGHT, name="colliders",
                      legendgroup="colliders", scene=scene, hoverinfo="skip")
    if not any(b.moving for b in body_list):
        return trace, None
    return trace, lambda n: xyz(bodies_mesh(body_list, n, mid, half)[0])


def target_name(target) -> str:
    """``"target at frame 40 (StateKeyframe@40)"``: what the legend and a hover say."""
    return f"target at frame {target.frame} ({target.label})"


def target_opacity(target):
    """A target's opacity at frame ``n``: whole at its own frame, faint elsewhere, so the
    cloth is seen through the targets not due."""
    return lambda n: {"opacity": 1.0 if n == target.frame else 0.2}


def _edges(go, t, faces, common):
    line = polylines(t.points[e] for e in mesh_edges(faces))
    return go.Scatter3d(**xyz(line), mode="lines", line=dict(color=TARGET, width=2), **common)


def _diamonds(go, t, faces, common):
    return go.Scatter3d(**xyz(t.points), mode="markers",
                        marker=dict(symbol="diamond", size=4, color=TARGET), **common)


def _loop(go, t, faces, common):
    return go.Scatter3d(**xyz(np.vstack([t.points, t.points[:1]])), mode="lines",
                        line=dict(color=REGION, width=4), **common)


# a 3-D panel's trace of each figure of a keyframe target (objectives.markers.Figure)
TARGET_TRACES = {WholeShape: _edges, Points: _diamonds, Outline: _loop}


def target_traces(go, targets, faces, scene):
    """Each keyframe target by its figure (:data:`TARGET_TRACES`): a whole-cloth shape as
    its edges, points as diamonds, a region as its outline; all in one legend group, each
    named with its frame."""
    return [TARGET_TRACES[t.figure](go, t, faces, dict(name=target_name(t), legendgroup="targets",
                                                       scene=scene, hoverinfo="name"))
            for t in targets]


def ring_trace(go, ring, scene):
    """The view's ring as a thick circle."""
    return go.Scatter3d(**xyz(circle(ring.center, ring.normal, ring.radius)), mode="lines",
                        line=dict(color=RING, width=8), name="ring", legendgroup="targets",
                        scene=scene, hoverinfo="name")


def com_path(go, positions, scene):
    """The mass-uniform centre of the particles over all frames, as a thin line (the
    "trails" of a cloth)."""
    return go.Scatter3d(**xyz(positions.mean(axis=1)), mode="lines",
                        line=dict(color=COM, width=3), name="centre path",
                        legendgroup="trails", scene=scene, hoverinfo="skip")


def agents(go, positions, highlight, three_d: bool, scene):
    """A flock's agents as dots (highlighted ones larger, orange)."""
    n = positions.shape[1]
    hl = np.zeros(n, bool)
    hl[list(highlight)] = True
    marker = dict(color=np.where(hl, HIGHLIGHT, AGENT).tolist(),
                  size=np.where(hl, 9, 5).tolist())
    if three_d:
        trace = go.Scatter3d(**xyz(positions[0]), mode="markers", marker=marker, name="agents",
                             scene=scene, hovertext=[f"agent {i}" for i in range(n)])
        return trace, lambda n_: xyz(positions[n_])
    trace = go.Scatter(x=f32(positions[0, :, 0]), y=f32(positions[0, :, 1]), mode="markers",
                       marker=marker, name="agents", hovertext=[f"agent {i}" for i in range(n)])
    return trace, lambda n_: {"x": f32(positions[n_, :, 0]), "y": f32(positions[n_, :, 1])}


def trails(go, positions, three_d: bool, scene):
    """Each agent's last :data:`TRAIL` frames as thin lines (NaN-separated)."""
    def at(n):
        lines = polylines(positions[max(0, n - TRAIL):n + 1].transpose(1, 0, 2))
        return xyz(lines) if three_d else {"x": f32(lines[:, 0]), "y": f32(lines[:, 1])}

    style = dict(mode="lines", line=dict(color=AGENT, width=1), opacity=0.5, name="trails",
                 legendgroup="trails", hoverinfo="skip")
    first = at(0)
    trace = go.Scatter3d(**first, scene=scene, **style) if three_d else go.Scatter(**first, **style)
    return trace, at


def _filled(go, t, common):
    p = np.vstack([t.points, t.points[:1]])
    return go.Scatter(x=f32(p[:, 0]), y=f32(p[:, 1]), mode="lines", fill="toself",
                      line=dict(color=REGION, width=1.5), **common)


def _crosses(go, t, common):
    return go.Scatter(x=f32(t.points[:, 0]), y=f32(t.points[:, 1]), mode="markers",
                      marker=dict(symbol="x", size=9, color=COM), **common)


# a 2-D flock's trace of each figure of a keyframe target (a flock has no surface: a whole
# shape is drawn as its points)
FLAT_TARGET_TRACES = {Outline: _filled, Points: _crosses, WholeShape: _crosses}


def flat_targets(go, targets):
    """A 2-D flock's targets by their figure (:data:`FLAT_TARGET_TRACES`): region outlines
    filled lightly, point targets as crosses."""
    return [FLAT_TARGET_TRACES[t.figure](go, t, dict(name=target_name(t), legendgroup="targets",
                                                     hoverinfo="name"))
            for t in targets]
