"""One self-contained HTML page per result (needs plotly: ``pip install
casadi_keyframe[viewer]``): rotate and zoom, play, pause and scrub by frame, buttons that
show or hide the keyframe targets, the colliders and the trails, and above the plot the
frame, its time and, at a keyframe frame, how far the result is from it.

A cloth is a lit triangle mesh drawn by the browser's WebGL, so what is behind is hidden; a
blend shows its three clips side by side (fall, blend, walk) on equal axes; a 2-D flock is
seen from above.  plotly.js is embedded in the page (no server, no network) and positions
are stored as float32 binary.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..saved import atomic_path
from . import traces as tr

INSTALL = "pip install casadi_keyframe[viewer]"
# viewer.html#frame=N opens at frame N (and moves the slider there)
OPEN_AT_FRAME = """
var m = window.location.hash.match(/frame=(\\d+)/);
if (m) {
  var gd = document.getElementById('{plot_id}');
  Plotly.animate(gd, [m[1]], {mode: 'immediate', frame: {duration: 0, redraw: true},
                              transition: {duration: 0}});
  Plotly.relayout(gd, {'sliders[0].active': Number(m[1])});
}
"""


def plotly_module():
    """``plotly.graph_objects``, or an ImportError that says how to install it."""
    try:
        import plotly.graph_objects as go
    except ImportError:
        raise ImportError(f"the HTML viewer needs plotly, which is not installed: {INSTALL} "
                          f"(or pip install plotly)") from None
    return go


def panels(scene) -> list[dict]:
    """What each 3-D panel shows: ``title``, ``positions``, ``bodies``, ``targets``,
    ``color``; a blend's three clips side by side, else the one result."""
    own = dict(positions=scene.positions, bodies=scene.bodies, targets=scene.targets)
    if not scene.clips:
        return [dict(title=scene.name, color=tr.CLOTH, **own)]
    fall, walk = scene.clips
    return [dict(title="fall (source clip)", color=tr.CLIP, positions=fall.positions,
                 bodies=fall.bodies, targets=[]),
            dict(title="blend (optimised)", color=tr.BLEND, **own),
            dict(title="walk (source clip)", color=tr.CLIP, positions=walk.positions,
                 bodies=walk.bodies, targets=[])]


def _extent(panel) -> tuple[np.ndarray, np.ndarray]:
    pts = [panel["positions"].reshape(-1, 3)] + [t.points for t in panel["targets"]]
    middle = np.mean([p.mean(0) for p in pts], 0)
    pts += [shape.extent(middle) for b in panel["bodies"] for shape in b.shapes]
    return np.min([p.min(0) for p in pts], 0), np.max([p.max(0) for p in pts], 0)


