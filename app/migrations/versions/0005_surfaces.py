"""Surfaces beyond walls (issue 11): ``walls.kind`` (None for a wall, ``ceiling`` or ``column``
for contract 4's ``surfaces``), ``walls.extra`` (a surface's other fields: ``column``,
``radius_m``, ``centre``) and ``jobs.expected_storeys`` (contract 3's per-storey counts).

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-25

"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0005'
down_revision: str | Sequence[str] | None = '0004'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    # nullable columns: added without a table copy on SQLite and PostgreSQL; existing rows are walls
    op.add_column('walls', sa.Column('kind', sa.String(length=20), nullable=True))
    op.add_column('walls', sa.Column('extra', sa.JSON(), nullable=True))
    op.add_column('jobs', sa.Column('expected_storeys', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('jobs', schema=None) as b:
        b.drop_column('expected_storeys')
    with op.batch_alter_table('walls', schema=None) as b:
        b.drop_column('extra')
        b.drop_column('kind')
