"""A packet with bytes after its last array is malformed, compressed or not."""

import numpy as np
import pytest

from pipeline.transport.wire import WireError, decode_packet, encode_packet


@pytest.mark.parametrize("extra", [b"\x00", b"junk", b"\x00" * 8])
def test_bytes_after_the_last_array_of_a_plain_packet_raise(extra):
    data = encode_packet({"round": 0}, [("x", {"a": np.arange(5)}), ("ack", {})], compress=False)
    assert data[:4] == b"FMP1"
    decode_packet(data)
    with pytest.raises(WireError, match=f"{len(extra)} trailing bytes"):
        decode_packet(data + extra)
