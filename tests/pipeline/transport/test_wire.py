import numpy as np
import pytest

from pipeline.transport import Message
from pipeline.transport.wire import WireError, decode_packet, encode_packet


def test_round_trip_keeps_arrays_and_header():
    msgs = [("blocks", {"rows": np.arange(3, dtype=np.int32),
                        "indices": np.array([[1, 2]], np.int64)}),
            ("final", {"t": np.array([4], np.int32)}), ("ack", {})]
    data = encode_packet({"src": 1, "dst": 2, "round": 7, "state": {"c": 3, "b": 1}}, msgs)
    header, back = decode_packet(data)
    assert header == {"src": 1, "dst": 2, "round": 7, "state": {"c": 3, "b": 1}}
    assert [k for k, _ in back] == ["blocks", "final", "ack"]
    for (_, a), (_, b) in zip(msgs, back, strict=True):
        assert a.keys() == b.keys()
        for k in a:
            assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k])


def test_wire_bytes_cover_the_counted_bytes():
    payload = {"rows": np.arange(100, dtype=np.int32), "indptr": np.arange(101, dtype=np.int32)}
    counted = Message(0, 1, "blocks", payload).nbytes
    wire = len(encode_packet({"src": 0, "dst": 1, "round": 0}, [("blocks", payload)]))
    assert counted - 12 <= wire < counted + 200


@pytest.mark.parametrize("cut", [0, 3, 9, -1])
def test_truncated_or_foreign_packets_raise(cut):
    data = encode_packet({"round": 0}, [("x", {"a": np.arange(5)})])
    with pytest.raises(WireError):
        decode_packet(data[:cut] if cut >= 0 else data + b"junk")
