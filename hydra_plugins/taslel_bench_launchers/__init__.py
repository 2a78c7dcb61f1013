"""Hydra launcher plugins of taslel_bench (Hydra only loads plugins from the ``hydra_plugins`` namespace).

``ray_launcher.RayLauncher``: the sweep's jobs as Ray tasks through joblib's ``"ray"`` backend
(``ray.util.joblib``), on a local Ray instance or a running cluster; selected by ``hydra/launcher=ray``.
"""
