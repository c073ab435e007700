"""Projects belong to their members (issue 30): ``project_members`` (project, user, role).

Existing projects keep working: their creator (when that user still exists) becomes their
manager, capped by the creator's own role; admins are members of every project without a
row.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-28

"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0006'
down_revision: str | Sequence[str] | None = '0005'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        'project_members',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('project_id', sa.Integer(), nullable=False),
        sa.Column('user_id', sa.Integer(), nullable=False),
        sa.Column('role', sa.String(length=20), nullable=False),
        sa.Column('added_by', sa.String(length=100), nullable=True),
        sa.Column('added_at', sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(['project_id'], ['projects.id'],
                                name=op.f('fk_project_members_project_id_projects')),
        sa.ForeignKeyConstraint(['user_id'], ['users.id'], name=op.f('fk_project_members_user_id_users')),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_project_members')),
        sa.UniqueConstraint('project_id', 'user_id', name=op.f('uq_project_members_project_id')),
    )
    op.create_index(op.f('ix_project_members_project_id'), 'project_members', ['project_id'], unique=False)
    op.create_index(op.f('ix_project_members_user_id'), 'project_members', ['user_id'], unique=False)
    # the creator of each existing project is its manager (reviewers stay reviewers: a
    # global role caps the project role); admins need no row
    op.execute(
        "INSERT INTO project_members (project_id, user_id, role, added_by, added_at) "
        "SELECT p.id, u.id, CASE WHEN u.role = 'reviewer' THEN 'reviewer' ELSE 'manager' END, "
        "'migration', CURRENT_TIMESTAMP FROM projects p JOIN users u ON u.name = p.created_by "
        "WHERE u.role <> 'admin'")


def downgrade() -> None:
    op.drop_index(op.f('ix_project_members_user_id'), table_name='project_members')
    op.drop_index(op.f('ix_project_members_project_id'), table_name='project_members')
    op.drop_table('project_members')
