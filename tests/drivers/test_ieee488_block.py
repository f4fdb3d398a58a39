"""IEEE 488.2 definite-length block headers (drivers/ieee488_block.py), byte by byte."""

from __future__ import annotations

import pytest

from hopkinson.drivers.ieee488_block import BlockFormatError, digit_count, payload_length


def test_known_headers() -> None:
    assert digit_count(b"#1") == 1 and payload_length(b"5") == 5
    assert digit_count(b"#8") == 8 and payload_length(b"20000000") == 20_000_000
    assert digit_count(b"#9") == 9 and payload_length(b"000000346") == 346  # LeCroy's DEF9


@pytest.mark.parametrize(
    ("prefix", "words"),
    [(b"", "cut short"), (b"#", "cut short"), (b"15", "does not start with '#'"), (b"#0", "indefinite-length"),
     (b"#A", "not a digit"), (b"#?", "not a digit")],
)
def test_malformed_digit_counts_are_named(prefix: bytes, words: str) -> None:
    with pytest.raises(BlockFormatError, match=words):
        digit_count(prefix)


@pytest.mark.parametrize("digits", [b"", b"?\nXX", b" 12", b"-1"])
def test_malformed_lengths_are_named(digits: bytes) -> None:
    with pytest.raises(BlockFormatError, match="not decimal digits"):
        payload_length(digits)
