"""The memory guard's message on the sync rule's links says "raise the limit" once (it read
"split the input or raise the limit, or raise the limit with --max-memory-gb")."""

import pytest

from pipeline.budget import check_detection_memory
from pipeline.errors import InputError
from pipeline.types import Links


def test_the_advice_names_the_limit_once():
    links = Links([0, 0], [0, 1], [1, 1], [0, 1])
    with pytest.raises(InputError) as err:
        check_detection_memory([2, 2], links, 1e-9, detection=False)
    text = str(err.value)
    assert "split the input, or raise the limit with --max-memory-gb" in text
    assert text.count("raise the limit") == 1
