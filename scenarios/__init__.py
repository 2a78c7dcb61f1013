"""Axis 1 — the worlds the A1 walks in (plant friction, obstacles, pushes, plant perturbations).

Each scenario implements :class:`taslel_bench.interfaces.Scenario` and is built by Hydra from
``conf/scenario/<name>.yaml``; this package imports only the core's interface and plant helpers.
"""
