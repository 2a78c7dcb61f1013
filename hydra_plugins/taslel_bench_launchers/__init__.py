"""Hydra launcher plugins of taslel_bench (Hydra only loads plugins from the ``hydra_plugins`` namespace).

``ray_launcher.RayLauncher``: the sweep's jobs as Ray tasks through joblib's ``"ray"`` backend
(``ray.util.joblib``), on a local Ray instance or a running cluster; selected by ``hydra/launcher=ray``.

``local_launcher.RobustJoblibLauncher`` (``hydra/launcher=local``, the default): joblib's loky processes with
a check that each job has its own run folder and dead workers turned into error rows.
"""
