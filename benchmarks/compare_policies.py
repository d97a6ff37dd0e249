"""Compare exploration policies on scenes x seeds. Results: docs/benchmarks/policies.md

Writes one record per episode, a Markdown table and plots. The same command as the
``naruto-benchmark`` console entry point; its arguments are the typed ``Args`` dataclass in
``naruto_agent/benchmark/cli.py`` (``--help`` lists them). Example, the 400-step comparison of
the docs page (3 seeds, shipped scenes and the Replica sample beside the repository)::

    python benchmarks/compare_policies.py \\
        --scenes replica_like_room apartment ../shared/scenes/replica_office0/mesh.ply \\
        --policies passive random frontier naruto --seeds 0 1 2 --max-episode-steps 400 \\
        --workers 2 --eval-points 1 --output-dir benchmarks/results/compare_policies

Add ``--ray-address auto`` (or ``HOST:PORT``, or ``local``) to run the episodes as Ray tasks.
Interrupt it at any time: finished episodes are kept and a rerun skips them.
"""

from __future__ import annotations

import sys

from naruto_agent.benchmark.cli import Args, main, parse_args

__all__ = ["Args", "main", "parse_args"]

if __name__ == "__main__":
    sys.exit(main())
