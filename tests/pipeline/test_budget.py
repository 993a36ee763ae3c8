"""The memory guard's estimate of the evidence rule's detection (set lists of at most B + 1 ids
a feature) against hand counts."""

import pytest

from pipeline.budget import (
    BYTES_PER_LIST_ENTRY,
    BYTES_PER_SYNC_LINK,
    MemoryBudget,
    check_detection_memory,
    detection_entries,
)
from pipeline.errors import InputError
from pipeline.types import Links

# a chain of 5 features over 5 cameras (one set of 5) and one link (a set of 2)
LINKS = Links([0, 1, 2, 3, 0], [0, 0, 0, 0, 1], [1, 2, 3, 4, 1], [0, 0, 0, 0, 1])
FPC = [2, 2, 1, 1, 1]


def test_entries_of_the_rows_and_of_lists_of_at_most_keep_ids():
    assert detection_entries(FPC, LINKS) == (5 * 5 + 2 * 2, 5)
    assert detection_entries(FPC, LINKS, 3) == (5 * 3 + 2 * 2, 5)
    assert detection_entries(FPC, LINKS, 100) == detection_entries(FPC, LINKS)


def test_the_lists_are_counted_beside_the_links_and_refused_past_the_limit():
    need = len(LINKS) * BYTES_PER_SYNC_LINK + (5 * 3 + 2 * 2) * BYTES_PER_LIST_ENTRY
    budget = MemoryBudget(need / 1e9)
    check_detection_memory(FPC, LINKS, budget, detection=False, set_lists=2)
    assert budget.total == need
    with pytest.raises(InputError, match="evidence rule's detection.*5 features"):
        check_detection_memory(FPC, LINKS, (need - 1) / 1e9, detection=False, set_lists=2)
