"""IEEE 488.2 definite-length arbitrary block header: `#<d><length, d digits><payload>`.

Example: b"#15hello" is the 5-byte payload b"hello". The payload is binary and may hold any
byte, including 0x0A (the SCPI message terminator), which is why a block must be read by
length and never up to a termination character (drivers/digitizer_visa.py reads it).

pyvisa has `pyvisa.util.parse_ieee_block_header`, but it searches the buffer for "#" (so a
stream that lost its header is silently re-framed at the first "#" in the payload) and its
errors do not say what was wrong with which bytes; the header rules here are strict and short
enough to own. Indefinite-length blocks ("#0 ... <newline>") are refused: a terminator cannot
delimit binary data.
"""

from __future__ import annotations


class BlockFormatError(ValueError):
    """The bytes are not a well-formed definite-length block header."""


def digit_count(prefix: bytes) -> int:
    """The count of length digits from the first two bytes, b"#<d>" (d in 1..9)."""
    if len(prefix) < 2:
        raise BlockFormatError(f"block header cut short: {bytes(prefix)!r}")
    if prefix[0:1] != b"#":
        raise BlockFormatError(f"block does not start with '#': {bytes(prefix[:2])!r}")
    d = prefix[1:2]
    if d == b"0":
        raise BlockFormatError("indefinite-length block (#0) is not supported")
    if not d.isdigit():
        raise BlockFormatError(f"block header digit count is not a digit: {bytes(prefix[:2])!r}")
    return int(d)


def payload_length(digits: bytes) -> int:
    """The payload length from the d length digits (ASCII decimal, e.g. b"00000200")."""
    if not digits or not digits.isdigit():
        raise BlockFormatError(f"block length field is not decimal digits: {bytes(digits)!r}")
    return int(digits)
