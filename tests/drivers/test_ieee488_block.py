"""Byte-level tests of IEEE 488.2 definite-length block framing (drivers/ieee488_block.py)."""

from __future__ import annotations

import io

import numpy as np
import pytest
from hopkinson.drivers.ieee488_block import (
    BlockFormatError,
    block_header,
    encode_block,
    parse_block,
    parse_block_header,
    read_block,
)


def test_header_is_hash_digit_count_then_length() -> None:
    assert block_header(0) == b"#10"
    assert block_header(5) == b"#15"
    assert block_header(200) == b"#3200"
    assert block_header(20_000_000) == b"#820000000"
    assert block_header(999_999_999) == b"#9999999999"


def test_header_refuses_lengths_it_cannot_express() -> None:
    with pytest.raises(ValueError):
        block_header(-1)
    with pytest.raises(ValueError):
        block_header(1_000_000_000)


def test_parse_known_bytes() -> None:
    assert parse_block(b"#15hello") == b"hello"
    assert parse_block(b"#10") == b""
    assert parse_block(b"#15hello\n", terminator=b"\n") == b"hello"
    assert parse_block_header(b"#3200xyz") == (5, 200)


def test_payload_full_of_newlines_and_hashes_round_trips() -> None:
    payload = b"\n#\n#15\n" * 1000 + bytes(range(256))
    data = encode_block(payload)
    assert data.startswith(b"#47256")  # 7 * 1000 + 256 bytes
    assert parse_block(data) == payload
    assert parse_block(data + b"\n", terminator=b"\n") == payload


def test_int16_codes_with_0x0a_bytes_round_trip() -> None:
    codes = np.arange(-32768, 32768, dtype="<i2")  # every code: 0x0A in low and high bytes
    raw = codes.tobytes()
    assert raw.count(b"\n") == 512
    got = np.frombuffer(parse_block(encode_block(raw)), dtype="<i2")
    np.testing.assert_array_equal(got, codes)


@pytest.mark.parametrize(
    ("data", "words"),
    [
        (b"", "cut short"),
        (b"#", "cut short"),
        (b"15hello", "does not start with '#'"),
        (b"#0hello\n", "indefinite-length"),
        (b"#A5hello", "not a digit"),
        (b"#2?\nXXXX", "not decimal digits"),
        (b"#3", "cut short"),
        (b"#3 12abc", "not decimal digits"),
    ],
)
def test_malformed_headers_are_named(data: bytes, words: str) -> None:
    with pytest.raises(BlockFormatError, match=words):
        parse_block(data)


def test_truncated_block_says_how_much_arrived() -> None:
    with pytest.raises(BlockFormatError, match="header says 10 bytes, got 3"):
        parse_block(b"#210abc")


def test_bytes_after_payload_are_refused() -> None:
    with pytest.raises(BlockFormatError, match="unexpected bytes"):
        parse_block(b"#15helloXY")
    with pytest.raises(BlockFormatError, match="unexpected bytes"):
        parse_block(b"#15hello", terminator=b"\n")


class _Stream:
    """A byte stream recording the sizes asked of read_exact."""

    def __init__(self, data: bytes) -> None:
        self._io = io.BytesIO(data)
        self.asked: list[int] = []

    def read_exact(self, n: int) -> bytes:
        self.asked.append(n)
        return self._io.read(n)


def test_read_block_reads_header_then_whole_payload_in_one_request() -> None:
    payload = bytes(np.arange(-32768, 32768, dtype="<i2").tobytes())
    stream = _Stream(encode_block(payload) + b"\nNEXT")
    got = read_block(stream.read_exact, terminator=b"\n")
    assert bytes(got) == payload
    assert stream.asked == [2, 6, len(payload) + 1]  # never stops at a 0x0A in the payload
    assert stream._io.read() == b"NEXT"  # the stream stays in step


def test_read_block_truncated_stream() -> None:
    stream = _Stream(b"#41000" + b"\n" * 10)
    with pytest.raises(BlockFormatError, match="header says 1000 bytes, got 10"):
        read_block(stream.read_exact)


def test_read_block_header_cut_short_and_missing_terminator() -> None:
    with pytest.raises(BlockFormatError, match="cut short"):
        read_block(_Stream(b"#41").read_exact)
    with pytest.raises(BlockFormatError, match="terminator"):
        read_block(_Stream(b"#13abcX").read_exact, terminator=b"\n")
