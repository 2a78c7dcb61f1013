"""``python -m taslel_bench.qpset info|merge``: inspect or merge QP test sets (:mod:`taslel_bench.qp.qpset_tool`)."""

from taslel_bench.qp.qpset_tool import main

if __name__ == "__main__":
    main()
