"""Byte encoding of the packets robots exchange over a real middleware.

One *packet* per logical round and ordered pair of neighbouring robots: a header (sender,
receiver, logical round, sequence number, the robot's phase and its termination-wave state)
and the algorithm messages of that round, each a ``kind`` and a payload of named numpy
arrays — exactly the :class:`~pipeline.transport.Message` payloads that the
in-process network counts. The header is JSON (small, self-describing); the arrays follow as
raw little-endian bytes, each described in the header by name, dtype and shape.

Two byte counts are kept apart: *counted* bytes are the algorithm messages measured like the
simulator does (:attr:`Message.nbytes`: 12-byte header plus the arrays' ``nbytes``), so the two
transports report comparable figures; *wire* bytes are the encoded packet lengths handed to
the middleware (JSON header, array descriptions, the per-round packet of a silent robot).

Compression: a packet whose bytes zlib (level :data:`ZLIB_LEVEL`) makes smaller travels
compressed (``FMZ1`` then the zlib stream of the whole ``FMP1`` packet); others travel as
they are. Decoding accepts both. Lossless, so the receiver's arrays are the sender's; the
wire bytes are the compressed lengths. Measured on formation d (``bench/team_bytes.py``, one
run): the feature exchange (SIFT descriptors as bytes, :mod:`pipeline.matching.packed`)
2.61 MB counted, 2.08 MB compressed; the consistency stage's packets 2.94 MB plain, 1.46 MB
compressed; fusion's 1.55 MB, 1.26 MB.
"""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np

__all__ = ["encode_packet", "decode_packet", "WireError", "ZLIB_LEVEL", "MAX_PACKET_BYTES",
           "set_compression"]

_MAGIC = b"FMP1"
_MAGIC_Z = b"FMZ1"
_LEN = struct.Struct("<I")
#: zlib level of compressed packets: level 1 keeps nearly all of level 6's reduction on SIFT
#: bytes (114.7 kB vs 112.2 kB of 147.7 kB for one 1154-feature robot) at under half the time
ZLIB_LEVEL = 1
#: largest decompressed packet accepted (a packet claiming more is malformed, not a reason to
#: exhaust memory): 1 GiB
MAX_PACKET_BYTES = 1 << 30
_compress = {"on": True}


def set_compression(on: bool) -> None:
    """Whether :func:`encode_packet` compresses by default in this process (a robot process
    sets it from its ``wire`` option; on unless told otherwise)."""
    _compress["on"] = bool(on)


class WireError(ValueError):
    """A packet that does not decode (truncated, wrong magic, inconsistent sizes)."""


def encode_packet(header: dict, messages: list[tuple[str, dict]],
                  compress: bool | None = None) -> bytes:
    """Encode one packet.

    Parameters
    ----------
    header : dict — JSON-serialisable fields (ints, floats, bools, strings, lists)
    messages : list of ``(kind, payload)`` — payload maps names to numpy arrays
    compress : bool or None — send it zlib-compressed when that is smaller (module
        docstring); None: as :func:`set_compression` set (default on)

    Returns
    -------
    bytes — ``MAGIC | len(json) | json | array bytes...``, or ``FMZ1 | zlib(that)``
    """
    descr, blobs = [], []
    for kind, payload in messages:
        arrays = []
        for name, a in payload.items():
            a = np.ascontiguousarray(a)
            if a.dtype.byteorder == ">":
                a = a.astype(a.dtype.newbyteorder("<"))
            arrays.append([name, a.dtype.str, list(a.shape)])
            blobs.append(a.tobytes())
        descr.append([kind, arrays])
    head = json.dumps({**header, "msgs": descr}, separators=(",", ":")).encode()
    plain = b"".join([_MAGIC, _LEN.pack(len(head)), head, *blobs])
    if (_compress["on"] if compress is None else compress) and len(plain) > 64:
        packed = zlib.compress(plain, ZLIB_LEVEL)
        if len(packed) + len(_MAGIC_Z) < len(plain):
            return _MAGIC_Z + packed
    return plain


def _inflate(data: memoryview) -> bytes:
    d = zlib.decompressobj()
    try:
        out = d.decompress(data, MAX_PACKET_BYTES)
    except zlib.error as exc:
        raise WireError(f"compressed packet does not inflate: {exc}") from None
    if d.unconsumed_tail:
        raise WireError(f"compressed packet inflates beyond {MAX_PACKET_BYTES} bytes")
    if not d.eof:
        raise WireError("truncated compressed packet")
    if d.unused_data:
        raise WireError(f"{len(d.unused_data)} trailing bytes after the compressed packet")
    return out


def decode_packet(data: bytes) -> tuple[dict, list[tuple[str, dict]]]:
    """Inverse of :func:`encode_packet`; raises :class:`WireError` on a malformed packet."""
    mv = memoryview(data)
    if len(mv) >= 4 and bytes(mv[:4]) == _MAGIC_Z:
        mv = memoryview(_inflate(mv[4:]))
    if len(mv) < 8 or bytes(mv[:4]) != _MAGIC:
        raise WireError("not a formation-match packet (bad magic)")
    (hlen,) = _LEN.unpack(mv[4:8])
    if 8 + hlen > len(mv):
        raise WireError("truncated packet header")
    try:
        header = json.loads(bytes(mv[8:8 + hlen]))
    except ValueError as exc:
        raise WireError(f"packet header is not JSON: {exc}") from None
    pos = 8 + hlen
    messages = []
    for kind, arrays in header.pop("msgs", []):
        payload = {}
        for name, dtype, shape in arrays:
            dt = np.dtype(dtype)
            size = dt.itemsize * int(np.prod(shape, dtype=np.int64))
            if pos + size > len(mv):
                raise WireError(f"truncated array {name!r} in a {kind!r} message")
            payload[name] = np.frombuffer(mv[pos:pos + size], dtype=dt).reshape(shape).copy()
            pos += size
        messages.append((kind, payload))
    if pos != len(mv):
        raise WireError(f"{len(mv) - pos} trailing bytes after the last array")
    return header, messages
