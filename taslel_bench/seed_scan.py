"""``python -m taslel_bench.seed_scan``: does every seed start and stand (:mod:`taslel_bench.sim.seed_scan`)."""

from taslel_bench.sim.seed_scan import main

if __name__ == "__main__":
    main()
