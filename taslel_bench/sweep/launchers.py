"""Which package each Hydra launcher of ``conf/hydra/launcher/`` needs, and a hint naming the pip extra
when it is missing (checked before Hydra composes the config, whose own error would not say it)."""

from __future__ import annotations

import importlib.util
import re
from collections.abc import Callable, Sequence

_SUBMITIT = ("hydra_plugins.hydra_submitit_launcher", "hydra-submitit-launcher", "slurm")
# hydra/launcher option -> (module it imports, its PyPI distribution, the pip extra of this project)
LAUNCHER_PACKAGES: dict[str, tuple[str, str, str]] = {
    "ray": ("ray", "ray", "ray"),
    "slurm": _SUBMITIT,
    "submitit_local": _SUBMITIT,
    "submitit_slurm": _SUBMITIT,
}
_LAUNCHER_OVERRIDE = re.compile(r"^(?:\+{1,2})?hydra/launcher=(\S+)$")


class LauncherNotInstalled(ImportError):
    """The chosen ``hydra/launcher`` needs a package that is not installed."""


def _installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


def require_launcher_package(launcher: str, installed: Callable[[str], bool] = _installed) -> None:
    """Raise :class:`LauncherNotInstalled` naming the pip extra if ``launcher`` cannot be loaded here."""
    if launcher not in LAUNCHER_PACKAGES:
        return
    module, distribution, extra = LAUNCHER_PACKAGES[launcher]
    if not installed(module):
        raise LauncherNotInstalled(
            f"hydra/launcher={launcher} needs {distribution}, which is not installed (no module {module}): "
            f'pip install -e ".[{extra}]" (from the repository root, in the project\'s venv)'
        )


def register_submitit_launchers() -> None:
    """Put this project's submitit launchers (error rows for lost jobs,
    ``hydra_plugins/taslel_bench_launchers/submitit_launcher.py``) under hydra-submitit-launcher's option
    names. Hydra's plugin scan runs that package's registrations (again) in an order of its own, so ours are
    made after the scan: call this before ``hydra.main`` (the scan happens once per process). Nothing to do
    without the ``slurm`` extra."""
    if not _installed("hydra_plugins.hydra_submitit_launcher"):
        return
    import importlib

    from hydra.core.plugins import Plugins

    Plugins.instance()  # the scan, now, so that it does not run after the registration below
    module = importlib.import_module("hydra_plugins.taslel_bench_launchers.submitit_launcher")
    module.register()


def check_launcher_overrides(argv: Sequence[str], installed: Callable[[str], bool] = _installed) -> None:
    """Check the launcher chosen on the command line (``hydra/launcher=<name>``)."""
    for arg in argv:
        match = _LAUNCHER_OVERRIDE.match(arg)
        if match:
            require_launcher_package(match.group(1), installed)
