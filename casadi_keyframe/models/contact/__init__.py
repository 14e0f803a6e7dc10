"""Contact: the bodies a cloth touches and the laws that act on them.

:mod:`.colliders` (the bodies' geometry: planes, spheres, capsules, meshes; moving and
turning), :mod:`.penalty` (the paper's stiff springs, and self-contact), :mod:`.hold` (the
step's hold on a body's surface), :mod:`.held_set` (what the hold decided for one step),
:mod:`.tangential` (the seam a law of tangential motion fills), :mod:`.stick_slide` (the
hold's stick and slide decisions), :mod:`.friction` (Coulomb's law) and :mod:`.collisions`
(which laws act on each body, ``collision=``).  The public names are re-exported by
:mod:`casadi_keyframe.models`; this face imports nothing, so a family module may import a
contact module without a cycle.
"""
