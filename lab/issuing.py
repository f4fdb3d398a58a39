"""Issuing a certificate: one unit of work (lab.uow). The campaign is found by its identity,
the record's rules are checked (lab.repositories.Certificates), the number is allocated, the
content is gathered and the documents are written — and only then is the certificate stored
and audited. When anything fails (a full folder, a DCC that does not validate, a lost race on
the number) the transaction rolls back and the documents written are removed: a number is
never issued without its document, and a document never names a number not issued.

A campaign with simulated shots never gets a real number: only a specimen, numbered in its own
series (`<prefix>-SIM-<year>-<NNNN>`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from hopkinson.lab import schema as t
from hopkinson.lab.errors import LabError
from hopkinson.lab.repositories import IssuedCertificate
from hopkinson.lab.uow import LabDatabase, UnitOfWork, utc_now

SPECIMEN_SERIES = "SIM"

Content = Callable[[UnitOfWork, t.Campaign], dict[str, Any]]
Documents = Callable[[dict[str, Any]], list[Path]]


def with_number(content: dict[str, Any], number: str, issued_utc: str, replaces: str = "") -> dict[str, Any]:
    """The content as issued: its number, date and the certificate it replaces."""
    return dict(content, number=number, issued_utc=issued_utc, replaces=replaces)


def issue(db: LabDatabase, *, campaign: str, prefix: str, authorised_by: str, content: Content,
          documents: Documents | None = None, specimen: bool = False, replaces: str = "") -> IssuedCertificate:
    """Issue the certificate of `campaign` (its UUID, or an unambiguous name) in one unit of work
    (module doc); LabError naming the rule or the failure."""
    if not authorised_by.strip():
        raise LabError("a certificate needs the name of the person who authorises it")
    series = f"{prefix}-{SPECIMEN_SERIES}" if specimen else prefix

    def work(uow: UnitOfWork) -> IssuedCertificate:
        camp = uow.campaigns.find(campaign)
        if camp.sensor_id is None:
            raise LabError(f"campaign {camp.name}: its shots name no sensor serial; no certificate")
        results = uow.shots.results(campaign=camp)
        simulated = [r.shot_name or r.shot_uuid for r in results if r.simulated]
        if simulated and not specimen:
            raise LabError(f"campaign {camp.name}: {len(simulated)} of its {len(results)} shots were made by the simulator "
                           f"({', '.join(simulated[:3])}{' …' if len(simulated) > 3 else ''}): no certificate; "
                           "--specimen issues a specimen marked as simulated data")
        revision = uow.certificates.revision_for(camp, specimen, replaces)
        issued_utc = utc_now()
        year = int(issued_utc[:4])
        sequence, number = uow.certificates.next_number(series, year)
        final = with_number(content(uow, camp), number, issued_utc, replaces)
        written = documents(final) if documents is not None else []
        uow.on_rollback(lambda: [path.unlink(missing_ok=True) for path in written])
        sensor = uow.session.get(t.Sensor, camp.sensor_id)
        uow.certificates.add(number=number, prefix=series, year=year, sequence=sequence, campaign=camp,
                             sensor=sensor, specimen=specimen, revision=revision, replaces=replaces,
                             authorised_by=authorised_by, issued_utc=issued_utc, content=final)
        return IssuedCertificate(number, replaces, issued_utc, final)

    return db.transact(authorised_by, work)
