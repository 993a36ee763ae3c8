"""``run-images --connect URL``: a URL that Python's URL parser itself refuses (an unclosed
IPv6 bracket) raised ValueError as a traceback; it is said as any malformed URL."""

import pytest

from pipeline.commands.run_images import check_live
from pipeline.errors import InputError


@pytest.mark.parametrize("url", ["rerun+http://[::1", "rerun+http://[::1:9876/proxy",
                                 "rerun+http://]x[:9876/proxy"])
def test_a_url_the_parser_refuses_is_an_input_error(url):
    with pytest.raises(InputError, match=r"expected Rerun's form rerun\+http://HOST:PORT/proxy"):
        check_live(False, url)
