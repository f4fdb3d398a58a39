"""Each analysis keeps its quasi-static gain (analysis.static_gain), its shot-specific u and the
amplitude it is measured at: a certificate's amplitude linearity is fitted to it, as a campaign's
statistics are (reports.statistics.campaign_linearity), not to the model's DC gain.

Three nullable columns on `analyses`; no row is changed: an analysis recorded before holds none
(a certificate then says its shots must be imported again after a new analysis).

Revision ID: 0003
Revises: 0002
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

COLUMNS = ("static_gain", "static_gain_u", "static_gain_amplitude_m_s2")


def upgrade() -> None:
    for name in COLUMNS:  # ALTER TABLE … ADD COLUMN: no table is copied, the append-only triggers stay
        op.add_column("analyses", sa.Column(name, sa.Float(), nullable=True))


def downgrade() -> None:
    raise NotImplementedError("the lab record is append-only: restore a backup taken before `lab upgrade`")
