"""A recorded run replayed in MuJoCo Studio's web viewer: ``python -m taslel_bench.view <run folder>``
(:mod:`taslel_bench.view.__main__`). The run's plant is rebuilt from its ``config.yaml``
(:func:`taslel_bench.record.video.plant_of_run`) and posed tick by tick from ``steps.parquet``
(:mod:`~taslel_bench.view.recording`, :mod:`~taslel_bench.view.playback`); :mod:`~taslel_bench.view.panel` adds
the camera, force arrows and the run's window; :mod:`~taslel_bench.view.server` serves it on one interface;
:mod:`~taslel_bench.view.browser` drives headless Chromium for screenshots."""
