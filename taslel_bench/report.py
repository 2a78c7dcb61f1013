"""``python -m taslel_bench.report <sweep folder>``: rebuild a sweep's table and report
(:mod:`taslel_bench.sweep.report`)."""

from taslel_bench.sweep.report import main

if __name__ == "__main__":
    main()
