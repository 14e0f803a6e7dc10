"""Meshes in: a cloth read from a mesh file hits target meshes at keyframes (OBJ, PLY or USD).

``cloth`` is the mesh file (its vertices are the particles, in the file's order; quads are
split into triangles with a note).  It hangs from the vertices ``pins`` names (indices, e.g.
``pins=0,29``; one index as ``pins=5,``), those of the file's vertex set ``pin_group`` (a
PLY vertex property, a USD point subset or primvar) and those inside ``pin_box``
(x0,y0,z0,x1,y1,z1).  The pinned vertices stay put, or move: with ``pin_motion`` (a
time-sampled mesh of the cloth, same vertices in the same order: USD with time samples, or
a PC2 cache beside its ``NAME_rest.obj`` at one frame per ``dt``, frames 0..steps at least)
they follow its positions at every frame, starting at its frame 0; with ``pin_body`` (a
body of ``bodies``: its index from 0 or its file's name without extension) each rides on
the body's surface point closest to it at frame 0, its offset along the normal kept.  A
pinned vertex is in no contact (the body it rides on never pushes it off its path; its free
neighbours still collide).  ``keyframes`` gives FRAME:FILE pairs: at each frame every particle
should be on its vertex of the file, which must be the cloth's mesh in another shape (same
vertices in the same order, same faces); ``align`` compares shapes after the best rigid
motion.  Metres, z up, gravity along -z; ``mass`` is the cloth's total in kg, ``ground`` (a
height), ``spheres`` (x,y,z,radius, ...) and ``bodies`` (mesh files: OBJ, PLY, USD, still or
time-sampled, or a PC2 cache beside its ``NAME_rest.obj`` at one frame per ``dt``) add
colliders, ``dt`` is the frame time and ``steps`` defaults to the last keyframe's frame.

The cloth starts at rest ``wrinkle`` metres (2 mm) out of the file's shape along its
normals: an exactly flat sheet hanging in its plane is a buckling saddle, whose exact
gradient grows by orders of magnitude per second on fine meshes
(``scenes.mesh_cloths.wrinkled``).  The controls are per-step forces on the free particles
(``control``: ``velocity`` for initial velocities only; ``smoothing`` metres searches in a
metric smooth over the mesh).  The objective: each keyframe at ``weight`` per particle,
``Smoothness(alpha)`` (``alpha``) and ``StrainLimit`` (``strain_limit``,
``strain_weight``).  ``effort`` is what the control cost measures: "acceleration" (the
default: each particle's force over its mass, as a result's effort is judged) or "force"
(the paper's ``alpha |u|^2``, under which a mesh's light corners, a quarter to a sixth of
an inner particle's mass, are the cheapest to jerk, and least-effort searches do).
``rest_band`` makes the linearized step's spring stiffness turn smoothly across rest over
that strain band (``ClothParams.rest_band``; 0 is the paper's step): the
motion is then a continuous function of the forces, which the search from zero forces
needs on a buckling sheet (``SOLVE``: scipy's trust-region least squares on the exact
residual products).  By default it is 0.05 with ``guess=none`` and 0 otherwise: along a
controller's motion the band's steep ramp makes the exact gradient grow far faster
backwards.  A result is simulated and judged under the step it was searched on.
With per-step forces the search starts from ``guess``: "aim" (the
default), a PD controller that pulls the cloth from target to target, run again with its
path aimed past each target by the miss the run before left (the springs' lag taken out,
the forces still a controller's, gentle); "track", the PD controller once, gentle but
lagging; "land", the controller landing on each target at rest by two inverse steps,
whatever force holding a target's shape takes (a snap: a start for a search, not an answer);
"none", zero forces (``scenes.mesh_cloths.tracking_guess``).  On a fine sheet the motion is
so sensitive to the forces between the keyframes (the sheet buckles) that the exact
gradient grows by many orders of magnitude over the horizon, and the search often finds
no better point than its start (a run that ends short of the keyframes exits with code 1, its
result written; ``docs/search_notes.md`` has what was measured and tried).
``--method transcription`` searches in positions instead: least effort with the keyframes
held, from the zero-force motion or ``--option start=rest`` (the sheet held still), no
controller needed and no exact gradient over the horizon.  ``SOLVE`` does not choose it:
from the aimed controller the goal is met at the start in seconds, and from zero forces
the least squares meets it in about the same time at a lower rms effort (the transcription
at a lower peak, with a margin on the tolerance); on the 30 x 30 walkthrough from rest it
takes the better part of an hour (``docs/problem_notes.md``).

    casadi-keyframe solve mesh_keyframes --set cloth=sheet.obj \\
        --set keyframes=40:wave.obj,80:fold.obj --set pins=0,29 --out results/mine

With no ``cloth`` it solves its own 12 x 12 hanging sheet with a wave at frame 40 and a fold
at frame 80 (``scenes.mesh_targets``).  A missing or unreadable file, a target of another
vertex count or other faces, a pin out of range or a frame beyond ``steps`` is refused with
the option's name (exit code 2).  The Blender add-on in ``blender/`` runs this problem.
"""
from casadi_keyframe.meshes import check_mesh
from casadi_keyframe.scenes.mesh_cloths import (EFFORTS, bodies_of, colliders_of,
                                                 mesh_keyframe_problem,
                                                 parse_keyframes, pin_body_of, pinned_of,
                                                 read_option, refuse)
