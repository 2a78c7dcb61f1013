"""``python -m taslel_bench.bench``: what a control tick costs, part by part (:mod:`taslel_bench.qp.tick_bench`)."""

from taslel_bench.qp.tick_bench import main

if __name__ == "__main__":
    main()