def equal_boxes(panel_list) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(mid, half)`` per panel: its own centre, and per axis the largest half-extent of
    any panel, so every panel has the same scale on every axis."""
    ext = [_extent(p) for p in panel_list]
    half = max(1.05 * max((hi - lo).max() / 2 for lo, hi in ext), 1e-3)
    halves = np.max([np.maximum((hi - lo) / 2 * 1.05, 0.25 * half) for lo, hi in ext], 0)
    return [((lo + hi) / 2, halves) for lo, hi in ext]


def _typed(trace, update):
    """``update`` with the trace's type in each frame's data (plotly assumes "scatter")."""
    return lambda n: {"type": trace.type, **update(n)}


def build_3d(go, scene):
    """The traces, their per-frame updates and the layout scenes of a 3-D result."""
    data, moving, layout = [], [], {}
    groups = {"targets": [], "colliders": [], "trails": []}
    plist = panels(scene)
    el, az = np.radians(scene.camera)
    eye = (1.45 if len(plist) == 1 else 1.8) * np.array(
        [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    for i, (panel, (mid, half)) in enumerate(zip(plist, equal_boxes(plist))):
        sid = "scene" if i == 0 else f"scene{i + 1}"

        def add(trace_update, group=None):
            trace, update = trace_update if isinstance(trace_update, tuple) else (trace_update, None)
            trace.showlegend = i == len(plist) // 2
            if group:
                groups[group].append(len(data))
            if update is not None:
                moving.append((len(data), _typed(trace, update)))
            data.append(trace)

        pos = panel["positions"]
        if scene.faces is not None:
            add(tr.surface(go, pos, scene.faces, panel["color"], panel["title"], sid))
        else:
            add(tr.agents(go, pos, scene.highlight, True, sid))
            add(tr.trails(go, pos, True, sid), "trails")
        if panel["bodies"]:
            add(tr.colliders(go, panel["bodies"], mid, float(half.max()), sid, scene.frames),
                "colliders")
        for target, t in zip(panel["targets"],
                             tr.target_traces(go, panel["targets"], scene.faces, sid)):
            add((t, tr.target_opacity(target)), "targets")
        if scene.ring is not None and panel["targets"]:
            add(tr.ring_trace(go, scene.ring, sid), "targets")
        add(tr.com_path(go, pos, sid), "trails")
        w = 1 / len(plist)
        layout[sid] = dict(
            domain=dict(x=[i * w, (i + 1) * w], y=[0, 1]),
            aspectmode="manual", aspectratio=dict(zip("xyz", (half / half.max()).tolist())),
            camera=dict(eye=dict(zip("xyz", eye.tolist()))),
            **{f"{a}axis": dict(range=[float(mid[k] - half[k]), float(mid[k] + half[k])],
                                autorange=False, title=a)
               for k, a in enumerate("xyz")})
        if len(plist) > 1:
            layout.setdefault("annotations", []).append(dict(
                text=panel["title"], x=(i + 0.5) * w, y=1.0, xref="paper", yref="paper",
                showarrow=False, font=dict(size=13)))
    return data, moving, layout, groups


def build_2d(go, scene):
    """The traces, per-frame updates and axes of a flock seen from above."""
    pos, groups = scene.positions, {"targets": [], "colliders": [], "trails": []}
    data = tr.flat_targets(go, scene.targets)
    groups["targets"] = list(range(len(data)))
    moving = [(i, _typed(trace, tr.target_opacity(target)))
              for i, (target, trace) in enumerate(zip(scene.targets, data))]
    for trace, update in (tr.trails(go, pos, False, None),
                          tr.agents(go, pos, scene.highlight, False, None)):
        if trace.name == "trails":
            groups["trails"].append(len(data))
        moving.append((len(data), _typed(trace, update)))
        data.append(trace)
    pts = np.vstack([pos.reshape(-1, 3)] + [t.points for t in scene.targets])[:, :2]
    lo, hi = pts.min(0), pts.max(0)
    pad = 0.06 * (hi - lo).max() + 0.3
    layout = dict(xaxis=dict(range=[lo[0] - pad, hi[0] + pad], autorange=False, title="x"),
                  yaxis=dict(range=[lo[1] - pad, hi[1] + pad], autorange=False, title="y",
                             scaleanchor="x"))
    return data, moving, layout, groups


def caption(scene, n: int) -> str:
    """The numbers above the plot at frame ``n``: frame, time, a cloth's largest spring
    stretch, and the keyframe misses."""
    text = f"<b>{scene.name}</b>   frame {n} / {scene.frames - 1}   t = {n * scene.dt:.3f} s"
    if scene.stretch is not None:
        text += f"   largest stretch {scene.stretch[n]:.3g}"
    if n in scene.misses:
        text += f"<br>keyframe: {scene.misses[n]}"
    return text


def figure(scene):
    """The plotly figure of ``scene``: traces, one animation frame per result frame,
    play / pause, a frame slider and the show / hide buttons."""
    go = plotly_module()
    flat = scene.dim == 2 and scene.faces is None
    data, moving, layout, groups = (build_2d if flat else build_3d)(go, scene)
    notes = layout.pop("annotations", [])

    def note(n):
        return [*notes, dict(text=caption(scene, n), x=0, y=1.1, xref="paper", yref="paper",
                             xanchor="left", yanchor="bottom", showarrow=False, align="left")]

    frames = [go.Frame(name=str(n), data=[update(n) for _, update in moving],
                       traces=[i for i, _ in moving], layout=dict(annotations=note(n)))
              for n in range(scene.frames)]
    fig = go.Figure(data=data, frames=frames)
    fig.update_layout(**layout, annotations=note(0), height=800,
                      margin=dict(l=10, r=10, t=110, b=190),
                      legend=dict(orientation="h", x=0, y=-0.3, xanchor="left",
                                  yanchor="top"),  # below the controls: it hides no data
                      updatemenus=controls(scene, groups), sliders=[slider(scene)],
                      uirevision="keep")
    return fig


def controls(scene, groups) -> list[dict]:
    """Play / pause, and one show / hide toggle per group that has traces."""
    ms = max(1000 * scene.dt, 1)
    play = dict(label="\u25b6 play", method="animate",
                args=[None, dict(frame=dict(duration=ms, redraw=True), fromcurrent=True,
                                 transition=dict(duration=0), mode="immediate")])
    pause = dict(label="\u275a\u275a pause", method="animate",
                 args=[[None], dict(frame=dict(duration=0, redraw=False), mode="immediate")])
    menus = [dict(type="buttons", direction="left", x=0, y=-0.1, xanchor="left",
                  yanchor="top", showactive=False, buttons=[play, pause])]
    toggles = [dict(label=f"{name} on/off", method="restyle",
                    args=[{"visible": False}, idx], args2=[{"visible": True}, idx])
               for name, idx in groups.items() if idx]
    if toggles:
        menus.append(dict(type="buttons", direction="left", x=0.25, y=-0.1, xanchor="left",
                          yanchor="top", showactive=False, buttons=toggles))
    return menus


def slider(scene) -> dict:
    """A slider with one step per frame, about 20 of them labelled (the caption above the
    plot names the frame shown)."""
    every = max(1, int(np.ceil(scene.frames / 20)))
    steps = [dict(label=str(n) if n % every == 0 else "", method="animate",
                  args=[[str(n)], dict(mode="immediate", frame=dict(duration=0, redraw=True),
                                       transition=dict(duration=0))])
             for n in range(scene.frames)]
    return dict(steps=steps, active=0, x=0.0, len=1.0, y=-0.18, yanchor="top",
                currentvalue=dict(visible=False), pad=dict(t=10))


def write_viewer(scene, path) -> Path:
    """Write the viewer of ``scene`` to ``path``, whole or not at all; plotly.js inside."""
    html = figure(scene).to_html(include_plotlyjs=True, full_html=True, auto_play=False,
                                 config=dict(displaylogo=False, responsive=True),
                                 post_script=OPEN_AT_FRAME)
    with atomic_path(path) as tmp:
        tmp.write_text(html, encoding="utf-8")
    return Path(path)


def write_page(scene, folder) -> list[Path]:
    """``viewer.html`` in ``folder`` (the :data:`~casadi_keyframe.export.FORMATS` writer)."""
    return [write_viewer(scene, Path(folder) / "viewer.html")]
