"""``python -m taslel_bench.replay <qps.npz>``: replay a QP test set on every backend
(:mod:`taslel_bench.qp.replay`)."""

from taslel_bench.qp.replay import main

if __name__ == "__main__":
    main()
