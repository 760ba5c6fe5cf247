"""Benchmark script: the same as ``ddmr bench`` (``python benchmarks/bench.py [--quick]``)."""

import sys

from ddmr_cli.cli.bench import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
