"""Storeys of a building (issue 12): ``walls.storey`` (contract 4: the storey a wall stands in)
and ``jobs.storeys`` (contract 4's top-level ``storeys`` block of the job's results).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-24

"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0004'
down_revision: str | Sequence[str] | None = '0003'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # nullable columns: added without a table copy on SQLite and PostgreSQL
    op.add_column('walls', sa.Column('storey', sa.String(length=50), nullable=True))
    op.add_column('jobs', sa.Column('storeys', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('jobs', schema=None) as b:
        b.drop_column('storeys')
    with op.batch_alter_table('walls', schema=None) as b:
        b.drop_column('storey')
