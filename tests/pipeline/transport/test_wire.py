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
    wire = len(encode_packet({"src": 0, "dst": 1, "round": 0}, [("blocks", payload)],
                             compress=False))
    assert counted - 12 <= wire < counted + 200


def test_compressed_packets_are_smaller_and_decode_to_the_same_arrays():
    rng = np.random.default_rng(0)
    # SIFT-like bytes (mostly small values) and an index array: both compress
    payload = {"d": np.minimum(rng.exponential(12, (300, 128)), 255).astype(np.uint8),
               "rows": np.arange(500, dtype=np.int64)}
    plain = encode_packet({"round": 3}, [("features", payload)], compress=False)
    packed = encode_packet({"round": 3}, [("features", payload)])
    assert packed[:4] == b"FMZ1" and plain[:4] == b"FMP1"
    assert len(packed) < 0.8 * len(plain)
    for data in (plain, packed):
        header, [(kind, back)] = decode_packet(data)
        assert header == {"round": 3} and kind == "features"
        assert all(np.array_equal(back[k], payload[k]) and back[k].dtype == payload[k].dtype
                   for k in payload)
    # random bytes do not compress: the packet goes as it is
    noise = {"x": rng.integers(0, 256, 4000).astype(np.uint8)}
    assert encode_packet({}, [("x", noise)])[:4] == b"FMP1"


@pytest.mark.parametrize("bad", [b"FMZ1", b"FMZ1garbage", b"FMZ1" + b"x" * 40])
def test_malformed_compressed_packets_raise(bad):
    import zlib

    with pytest.raises(WireError):
        decode_packet(bad)
    good = encode_packet({}, [("x", {"a": np.zeros(1000, np.int64)})])
    with pytest.raises(WireError):  # a stream that is not a packet inside
        decode_packet(b"FMZ1" + zlib.compress(b"not a packet" * 20))
    with pytest.raises(WireError):
        decode_packet(good[:-3])


@pytest.mark.parametrize("cut", [0, 3, 9, -1])
def test_truncated_or_foreign_packets_raise(cut):
    data = encode_packet({"round": 0}, [("x", {"a": np.arange(5)})])
    with pytest.raises(WireError):
        decode_packet(data[:cut] if cut >= 0 else data + b"junk")
