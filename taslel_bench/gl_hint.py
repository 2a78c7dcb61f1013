"""A one-line hint instead of a traceback when ``import mujoco`` fails because ``MUJOCO_GL`` names a GL
library that cannot be loaded (MuJoCo loads it at import time when the variable is set)."""

from __future__ import annotations

import os
import sys

PACKAGES = {"egl": "libegl1 libgl1-mesa-dri", "osmesa": "libosmesa6", "glfw": "libglfw3 (and a display)"}


def hint(backend: str, exc: BaseException) -> str:
    """The one line printed when MuJoCo cannot load ``MUJOCO_GL=backend``."""
    need = PACKAGES.get(backend, "a GL library MuJoCo knows (egl or osmesa)")
    return (f"error: MUJOCO_GL={backend}: MuJoCo could not load it ({type(exc).__name__}: {exc}); install {need} "
            f"(apt-get install -y {need.split(' (')[0]}), use MUJOCO_GL=egl or MUJOCO_GL=osmesa, or unset MUJOCO_GL "
            f"(only videos need rendering)")


def import_mujoco_or_exit() -> None:
    """Import MuJoCo; if that fails while ``MUJOCO_GL`` is set, print :func:`hint` and exit 1."""
    backend = os.environ.get("MUJOCO_GL", "").strip().lower()
    try:
        import mujoco  # noqa: F401 -- imported for its side effect: the GL library is loaded here
    except (ImportError, AttributeError, OSError, RuntimeError) as exc:
        if not backend:
            raise
        print(hint(backend, exc), file=sys.stderr)
        sys.exit(1)
