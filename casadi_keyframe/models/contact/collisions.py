"""How a cloth touches its bodies (``collision=``): which contact laws act on each body.

* ``"guarded"`` (the default): the paper's penalty springs in the contact layer
  (:class:`~.penalty.BodyPenalty`), and the step's hold (:class:`~.hold.BodyHold`) on the
  body's surface, so no particle passes through; on a moving body the hold is on the
  layer's surface, since the penalty springs see the body at a step's start and a body
  that moves farther than its layer in a step would otherwise kick the held particles off;
* ``"constraint"``: the hold alone, on the contact layer's surface;
* ``"penalty"``: the penalty springs alone (the paper's collisions).

The names are what problem files, saved runs and the command line give.
"""
from __future__ import annotations

from .hold import BodyHold
from .penalty import BodyPenalty

# name: (penalty springs?, the hold?, where it holds: 0 m from the surface, or None: the layer)
LAWS = {"guarded": (True, True, 0.0), "constraint": (False, True, None),
        "penalty": (True, False, None)}
COLLISIONS = tuple(LAWS)
DEFAULT_COLLISION = "guarded"


def check_collision(collision: str) -> str:
    """``collision`` if it is one of :data:`COLLISIONS`; else a ValueError naming them."""
    if collision not in LAWS:
        raise ValueError(f"collision must be one of {list(COLLISIONS)} (contact held by the "
                         f"step, or the paper's penalty springs), got {collision!r}")
    return collision


def collision_families(collision: str, bodies: tuple, n: int, jit: bool | None, masses=None,
                       gravity=(0.0, 0.0, -9.81)) -> tuple:
    """The families through which n particles (of ``masses``, under ``gravity``: what
    friction's normal impulse takes) touch ``bodies`` under ``collision``: each body's
    penalty springs, then one hold over them all (none without bodies)."""
    penalty, hold, layer = LAWS[check_collision(collision)]
    if not bodies:
        return ()
    bodies = tuple(part for body in bodies for part in body.parts())  # a mesh's pieces
    springs = tuple(BodyPenalty(body, n, jit) for body in bodies) if penalty else ()
    layers = [body.contact.thickness if layer is None or body.moves else layer
              for body in bodies]
    held = BodyHold(bodies, n, jit, layers=layers, penalty=[penalty] * len(bodies),
                    masses=masses, gravity=gravity)
    return springs + ((held,) if hold else ())
