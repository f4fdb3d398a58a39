"""IEEE 488.2 definite-length arbitrary block: `#<d><length, d digits><payload>`.

Example: b"#15hello" is the 5-byte payload b"hello". The payload is binary and may hold any
byte, including 0x0A (the SCPI message terminator), which is why a block must be read by
length and never up to a termination character.

pyvisa has `pyvisa.util.parse_ieee_block_header`, but it searches the buffer for "#" (so a
stream that lost its header is silently re-framed at the first "#" in the payload) and its
errors do not say what was wrong with which bytes; the framing here is strict and short
enough to own. Indefinite-length blocks ("#0 ... <newline>") are refused: a terminator cannot
delimit binary data.
"""

from __future__ import annotations

from collections.abc import Callable


class BlockFormatError(ValueError):
    """The bytes are not a well-formed definite-length block (or are cut short)."""


def block_header(length: int) -> bytes:
    """The header for a payload of `length` bytes, e.g. block_header(5) == b"#15"."""
    if length < 0:
        raise ValueError(f"block length must be >= 0, got {length}")
    digits = str(length)
    if len(digits) > 9:
        raise ValueError(f"block length {length} needs more than 9 digits")
    return f"#{len(digits)}{digits}".encode("ascii")


def encode_block(payload: bytes) -> bytes:
    """Header + payload (no message terminator)."""
    return block_header(len(payload)) + bytes(payload)


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


def parse_block_header(data: bytes) -> tuple[int, int]:
    """(payload offset, payload length) of the block starting at data[0]."""
    d = digit_count(data[:2])
    if len(data) < 2 + d:
        raise BlockFormatError(f"block header cut short: {bytes(data[: 2 + d])!r}")
    return 2 + d, payload_length(data[2 : 2 + d])


def parse_block(data: bytes, terminator: bytes = b"") -> bytes:
    """The payload of one complete block (optionally followed by `terminator`).

    Raises BlockFormatError when the header is malformed, the block is truncated, or
    anything but the terminator follows the payload.
    """
    offset, length = parse_block_header(data)
    end = offset + length
    if len(data) < end:
        raise BlockFormatError(f"block truncated: header says {length} bytes, got {len(data) - offset}")
    tail = bytes(data[end:])
    if tail != terminator:
        raise BlockFormatError(f"unexpected bytes after the block payload: {tail[:20]!r}")
    return bytes(data[offset:end])


def read_block(read_exact: Callable[[int], bytes], terminator: bytes = b"") -> memoryview:
    """Read one block from a stream: `read_exact(n)` must return exactly n bytes (or fewer
    only at end of stream/timeout, which is reported as truncation).

    Reads the 2-byte prefix, the length digits, then payload + terminator in one call so the
    transport can move it in large chunks. Returns a read-only view of the payload.
    """
    prefix = read_exact(2)
    d = digit_count(prefix)
    digits = read_exact(d)
    if len(digits) < d:
        raise BlockFormatError(f"block header cut short: {bytes(prefix + digits)!r}")
    length = payload_length(digits)
    body = read_exact(length + len(terminator))
    if len(body) < length + len(terminator):
        raise BlockFormatError(
            f"block truncated: header says {length} bytes, got {max(len(body) - len(terminator), 0)}"
        )
    if terminator and body[length:] != terminator:
        raise BlockFormatError(
            f"block not followed by the terminator {terminator!r}: {bytes(body[length:])!r}"
        )
    return memoryview(body)[:length]  # a view: no copy of a large payload
