"""SCPI message framing of the simulated digitizers: message units, header matching, the
numbered errors and the replies (text or IEEE 488.2 definite-length block) every dialect shares.

- Messages end with "\\n"; message units are separated by ";" (outside quoted strings);
  headers take the short or the long form in any case; the replies of one message are joined
  by ";" in order (binary blocks included) and end with "\\n".
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass


class SimError(Exception):
    """An error to report, numbered as in SCPI-99 (-1xx command, -2xx execution, -3xx device,
    -4xx query); each dialect reports it its own way."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


@dataclass
class Block:
    """A binary block reply (sent as an IEEE 488.2 definite-length block)."""

    payload: memoryview | bytes
    prefix: str = ""  # response header text before the '#'
    digits: int = 0  # length digits (0: as few as needed; 9 for a LeCroy DEF9 block)
    lead: bytes = b""  # bytes of the block before `payload` (a descriptor), sent without a copy

    @property
    def length(self) -> int:
        return len(self.lead) + len(self.payload)


@dataclass
class Call:
    """One message unit as a handler sees it."""

    suffixes: tuple[int, ...]  # the numeric suffixes of the "<n>" nodes, in order
    query: bool
    arg: str
    nodes: tuple[str, ...] = ()  # the matched patterns (for reply headers)
    node_suffixes: tuple[int | None, ...] = ()  # aligned with nodes

    @property
    def suffix(self) -> int:
        return self.suffixes[-1] if self.suffixes else 1

    @property
    def args(self) -> list[str]:
        return [a.strip() for a in self.arg.split(",")] if self.arg else []

    def query_only(self) -> None:
        """A header that exists only as a query: its command form is undefined."""
        if not self.query:
            raise SimError(-113, "Undefined header")

    def command_only(self) -> None:
        """A header that exists only as a command: its query form is undefined."""
        if self.query:
            raise SimError(-113, "Undefined header")


Reply = str | Block | None
Handler = Callable[[Call], Reply]


def block_bytes(block: Block) -> bytes:
    """`<prefix>#<d><length><payload>` (IEEE 488.2 definite length, written here: the simulator
    does not share the driver's framing code)."""
    digits = str(block.length).zfill(block.digits).encode("ascii")
    return block.prefix.encode("ascii") + b"#" + str(len(digits)).encode("ascii") + digits


def split_units(message: str) -> list[str]:
    """Message units at ';' outside "..." strings."""
    units, current, quoted = [], [], False
    for char in message:
        if char == '"':
            quoted = not quoted
        if char == ";" and not quoted:
            units.append("".join(current))
            current = []
        else:
            current.append(char)
    units.append("".join(current))
    return [u.strip() for u in units if u.strip()]


def node_matches(node: str, pattern: str) -> tuple[bool, int | None]:
    """Does a header node match a pattern ("SRATe", "CHANnel<n>", "VDIV|VOLT_DIV")? With the
    node's numeric suffix for a "<n>" pattern."""
    for alternative in pattern.split("|"):
        numbered = alternative.endswith("<n>")
        stem = alternative[:-3] if numbered else alternative
        text, suffix = node, None
        if numbered:
            m = re.fullmatch(r"([A-Za-z_]*?)(\d*)", node)
            if m is None:
                continue
            text, suffix = m.group(1), int(m.group(2)) if m.group(2) else 1
        short = "".join(c for c in stem if c.isupper() or c.isdigit() or c == "_")
        if text.upper() in (short.upper(), stem.upper()):
            return True, suffix
    return False, None


def long_header(call: Call) -> str:
    """The long form of a matched header, e.g. ":HORIZONTAL:MODE:SAMPLERATE" or ":CH1:SCALE"."""
    parts = []
    for pattern, suffix in zip(call.nodes, call.node_suffixes, strict=True):
        first = pattern.split("|")[-1]
        stem = first[:-3] if first.endswith("<n>") else first
        parts.append(stem.upper() + ("" if suffix is None else str(suffix)))
    return ":" + ":".join(parts)

