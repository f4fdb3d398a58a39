"""A lab's own digitizer dialect, as a lab would write it in its own package: one class that
changes what differs from the generic SCPI dialect (tests name it "tests.drivers.vendor_b:VendorBDialect")."""

from __future__ import annotations

from hopkinson.drivers.scpi_dialect import GenericScpiDialect, ReplyFormatError, ScpiLink


class VendorBDialect(GenericScpiDialect):
    """Arms with :DIGitize:SINGle and reports STOP / WAIT / DONE."""

    name = "vendor-b"

    def arm(self, link: ScpiLink) -> None:
        self.command(link, ":DIGitize:SINGle")

    def state(self, link: ScpiLink) -> str:
        command = ":DIGitize:STATus?"
        reply = link.query(command)
        words = {"STOP": "IDLE", "WAIT": "ARMED", "DONE": "TRIGGERED"}
        if reply not in words:
            raise ReplyFormatError(command, f"unknown acquisition state {reply!r}", reply)
        return words[reply]


class NotADialect:
    """Not a DigitizerDialect: the driver refuses it by name."""
