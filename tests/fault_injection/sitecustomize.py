"""Fault injection for the sweep tests (tests/test_reliability_sweep.py), loaded by every Python process of
the test's sweep (main process and loky workers) through PYTHONPATH. Nothing happens unless
``TASLEL_FAULTS`` is set: ``kill=<text>`` SIGKILLs the process that starts a run whose folder contains
<text> (a worker dying as under the OOM killer); ``enospc=<text>`` makes writing that run's steps.parquet
fail with ENOSPC (a full disk); ``eacces=<text>`` makes taking that run folder's lock fail with EACCES
(a folder this process cannot write; root ignores file modes, so a chmod cannot show it). Entries are separated by
``;``. The patch is applied when ``taslel_bench.sim.run`` is first imported (nothing is imported at startup)."""

import os
import sys

_FAULTS = dict(item.split("=", 1) for item in os.environ.get("TASLEL_FAULTS", "").split(";") if "=" in item)
_TARGET = "taslel_bench.sim.run"


def _patch(run_module) -> None:
    import errno
    import signal

    from taslel_bench.record import run_files
    from taslel_bench.record.run_lock import RunLock
    from taslel_bench.record.steps_writer import StepsWriter

    original_run, original_write_parquet = run_module.run, run_files.write_parquet
    original_append = StepsWriter.append

    def run_with_faults(cfg, out_dir, *args, **kwargs):
        if "kill" in _FAULTS and _FAULTS["kill"] in str(out_dir):
            os.kill(os.getpid(), signal.SIGKILL)
        return original_run(cfg, out_dir, *args, **kwargs)

    def write_parquet_with_faults(path, frame):
        if "enospc" in _FAULTS and _FAULTS["enospc"] in str(path):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        return original_write_parquet(path, frame)

    def append_with_faults(self, frame):  # steps.parquet streams chunk by chunk (record.chunk_ticks)
        if "enospc" in _FAULTS and _FAULTS["enospc"] in str(self.path):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.tmp))
        return original_append(self, frame)

    original_acquire = RunLock.acquire

    def acquire_with_faults(self):
        if "eacces" in _FAULTS and _FAULTS["eacces"] in str(self.path):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(self.path))
        return original_acquire(self)

    RunLock.acquire = acquire_with_faults
    run_module.run = run_with_faults
    run_files.write_parquet = write_parquet_with_faults
    StepsWriter.append = append_with_faults


class _PatchOnImport:
    def find_spec(self, name, path=None, target=None):
        if name != _TARGET:
            return None
        for finder in sys.meta_path:
            if finder is not self and hasattr(finder, "find_spec"):
                spec = finder.find_spec(name, path, target)
                if spec is not None:
                    break
        else:
            return None
        exec_module = spec.loader.exec_module

        def exec_and_patch(module):
            exec_module(module)
            _patch(module)

        spec.loader.exec_module = exec_and_patch
        return spec


if _FAULTS:
    sys.meta_path.insert(0, _PatchOnImport())
