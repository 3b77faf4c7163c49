"""Alembic migrations of the service store; configured from app.store.migrate, not alembic.ini."""
