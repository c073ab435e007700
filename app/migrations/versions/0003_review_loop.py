"""Review that closes the loop: added objects, bulk decisions, suggestions, carried decisions,
job cancellation, reopening a signed-off project.

- ``detections``: ``confidence`` (contract 4), ``extra`` (other contract-4 fields), ``note``
  (a reviewer's note on an added object), ``carried_from`` (the detection of an earlier job
  whose decision was carried over);
- ``review_decisions.batch``: the id of the bulk decision a row belongs to;
- ``jobs.cancelled_by``;
- ``suggestions``: candidates recognition found but did not keep (possible misses);
- ``project_events``: sign-off, reopen, job cancelled, decisions carried over (append-only);
- ``signoffs``: a project may be signed off again after an admin reopened it, so
  ``project_id`` is no longer unique (the newest row is the current sign-off).

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23

"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = '0003'
down_revision: str | Sequence[str] | None = '0002'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def _append_only(table: str) -> None:
    if op.get_bind().dialect.name == 'sqlite':
        for what in ('UPDATE', 'DELETE'):
            op.execute(f"CREATE TRIGGER {table}_no_{what.lower()} BEFORE {what} ON {table} "
                       f"BEGIN SELECT RAISE(ABORT, '{table} is append-only'); END")
    elif op.get_bind().dialect.name == 'postgresql':
        op.execute("CREATE OR REPLACE FUNCTION sbsc_append_only() RETURNS trigger AS $$ "
                   "BEGIN RAISE EXCEPTION '% is append-only', TG_TABLE_NAME; END; $$ LANGUAGE plpgsql")
        op.execute(f"CREATE TRIGGER {table}_append_only BEFORE UPDATE OR DELETE ON {table} "
                   "FOR EACH ROW EXECUTE FUNCTION sbsc_append_only()")


def _drop_append_only(table: str) -> None:
    if op.get_bind().dialect.name == 'sqlite':
        for what in ('update', 'delete'):
            op.execute(f"DROP TRIGGER IF EXISTS {table}_no_{what}")
    elif op.get_bind().dialect.name == 'postgresql':
        op.execute(f"DROP TRIGGER IF EXISTS {table}_append_only ON {table}")


def upgrade() -> None:
    with op.batch_alter_table('detections', schema=None) as b:
        b.add_column(sa.Column('confidence', sa.Float(), nullable=True))
        b.add_column(sa.Column('extra', sa.JSON(), nullable=True))
        b.add_column(sa.Column('note', sa.Text(), nullable=True))
        b.add_column(sa.Column('carried_from', sa.Integer(), nullable=True))
    # review_decisions is append-only: on SQLite a batch copy would drop its triggers, and
    # adding a nullable column needs no copy on either database
    op.add_column('review_decisions', sa.Column('batch', sa.String(length=40), nullable=True))
    op.create_index(op.f('ix_review_decisions_batch'), 'review_decisions', ['batch'], unique=False)
    op.add_column('jobs', sa.Column('cancelled_by', sa.String(length=100), nullable=True))

    op.create_table(
        'suggestions',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('project_id', sa.Integer(), nullable=False),
        sa.Column('job_id', sa.Integer(), nullable=False),
        sa.Column('class_id', sa.String(length=100), nullable=False),
        sa.Column('wall_key', sa.String(length=50), nullable=False),
        sa.Column('u', sa.Float(), nullable=False),
        sa.Column('v', sa.Float(), nullable=False),
        sa.Column('width_m', sa.Float(), nullable=False),
        sa.Column('height_m', sa.Float(), nullable=False),
        sa.Column('source', sa.String(length=20), nullable=False),
        sa.Column('score', sa.Float(), nullable=True),
        sa.Column('reason', sa.String(length=40), nullable=False),
        sa.Column('promoted_id', sa.Integer(), nullable=True),
        sa.ForeignKeyConstraint(['job_id'], ['jobs.id'], name=op.f('fk_suggestions_job_id_jobs')),
        sa.ForeignKeyConstraint(['project_id'], ['projects.id'],
                                name=op.f('fk_suggestions_project_id_projects')),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_suggestions')))
    op.create_index(op.f('ix_suggestions_job_id'), 'suggestions', ['job_id'], unique=False)
    op.create_index(op.f('ix_suggestions_project_id'), 'suggestions', ['project_id'], unique=False)

    op.create_table(
        'project_events',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('project_id', sa.Integer(), nullable=False),
        sa.Column('user_id', sa.Integer(), nullable=True),
        sa.Column('user_name', sa.String(length=100), nullable=False),
        sa.Column('at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('kind', sa.String(length=40), nullable=False),
        sa.Column('comment', sa.Text(), nullable=True),
        sa.Column('data', sa.JSON(), nullable=True),
        sa.ForeignKeyConstraint(['project_id'], ['projects.id'],
                                name=op.f('fk_project_events_project_id_projects')),
        sa.ForeignKeyConstraint(['user_id'], ['users.id'], name=op.f('fk_project_events_user_id_users')),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_project_events')))
    op.create_index(op.f('ix_project_events_project_id'), 'project_events', ['project_id'], unique=False)
    _append_only('project_events')

    # several sign-offs per project (after a reopen): drop the unique key; on SQLite the
    # batch copy loses the table's triggers, so they are made again
    _drop_append_only('signoffs')
    with op.batch_alter_table('signoffs', schema=None) as b:
        b.drop_constraint('uq_signoffs_project_id', type_='unique')
        b.create_index(b.f('ix_signoffs_project_id'), ['project_id'], unique=False)
    _append_only('signoffs')


def downgrade() -> None:
    _drop_append_only('signoffs')
    with op.batch_alter_table('signoffs', schema=None) as b:
        b.drop_index(b.f('ix_signoffs_project_id'))
        b.create_unique_constraint('uq_signoffs_project_id', ['project_id'])
    _append_only('signoffs')
    _drop_append_only('project_events')
    op.drop_index(op.f('ix_project_events_project_id'), table_name='project_events')
    op.drop_table('project_events')
    op.drop_index(op.f('ix_suggestions_project_id'), table_name='suggestions')
    op.drop_index(op.f('ix_suggestions_job_id'), table_name='suggestions')
    op.drop_table('suggestions')
    op.drop_column('jobs', 'cancelled_by')
    op.drop_index(op.f('ix_review_decisions_batch'), table_name='review_decisions')
    op.drop_column('review_decisions', 'batch')
    with op.batch_alter_table('detections', schema=None) as b:
        b.drop_column('carried_from')
        b.drop_column('note')
        b.drop_column('extra')
        b.drop_column('confidence')
