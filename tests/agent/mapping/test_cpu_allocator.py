"""The glibc allocator tuning: freed tensor memory is reused instead of faulted in again."""

from __future__ import annotations

import resource
import sys

import pytest
import torch

from naruto_agent.mapping.cpu_allocator import (
    MAX_MMAP_THRESHOLD_BYTES,
    keep_freed_memory_for_reuse,
)


def _minor_faults_of_reallocating(megabytes: int, repeats: int) -> int:
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(repeats):
        block = torch.empty(megabytes * 1024 * 1024 // 4, dtype=torch.float32)
        block.fill_(1.0)  # touch every page
        del block
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc tuning is Linux-only")
def test_freed_blocks_are_reused_without_page_faults() -> None:
    if not keep_freed_memory_for_reuse():
        pytest.skip("this C library is not glibc")
    _minor_faults_of_reallocating(16, 12)  # the heap grows to hold the block
    pages_per_block = 16 * 1024 * 1024 // 4096
    # Without the tuning every 16 MB block is a fresh mmap: ~4,096 faults per repeat.
    assert _minor_faults_of_reallocating(16, 10) < pages_per_block


def test_bad_thresholds_are_refused_with_the_limit() -> None:
    with pytest.raises(ValueError, match="glibc's maximum"):
        keep_freed_memory_for_reuse(mmap_threshold_bytes=MAX_MMAP_THRESHOLD_BYTES + 1)
    with pytest.raises(ValueError, match="trim_threshold_bytes"):
        keep_freed_memory_for_reuse(trim_threshold_bytes=0)
