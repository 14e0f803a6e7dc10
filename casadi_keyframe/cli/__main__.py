"""``python -m casadi_keyframe.cli``: the ``casadi-keyframe`` command."""
import sys

from . import main

sys.exit(main())