from casadi_keyframe.scenes.mesh_targets import fold, hanging_sheet, wave

ZERO_START_BAND = 0.05  # rest_band's default with guess=none


def SOLVE(guess: str = "aim", **_) -> dict:
    """From zero forces scipy's trust-region least squares (on the rest band's continuous
    step, see ``rest_band``); from a controller's start, which is near the keyframes,
    L-BFGS-B."""
    method = "least-squares" if guess == "none" else "lbfgsb"
    return {"method": method, "maxiter": 200, "gradient": "adjoint"}



RANGES = {"ground": "(-inf, inf)", "steps": "[1, inf)", "dt": "(0, inf)", "mass": "(0, inf)", "weight": "[0, inf)",
          "alpha": "[0, inf)", "strain_limit": "[1, inf)", "strain_weight": "[0, inf)",
          "smoothing": "(0, inf)", "wrinkle": "[0, inf)", "rest_band": "[0, 1)", "control": ("forces", "velocity"),
          "guess": ("aim", "track", "land", "none"), "effort": EFFORTS}


def build(cloth: str | None = None, keyframes: str | None = None,
          pins: tuple[float, ...] | None = None, pin_group: str | None = None,
          pin_box: tuple[float, ...] | None = None, steps: int | None = None,
          dt: float = 1 / 60, mass: float = 0.3, control: str = "forces",
          ground: float | None = None, spheres: tuple[float, ...] | None = None,
          bodies: str | None = None, pin_motion: str | None = None,
          pin_body: str | None = None,
          weight: float = 100.0, alpha: float = 1e-4, align: bool = False,
          strain_limit: float = 1.2, strain_weight: float = 1e3,
          smoothing: float | None = None, wrinkle: float = 0.002, guess: str = "aim",
          rest_band: float | None = None, effort: str = "acceleration"):
    if cloth is None:
        if keyframes is not None:
            raise refuse("keyframes", "targets need the cloth they shape: give cloth=FILE too")
        vertices, quads = hanging_sheet(12, 12)
        sheet = check_mesh(vertices, quads)
        targets = [(40, check_mesh(wave(vertices), quads)), (80, check_mesh(fold(vertices), quads))]
        pins = (0, 11) if pins is None and pin_group is None and pin_box is None else pins
    else:
        if keyframes is None:
            raise refuse("keyframes", "give the targets as FRAME:FILE pairs, e.g. "
                                      "keyframes=40:wave.obj,80:fold.obj")
        sheet, targets = read_option("cloth", cloth), parse_keyframes(keyframes)
    if pins is not None and any(p != int(p) for p in pins):
        raise refuse("pins", f"give whole vertex indices, got {pins}")
    pinned = pinned_of(sheet, None if pins is None else [int(p) for p in pins], pin_group,
                       pin_box)
    meshes = [] if bodies is None else bodies_of(bodies, dt)
    return mesh_keyframe_problem(cloth=sheet, keyframes=targets, steps=steps, dt=dt, mass=mass,
                                 pinned=pinned, control=control,
                                 colliders=colliders_of(ground, spheres) + meshes,
                                 pin_motion=pin_motion,
                                 pin_body=None if pin_body is None else pin_body_of(pin_body,
                                                                                    meshes),
                                 weight=weight,
                                 alpha=alpha, align=align, strain_limit=strain_limit,
                                 strain_weight=strain_weight, smoothing=smoothing,
                                 wrinkle=wrinkle, guess=guess,
                                 rest_band=(ZERO_START_BAND if guess == "none" else 0.0)
                                 if rest_band is None else rest_band, effort=effort)
